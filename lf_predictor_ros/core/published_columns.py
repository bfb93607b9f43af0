"""The published history as columns of arrays, for the vessel memory's job in a child process.

`LfOdometry.published` is a list of `Published` records (one per estimate, 1000–1700 in a
window). Pickled as objects they cost the sending thread about 20 ms of the GIL (2-core machine,
docs/BENCHMARKS.md, sixty-sixth session); as a few arrays, about 2–3 ms to build and nothing
worth counting to pickle. `PublishedColumns.of` packs a history, `PublishedColumns.records`
gives the same records back, value for value (`test/core/test_published_columns.py`).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

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
        columns = {name: _stacked([getattr(p, name) for p in history], name)
                   for name in _ARRAY_FIELDS}
        sources = tuple(sorted({p.source for p in history}))
        index = {name: i for i, name in enumerate(sources)}
        codes = np.array([index[p.source] for p in history], dtype=np.intp)
        has_excess = np.array([p.twin_excess is not None for p in history], dtype=bool)
        present = [p.twin_excess for p in history if p.twin_excess is not None]
        width = _stacked(present, 'twin_excess').shape[1] if present else 0
        excess = np.full((len(history), width), np.nan)
        if present:
            excess[has_excess] = _stacked(present, 'twin_excess')
        return cls(np.array([p.stamp for p in history], dtype=np.float64), sources=sources,
                   source_codes=codes, twin_excess=excess, has_twin_excess=has_excess,
                   **columns)

    def records(self) -> list[Published]:
        """The records again (each array a copy of its row)."""
        return [Published(float(self.stamp[i]), self.pose[i].copy(), self.twist[i].copy(),
                          self.sources[self.source_codes[i]],
                          self.accel[i].copy(), self.lag[i].copy(),
                          self.twin_excess[i].copy() if self.has_twin_excess[i] else None)
                for i in range(self.stamp.shape[0])]


def _stacked(rows: Sequence[FloatArray], name: str) -> FloatArray:
    """Rows of one shape, float64, as one (m, k) array (m = 0: shape (0, 0))."""
    if not rows:
        return np.zeros((0, 0))
    shape = np.shape(rows[0])
    if len(shape) != 1 or any(not isinstance(r, np.ndarray) or r.dtype != np.float64 or
                              r.shape != shape for r in rows):
        raise ValueError(f'published {name} rows are not float64 vectors of one shape: '
                         'send the records as they are')
    return np.array(rows, dtype=np.float64)
