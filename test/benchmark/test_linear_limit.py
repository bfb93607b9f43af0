"""The linear limit: least squares on the truth, causal, exact where the truth is linear."""
from __future__ import annotations

import numpy as np
import pytest

from lf_predictor_ros.benchmark.linear_limit import linear_limit


def _series(n: int = 3000, seed: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 3))
    lf = np.cumsum(0.01 * rng.standard_normal((n, 3)), axis=0)
    wave = 0.5 * np.sin(0.8 * np.arange(n))[:, None] * np.ones(3)
    return lf + wave, u, lf


def test_exact_when_the_truth_is_the_measurement_minus_a_lagged_combination() -> None:
    """truth[k] = y[k] − 0.5 (y[k] − y[k−1]) + 0.1 u[k−2]: inside the span, so RMSE ≈ 0."""
    y, u, _ = _series()
    truth = y.copy()
    truth[2:] = y[2:] - 0.5 * (y[2:] - y[1:-1]) + 0.1 * u[:-2]
    out = linear_limit(y, u, truth, 3, nu=4, ny=4, begin=10)
    assert np.max(np.abs(out[10:] - truth[10:])) < 1e-9
    assert np.array_equal(out[:3], y[:3])  # before a full history: the measurement


def test_fits_only_from_begin_and_never_modifies_inputs() -> None:
    y, u, lf = _series()
    copies = (y.copy(), u.copy(), lf.copy())
    out = linear_limit(y, u, lf, 1, nu=2, ny=12, begin=500)
    assert np.array_equal(out[:500, 0], y[:500, 0]) and np.all(out[:, 1:] == 0.0)
    rmse = np.sqrt(np.mean((out[500:, 0] - lf[500:, 0]) ** 2))
    raw = np.sqrt(np.mean((y[500:, 0] - lf[500:, 0]) ** 2))
    assert rmse < 0.5 * raw  # a 12-tap FIR removes most of a pure 0.8 rad/s sinusoid
    for a, b in zip((y, u, lf), copies, strict=True):
        assert np.array_equal(a, b)


def test_needs_enough_samples_and_valid_orders() -> None:
    y, u, lf = _series(100)
    with pytest.raises(ValueError, match='record longer'):
        linear_limit(y, u, lf, 3, nu=12, ny=24, begin=0)
    with pytest.raises(ValueError, match='ny >= 1'):
        linear_limit(y, u, lf, 1, nu=1, ny=0, begin=0)
