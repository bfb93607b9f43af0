"""Rows appended to a growing array (core/row_buffer.py): views stay, capacity holds."""
from __future__ import annotations

import numpy as np
import pytest

from lf_predictor_ros.core.row_buffer import MIN_ROWS, RowBuffer


def test_rows_come_back_in_order_across_the_moves() -> None:
    buffer = RowBuffer((2,))
    rows = np.arange(2 * (5 * MIN_ROWS + 3), dtype=float).reshape(-1, 2)
    for row in rows:
        buffer.append(row)
    assert len(buffer) == rows.shape[0] and buffer.row_shape == (2,)
    np.testing.assert_array_equal(buffer.view(), rows)


def test_capacity_keeps_the_newest_rows() -> None:
    buffer = RowBuffer(dtype=np.intp, capacity=100)
    for k in range(1000):
        buffer.append(k)
        assert len(buffer) == min(k + 1, 100)
    assert buffer.view().tolist() == list(range(900, 1000))
    one = RowBuffer(capacity=1)
    for k in range(5):
        one.append(float(k))
    assert one.view().tolist() == [4.0]


def test_a_view_is_a_read_only_snapshot() -> None:
    buffer = RowBuffer(capacity=50)
    for k in range(70):
        buffer.append(float(k))
    snapshot = buffer.view()
    kept = snapshot.copy()
    for k in range(70, 400):  # several moves, and rows dropped at the front
        buffer.append(float(k))
    buffer.clear()
    buffer.append(-1.0)
    np.testing.assert_array_equal(snapshot, kept)  # rows 20 … 69, untouched
    assert kept.tolist() == [float(k) for k in range(20, 70)]
    assert buffer.view().tolist() == [-1.0]
    with pytest.raises(ValueError, match='read-only'):
        snapshot[0] = 0.0


def test_clear_empties_it() -> None:
    buffer = RowBuffer((3,))
    buffer.append(np.ones(3))
    buffer.clear()
    assert len(buffer) == 0 and buffer.view().shape == (0, 3)


@pytest.mark.parametrize('capacity', [0, -1, 2.0])
def test_invalid_capacity(capacity: object) -> None:
    with pytest.raises(ValueError, match='capacity >= 1'):
        RowBuffer(capacity=capacity)  # type: ignore[arg-type]
