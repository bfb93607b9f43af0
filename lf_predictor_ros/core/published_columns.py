"""The published history, kept as columns of arrays for the vessel memory's job (issue 14).

`LfOdometry` keeps every estimate it publishes as a `Published` record: the covariance
calibration and the vessel memory learn from that history in a child process
(`core.fit_process`). Pickled as 1000–20000 objects the history would hold the sending thread's
GIL for about 20 ms (2-core machine, docs/BENCHMARKS.md, sixty-sixth session); packed into
arrays when the job starts, it still held the GIL for 1.5–3 ms in a few large array calls, and
the node's pose callbacks waited that long (sixty-eighth session). `PublishedLog` therefore
writes each record into columns as it is published (`row_buffer.RowBuffer`) and hands out
`PublishedColumns` snapshots without a copy; `PublishedColumns.records` gives the records
back, value for value (`test/core/test_published_columns.py`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, cast

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.row_buffer import RowBuffer

FloatArray = NDArray[np.float64]
EstimateSource = Literal['network', 'fallback']
SOURCES: tuple[EstimateSource, ...] = ('network', 'fallback')  # every EstimateSource
_VECTOR_FIELDS = ('pose', 'twist', 'accel', 'lag')


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

    Each column is a `RowBuffer`: a row once written is never written again, so a `columns`
    snapshot is made of views, taken without a copy, that later appends leave as they are:
    another thread may read or pickle it while the node goes on publishing. The first record
    fixes each vector's length (the twin excess has the pose's).
    """

    def __init__(self, capacity: int) -> None:
        """Keep at most ``capacity`` (≥ 1) records."""
        if not (isinstance(capacity, int) and capacity >= 1):
            raise ValueError(f'the published history needs a capacity >= 1, got {capacity!r}')
        self.capacity = capacity
        self._stamp = RowBuffer(capacity=capacity)
        self._vectors: dict[str, RowBuffer] = {}  # made at the first record (its lengths)
        self._excess = RowBuffer((0,), capacity=capacity)
        self._has_excess = RowBuffer(dtype=bool, capacity=capacity)
        self._codes = RowBuffer(dtype=np.intp, capacity=capacity)
        self._sources: dict[str, int] = {}

    def __len__(self) -> int:
        return len(self._stamp)

    def append(self, record: Published) -> None:
        """Add ``record`` as the newest (its vectors copied); beyond ``capacity`` drop the oldest.

        Raises:
            ValueError: a vector is not a real 1-D array of the length the first record set
                (the log is left as it was).
        """
        if not self._vectors:
            widths = {name: _width(getattr(record, name), name) for name in _VECTOR_FIELDS}
            self._vectors = {name: RowBuffer((width,), capacity=self.capacity)
                             for name, width in widths.items()}
            self._excess = RowBuffer((widths['pose'],), capacity=self.capacity)
        rows = [_checked(getattr(record, name), column.row_shape, name)
                for name, column in self._vectors.items()]  # all checked before any is written
        excess = record.twin_excess
        excess_row = np.nan if excess is None else \
            _checked(excess, self._excess.row_shape, 'twin_excess')
        for column, row in zip(self._vectors.values(), rows, strict=True):
            column.append(row)
        self._excess.append(excess_row)
        self._has_excess.append(excess is not None)
        self._stamp.append(record.stamp)
        self._codes.append(self._sources.setdefault(record.source, len(self._sources)))

    def columns(self) -> PublishedColumns:
        """The kept records as read-only views (a snapshot: later appends do not change it)."""
        empty = np.empty((0, 0))
        vectors = {name: self._vectors[name].view() if self._vectors else empty
                   for name in _VECTOR_FIELDS}
        return PublishedColumns(
            self._stamp.view(), sources=tuple(self._sources),
            source_codes=self._codes.view(),
            twin_excess=self._excess.view() if self._vectors else empty,
            has_twin_excess=self._has_excess.view(), **vectors)


def _width(value: object, name: str) -> int:
    """The length of the first record's vector ``name``."""
    shape = getattr(value, 'shape', None)
    if shape is None or len(shape) != 1:
        raise ValueError(f'published {name} must be a 1-D numpy array, got {value!r}')
    return int(shape[0])


def _checked(value: object, row_shape: tuple[int, ...], name: str) -> FloatArray:
    """``value`` if it fits a row of ``row_shape`` (a real 1-D array of that length)."""
    if getattr(value, 'shape', None) != row_shape or \
            getattr(value, 'dtype', np.dtype(object)).kind not in 'biuf':
        raise ValueError(f'published {name} must be a real array of shape {row_shape} '
                         f'(set by the first record), got {value!r}')
    return cast(FloatArray, value)
