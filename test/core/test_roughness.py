"""Roughness guard: an LF estimate is smoother than the measurement (core/roughness.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.roughness import RoughnessGuard

H = 1.0  # s
OMEGA = 0.8  # rad/s, wave peak


def _measured(t: float, rng: np.random.Generator) -> np.ndarray:
    """LF ramp 0.02 m/s + 0.5 m wave at ω0 + 0.05 m noise (north, east; heading 0.01 rad wave)."""
    wave = math.sin(OMEGA * t)
    return np.array([0.02 * t + 0.5 * wave, -0.01 * t + 0.4 * wave, 0.01 * wave]) + \
        rng.normal(0.0, [0.05, 0.05, 0.001])


def test_an_lf_estimate_is_never_rough_a_limit_cycle_is_at_once() -> None:
    """A smooth estimate (the ramp + 8 % of the wave) never trips; ±1.2 m per sample does.

    Second differences: the measurement's ≈ (ω0 h)² 0.5 m ≈ 0.32 m RMS (+ noise), the estimate's
    ≈ 0.64 · 0.04 = 0.026 m; the limit cycle's 4 × 1.2 = 4.8 m, so its EWMA passes the
    measurement's on the second sample of the cycle (the first second difference is 1.2 m:
    1.44 / 30 < 0.12 m²; the next 3.6 m: 13 / 30 > 0.12 m²).
    """
    guard = RoughnessGuard(3, H, 30.0, ratio=1.0)
    rng = np.random.default_rng(0)
    trips = []
    for k in range(400):
        t = k * H
        residual = 0.08 * np.array([0.5, 0.4, 0.01]) * math.sin(OMEGA * t)  # 8 % of the wave
        estimate = np.array([0.02 * t, -0.01 * t, 0.0]) + residual
        trips.append(guard.update(_measured(t, rng), estimate))
    assert not any(trips)
    first = None
    for k in range(400, 420):
        t = k * H
        estimate = np.array([0.02 * t, -0.01 * t, 0.0])
        estimate[0] += 1.2 * (-1) ** k
        if guard.update(_measured(t, rng), estimate) and first is None:
            first = k
    assert first == 401
    # back to smooth: the EWMA of 23 m² decays below ≈ 0.12 m² after ln(23/0.12) · 30 ≈ 160 s
    cleared = None
    for k in range(420, 800):
        t = k * H
        estimate = np.array([0.02 * t, -0.01 * t, 0.0])
        if not guard.update(_measured(t, rng), estimate) and cleared is None:
            cleared = k
    assert cleared is not None and 120 <= cleared - 420 <= 220


def test_heading_wrap_is_no_roughness_and_none_restarts() -> None:
    """A heading that crosses ±π smoothly is smooth; None forgets the prediction's history."""
    guard = RoughnessGuard(3, H, 10.0, ratio=1.0)
    rng = np.random.default_rng(1)
    for k in range(100):
        heading = math.remainder(math.pi - 0.5 + 0.01 * k, 2 * math.pi)  # crosses +π at k = 50
        measured = np.array([0.0, 0.0, heading]) + rng.normal(0.0, [0.05, 0.05, 0.01])
        assert not guard.update(measured, np.array([0.0, 0.0, heading]))
    assert not guard.update(np.zeros(3), None)
    # two predictions after None: no second difference yet, however wild
    assert not guard.update(np.zeros(3), np.array([100.0, 0.0, 0.0]))
    assert not guard.update(np.zeros(3), np.array([-100.0, 0.0, 0.0]))
    assert guard.update(np.zeros(3), np.array([100.0, 0.0, 0.0]))
    guard.reset()
    assert not guard.update(np.zeros(3), np.array([100.0, 0.0, 0.0]))


def test_non_finite_values_are_skipped_and_bad_settings_raise() -> None:
    guard = RoughnessGuard(1, H, 5.0, ratio=1.0)
    for k in range(10):
        assert not guard.update(np.array([0.1 * (-1) ** k]), np.array([0.01 * k]))
    assert not guard.update(np.array([math.nan]), np.array([math.inf]))
    with pytest.raises(ValueError, match='ratio must be > 0'):
        RoughnessGuard(1, 1.0, 5.0, ratio=0.0)
    with pytest.raises(ValueError, match='time_constant > sample_time'):
        RoughnessGuard(1, 1.0, 1.0)
    with pytest.raises(ValueError, match='roughness_guard_time'):
        PredictorParams(sample_time=1.0, roughness_guard_time=0.5)
    assert PredictorParams(sample_time=1.0, roughness_guard_time=30.0).roughness_guard_time == 30.0


def test_the_default_ratio_passes_a_rough_estimate_and_trips_a_limit_cycle() -> None:
    """At ROUGHNESS_RATIO (50) a rough estimate passes, a limit cycle trips.

    An estimate 3× rougher than the measurement (ratio 9) passes; the ±1.2 m cycle (second
    differences 4.8 m against 0.32 m: ratio ≈ 225) trips within 4 s.
    """
    guard = RoughnessGuard(1, H, 30.0)
    rng = np.random.default_rng(2)
    for k in range(300):
        t = k * H
        measured = np.array([0.3 * math.sin(OMEGA * t)])
        assert not guard.update(measured, 3.0 * measured + rng.normal(0.0, 1e-3, 1))
    tripped = [guard.update(np.array([0.3 * math.sin(OMEGA * k)]), np.array([1.2 * (-1) ** k]))
               for k in range(300, 310)]
    assert any(tripped[:4]) and all(tripped[4:])
