"""Rows appended to an array that grows, for callbacks that must stay light (issue 13, cost).

A list of per-sample arrays is cheap to append to but costs milliseconds to turn into one array
when a check or a job needs it, in the one callback that asks, or on a thread that holds the
node's GIL meanwhile (docs/BENCHMARKS.md, sixty-seventh and sixty-eighth sessions). `RowBuffer`
writes each row into a preallocated array instead. A row once written is never written again:
when the array is full the kept rows move to a new one (twice as many rows), so a `view` handed
out (to another thread, to a pickle) stays as it was while appends go on.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import DTypeLike, NDArray

MIN_ROWS = 64  # rows of a buffer's first array [-]


class RowBuffer:
    """Rows of one shape and dtype, oldest first; at most ``capacity`` kept (None: all)."""

    def __init__(self, row_shape: tuple[int, ...] = (), dtype: DTypeLike = np.float64,
                 capacity: int | None = None) -> None:
        """An empty buffer of rows shaped ``row_shape``; ``capacity`` ≥ 1 drops the oldest."""
        if capacity is not None and not (isinstance(capacity, int) and capacity >= 1):
            raise ValueError(f'a row buffer needs a capacity >= 1 (or None), got {capacity!r}')
        self.capacity = capacity
        self._data: NDArray[Any] = np.empty((0, *row_shape), dtype=dtype)
        self._start = 0
        self._end = 0

    def __len__(self) -> int:
        return self._end - self._start

    @property
    def row_shape(self) -> tuple[int, ...]:
        """The shape of one row."""
        return tuple(self._data.shape[1:])

    def append(self, row: Any) -> None:
        """Write ``row`` after the newest (numpy's assignment rules); beyond capacity drop one."""
        if self._end == self._data.shape[0]:
            self._move()
        self._data[self._end] = row
        self._end += 1
        if self.capacity is not None and self._end - self._start > self.capacity:
            self._start += 1

    def clear(self) -> None:
        """Forget every row (views handed out stay as they are)."""
        self._start = self._end

    def view(self) -> NDArray[Any]:
        """The kept rows as a read-only view (a snapshot: later appends do not change it)."""
        view = self._data[self._start:self._end]
        view.flags.writeable = False
        return view

    def _move(self) -> None:
        """The kept rows into a new array with room for as many again."""
        kept = self._end - self._start
        rows = max(MIN_ROWS, 2 * kept)
        if self.capacity is not None:
            rows = min(rows, 2 * self.capacity)  # > kept: kept ≤ capacity
        moved = np.empty((rows, *self._data.shape[1:]), dtype=self._data.dtype)
        moved[:kept] = self._data[self._start:self._end]
        self._data, self._start, self._end = moved, 0, kept
