"""benchmark.suite helpers with known answers (the end-to-end runs are in test_benchmark.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.benchmark.suite import _estimate_rmse, _LoopOutcome
from sim_ros.simulation import SimRecord


def _outcome(t: np.ndarray, truth: np.ndarray, estimate_t: np.ndarray,
             estimates: np.ndarray) -> _LoopOutcome:
    zeros = np.zeros_like(truth)
    record = SimRecord(t, zeros, np.ones(t.size), truth, truth, zeros, zeros, np.ones(t.size))
    return _LoopOutcome(record, False, {}, estimate_t, estimates)


def test_estimate_rmse_compares_each_estimate_with_the_truth_when_it_was_fed() -> None:
    """Truth on a 0.1 s grid, estimates every 1 s with known offsets; heading wrapped."""
    t = np.round(np.arange(0.0, 100.0, 0.1), 10)
    truth = np.zeros((t.size, 3))
    truth[:, 0] = 0.05 * t  # moving north: an estimate at the wrong sample would show it
    truth[:, 2] = math.pi - 0.01  # heading just below π
    estimate_t = np.arange(1.0, 100.0, 1.0)
    estimates = np.zeros((estimate_t.size, 3))
    estimates[:, 0] = 0.05 * estimate_t + np.where(np.arange(estimate_t.size) % 2, 0.3, -0.3)
    estimates[:, 1] = 0.4
    estimates[:, 2] = -math.pi + 0.01  # 0.02 rad from the truth across ±π
    rmse = _estimate_rmse(_outcome(t, truth, estimate_t, estimates), 3, start=10.0)
    assert rmse['north'] == pytest.approx(0.3, rel=1e-9)
    assert rmse['east'] == pytest.approx(0.4, rel=1e-9)
    assert rmse['yaw'] == pytest.approx(0.02, rel=1e-6)
    # samples before start are not scored: a large early error changes nothing
    early = estimates.copy()
    early[:5, 0] += 100.0
    assert _estimate_rmse(_outcome(t, truth, estimate_t, early), 3, 10.0) == rmse
    # one DOF; an empty (aborted before start) loop is NaN, not a crash
    assert _estimate_rmse(_outcome(t, truth, estimate_t, estimates), 1, 10.0) == \
        {'north': pytest.approx(0.3, rel=1e-9)}
    empty = _estimate_rmse(_outcome(t, truth, np.zeros(0), np.zeros((0, 3))), 3, 10.0)
    assert all(math.isnan(v) for v in empty.values())
