"""Roughness guard: an LF estimate is smoother than the measurement (core/roughness.py)."""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from lf_predictor_ros.core import predictor as predictor_module
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.roughness import RoughnessGuard
from sim_ros.simulation import load_scenario, simulate

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


# ---- the predictor: a rough network is retired (core/predictor.py) ------------------------

def _forced_rough_run(trip_at: tuple[int, ...], sea_change_at: int | None = None,
                      monkeypatch: pytest.MonkeyPatch | None = None,
                      ) -> tuple[list[object], list[str], AdaptivePredictor]:
    """Per sample the network in service and the state, with the guard forced at ``trip_at``.

    An inline adaptive predictor with small windows on onedof_excited seed 5 at h = 1 s. With
    ``sea_change_at`` the training applied at that sample reports a change of sea state.
    """
    record = simulate(load_scenario('onedof_excited'), 5, 300.0)
    params = PredictorParams(ndof=1, sample_time=1.0, retrain_period=20.0, training_window=200.0,
                             transient_length=10.0, filter_window=60.0, append_length=40.0,
                             estimation_window=480.0, max_epochs=3, nu=4, ny=12,
                             roughness_guard_time=30.0)
    predictor = AdaptivePredictor(params, background=False)
    guard = predictor._roughness
    assert guard is not None
    real = guard.update
    sample = {'k': 0}

    def forced(measured: np.ndarray, predicted: np.ndarray | None) -> bool:
        return real(measured, predicted) or (sample['k'] in trip_at and predicted is not None)

    guard.update = forced  # type: ignore[method-assign]
    if monkeypatch is not None:
        retrain = predictor_module.run_retraining

        def restarting(*args: Any) -> Any:
            result = retrain(*args)
            return dataclasses.replace(result, restarted=sample['k'] == sea_change_at)

        monkeypatch.setattr(predictor_module, 'run_retraining', restarting)
    models: list[object] = []
    states: list[str] = []
    for k in range(len(record.t)):
        sample['k'] = k
        out = predictor.update(float(record.t[k]), record.measured_pose[k], record.thrust[k])
        assert np.all(np.isfinite(out))
        models.append(predictor.model)
        states.append(predictor.status().state)
    return models, states, predictor


@pytest.mark.filterwarnings('ignore:`torch.jit.script` is deprecated:DeprecationWarning')
def test_a_rough_network_is_retired_for_the_one_before_then_the_cascade() -> None:
    """A trip retires the network in service for the one before it; a second for the cascade.

    Networks are installed at 119, 139, 159: a trip at 165 brings back the one of 139; a second
    trip at 167 retires that one too: the cascade until the training at 179 brings a new network.
    Without trips the networks change only at trainings.
    """
    models, states, predictor = _forced_rough_run((165, 167))
    assert models[164] is not None and models[164] is not models[150]  # the 159 network
    assert models[150] is not None and models[150] is not models[130]  # the 139 network
    assert models[165] is models[150]  # retired: the network before it serves
    assert states[166] == 'trained'
    assert models[167] is None and states[167] == 'fallback'  # a second trip: the cascade
    assert models[178] is None
    assert models[179] is not None and models[179] not in (models[150], models[164])
    assert all(models[k] is models[k - 1] for k in range(180, 199))
    assert predictor.counters['rough_retirements'] == 2
    assert predictor.counters['guard_trips'] >= 2


@pytest.mark.filterwarnings('ignore:`torch.jit.script` is deprecated:DeprecationWarning')
def test_after_a_sea_change_a_rough_network_is_retired_for_the_cascade(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The network before a sea change is the old sea's: a trip then brings the cascade.

    The same run as above, the training at 159 reporting a new sea: the trip at 165 retires
    the 159 network for the cascade (tuned to the new ω0), not for the 139 one.
    """
    models, states, predictor = _forced_rough_run((165,), sea_change_at=159,
                                                  monkeypatch=monkeypatch)
    assert models[164] is not None and models[150] is not None
    assert models[165] is None and states[165] == 'fallback'
    assert models[179] is not None
    assert predictor.counters['rough_retirements'] == 1
