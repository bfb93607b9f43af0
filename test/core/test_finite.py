"""core.finite: the predict path's cheap finiteness check."""
from __future__ import annotations

import math

import numpy as np

from lf_predictor_ros.core.finite import all_finite


def test_all_finite_is_np_isfinite_over_every_array() -> None:
    assert all_finite(np.array([1.0, -2.0, 0.0]), np.zeros((2, 3)), [4.0])
    assert all_finite()
    assert all_finite(np.zeros(0))
    for bad in (math.nan, math.inf, -math.inf):
        assert not all_finite(np.array([1.0, bad, 0.0]))
        assert not all_finite(np.zeros(3), np.array([[0.0, bad]]))
    rng = np.random.default_rng(4)
    for _ in range(100):
        x = rng.choice([0.0, 1.5, math.nan, math.inf], size=(2, 3), p=[0.4, 0.5, 0.05, 0.05])
        assert all_finite(x) == bool(np.all(np.isfinite(x)))
