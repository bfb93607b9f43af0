"""The published history as columns of arrays, for the vessel memory's job in a child process.

`LfOdometry.published` is a list of `Published` records (one per estimate, 1000–1700 in a
window). Pickled as objects they cost the sending thread about 20 ms of the GIL (2-core machine,
docs/BENCHMARKS.md, sixty-sixth session); as a few arrays, about 1.5 ms to build and nothing
worth counting to pickle. `PublishedColumns.of` packs a history, `PublishedColumns.records`
gives the same records back, value for value (`test/core/test_published_columns.py`).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from operator import attrgetter

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.odometry import Published

FloatArray = NDArray[np.float64]
_ARRAY_FIELDS = ('pose', 'twist', 'accel', 'lag')


@dataclass(frozen=True)
class PublishedColumns:
    """A published history (oldest first) as arrays: row i is record i.

    ``sources``: the distinct source names, ``source_codes`` each record's index into them;
    ``twin_excess`` rows of records without one are NaN and ``has_twin_excess`` False.
    """

    stamp: FloatArray  # (m,)
    pose: FloatArray  # (m, k) each, as the records' arrays
    twist: FloatArray
    accel: FloatArray
    lag: FloatArray
    sources: tuple[str, ...]
    source_codes: NDArray[np.intp]  # (m,)
    twin_excess: FloatArray  # (m, k); NaN rows where has_twin_excess is False
    has_twin_excess: NDArray[np.bool_]  # (m,)

    @classmethod
    def of(cls, history: Sequence[Published]) -> PublishedColumns:
        """Pack ``history``.

        Raises:
            ValueError: an array field's rows differ in shape or are not float64 (then send
                the records as they are).
        """
        columns = {name: _stacked(list(map(attrgetter(name), history)), name)
                   for name in _ARRAY_FIELDS}
        names = list(map(attrgetter('source'), history))
        sources = tuple(sorted(set(names)))
        index = {name: i for i, name in enumerate(sources)}
        codes = np.array([index[name] for name in names], dtype=np.intp)
        excesses = list(map(attrgetter('twin_excess'), history))
        has_excess = np.array([e is not None for e in excesses], dtype=bool)
        present = [e for e in excesses if e is not None]
        stacked = _stacked(present, 'twin_excess')
        excess = np.full((len(history), stacked.shape[1]), np.nan)
        excess[has_excess] = stacked
        stamps = np.fromiter(map(attrgetter('stamp'), history), np.float64, len(history))
        return cls(stamps, sources=sources, source_codes=codes, twin_excess=excess,
                   has_twin_excess=has_excess, **columns)

    def records(self) -> list[Published]:
        """The records again (each array a copy of its row)."""
        return [Published(float(self.stamp[i]), self.pose[i].copy(), self.twist[i].copy(),
                          self.sources[self.source_codes[i]],
                          self.accel[i].copy(), self.lag[i].copy(),
                          self.twin_excess[i].copy() if self.has_twin_excess[i] else None)
                for i in range(self.stamp.shape[0])]


def _stacked(rows: list[FloatArray], name: str) -> FloatArray:
    """Rows of one shape, float64, as one (m, k) array (m = 0: shape (0, 0))."""
    if not rows:
        return np.zeros((0, 0))
    try:
        kinds = set(map(attrgetter('dtype'), rows))
        stacked = np.array(rows)
    except (AttributeError, ValueError):  # not arrays, or of different shapes
        stacked = None
    if stacked is None or kinds != {np.dtype(np.float64)} or stacked.ndim != 2:
        raise ValueError(f'published {name} rows are not float64 vectors of one shape: '
                         'send the records as they are')
    return stacked
