"""The published history, kept as columns of arrays for the vessel memory's job (issue 14).

`LfOdometry` keeps every estimate it publishes as a `Published` record: the covariance
calibration and the vessel memory learn from that history in a child process
(`core.fit_process`). Pickled as 1000–20000 objects the history would hold the sending thread's
GIL for about 20 ms (2-core machine, docs/BENCHMARKS.md, sixty-sixth session); packed into
arrays when the job starts, it still held the GIL for 1.5–3 ms in a few large array calls, and
the node's pose callbacks waited that long (sixty-eighth session). `PublishedLog` therefore
writes each record into columns as it is published and hands out `PublishedColumns` snapshots
without a copy; `PublishedColumns.records` gives the records back, value for value
(`test/core/test_published_columns.py`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
EstimateSource = Literal['network', 'fallback']
_VECTOR_FIELDS = ('pose', 'twist', 'accel', 'lag')
MIN_ROWS = 64  # rows of a log's first buffers [-]
ArrayT = TypeVar('ArrayT', bound=NDArray[Any])


@dataclass(frozen=True)
class Published:
    """One published estimate as the calibration sees it (pose unwrapped, ndof entries)."""

    stamp: float
    pose: FloatArray  # unwrapped, ndof entries
    twist: FloatArray
    source: EstimateSource
    accel: FloatArray  # the twist's low-passed change per second (twist error model regressor)
    lag: FloatArray  # the pose error model's regressor w (`LfOdometry._lag_regressor`)
    # the untaken twin offset's excess max(0, m² − 2 L) (`LfOdometry._twin_excess`; None: no
    # offset given or not calibrated yet)
    twin_excess: FloatArray | None = None


@dataclass(frozen=True)
class PublishedColumns:
    """A published history (oldest first) as arrays: row i is record i.

    ``sources``: the distinct source names, ``source_codes`` each record's index into them;
    ``twin_excess`` rows of records without one are NaN and ``has_twin_excess`` False. The
    arrays of a `PublishedLog.columns` snapshot are read-only views.
    """

    stamp: FloatArray  # (m,)
    pose: FloatArray  # (m, k) each, float64
    twist: FloatArray
    accel: FloatArray
    lag: FloatArray
    sources: tuple[str, ...]
    source_codes: NDArray[np.intp]  # (m,)
    twin_excess: FloatArray  # (m, pose's k); NaN rows where has_twin_excess is False
    has_twin_excess: NDArray[np.bool_]  # (m,)

    def __len__(self) -> int:
        return int(self.stamp.shape[0])

    def records(self) -> list[Published]:
        """The records again (each array a copy of its row)."""
        return [Published(float(self.stamp[i]), self.pose[i].copy(), self.twist[i].copy(),
                          cast(EstimateSource, self.sources[self.source_codes[i]]),
                          self.accel[i].copy(), self.lag[i].copy(),
                          self.twin_excess[i].copy() if self.has_twin_excess[i] else None)
                for i in range(self.stamp.shape[0])]


class PublishedLog:
    """The newest ``capacity`` published records as columns, oldest first.

    Every column is a buffer of up to 2 × ``capacity`` rows. `append` writes the row after the
    newest and never writes a row again; when the buffers are full, the kept rows (at most
    ``capacity``) move to new buffers. A `columns` snapshot is therefore made of views, taken
    without a copy, that later appends leave as they are: another thread may read or pickle
    it while the node goes on publishing. The first record fixes each vector's length (the twin
    excess has the pose's).
    """

    def __init__(self, capacity: int) -> None:
        """Keep at most ``capacity`` (≥ 1) records."""
        if not (isinstance(capacity, int) and capacity >= 1):
            raise ValueError(f'the published history needs a capacity >= 1, got {capacity!r}')
        self.capacity = capacity
        self._stamp: FloatArray = np.empty(0)
        self._vectors: dict[str, FloatArray] = {}
        self._excess: FloatArray = np.empty((0, 0))
        self._has_excess: NDArray[np.bool_] = np.empty(0, dtype=bool)
        self._codes: NDArray[np.intp] = np.empty(0, dtype=np.intp)
        self._sources: dict[str, int] = {}
        self._start = 0
        self._end = 0

    def __len__(self) -> int:
        return self._end - self._start

    def append(self, record: Published) -> None:
        """Add ``record`` as the newest (its vectors copied); beyond ``capacity`` drop the oldest.

        Raises:
            ValueError: a vector is not a real 1-D array of the length the first record set
                (the log is left as it was).
        """
        if self._end == self._stamp.shape[0]:
            self._move(record)
        row = self._end  # not in any snapshot yet: a failed append leaves it to the next
        for name, column in self._vectors.items():
            column[row] = _checked(getattr(record, name), column, name)
        excess = record.twin_excess
        if excess is None:
            self._excess[row] = np.nan
        else:
            self._excess[row] = _checked(excess, self._excess, 'twin_excess')
        self._has_excess[row] = excess is not None
        self._stamp[row] = record.stamp
        self._codes[row] = self._sources.setdefault(record.source, len(self._sources))
        self._end = row + 1
        if self._end - self._start > self.capacity:
            self._start += 1

    def columns(self) -> PublishedColumns:
        """The kept records as read-only views (a snapshot: later appends do not change it)."""
        span = slice(self._start, self._end)
        empty = np.empty((0, 0))
        vectors = {name: _view(self._vectors[name], span) if self._vectors else empty
                   for name in _VECTOR_FIELDS}
        return PublishedColumns(
            _view(self._stamp, span), sources=tuple(self._sources),
            source_codes=_view(self._codes, span),
            twin_excess=_view(self._excess, span) if self._vectors else empty,
            has_twin_excess=_view(self._has_excess, span), **vectors)

    def _move(self, record: Published) -> None:
        """New buffers holding the kept rows at their start (the first record sets the widths)."""
        kept = self._end - self._start
        rows = min(2 * self.capacity, max(MIN_ROWS, 2 * kept))
        if not self._vectors:
            widths = {name: _width(getattr(record, name), name) for name in _VECTOR_FIELDS}
            self._vectors = {name: np.empty((0, width)) for name, width in widths.items()}
            self._excess = np.empty((0, widths['pose']))
        span = slice(self._start, self._end)
        self._stamp = _moved(self._stamp, span, rows)
        self._vectors = {name: _moved(column, span, rows)
                         for name, column in self._vectors.items()}
        self._excess = _moved(self._excess, span, rows)
        self._has_excess = _moved(self._has_excess, span, rows)
        self._codes = _moved(self._codes, span, rows)
        self._start, self._end = 0, kept


def _width(value: object, name: str) -> int:
    """The length of the first record's vector ``name``."""
    shape = getattr(value, 'shape', None)
    if shape is None or len(shape) != 1:
        raise ValueError(f'published {name} must be a 1-D numpy array, got {value!r}')
    return int(shape[0])


def _checked(value: object, column: FloatArray, name: str) -> FloatArray:
    """``value`` if it fits a row of ``column`` (a real 1-D array of its width)."""
    if getattr(value, 'shape', None) != column.shape[1:] or \
            getattr(value, 'dtype', np.dtype(object)).kind not in 'biuf':
        raise ValueError(f'published {name} must be a real array of shape {column.shape[1:]} '
                         f'(set by the first record), got {value!r}')
    return cast(FloatArray, value)


def _moved(array: ArrayT, span: slice, rows: int) -> ArrayT:
    """A new buffer of ``rows`` rows whose first rows are ``array[span]``."""
    moved = np.empty((rows, *array.shape[1:]), dtype=array.dtype)
    kept = array[span]
    moved[:kept.shape[0]] = kept
    return cast(ArrayT, moved)


def _view(array: ArrayT, span: slice) -> ArrayT:
    """A read-only view of ``array[span]``."""
    view = array[span]
    view.flags.writeable = False
    return cast(ArrayT, view)
