"""Tests of bumpless transfer and the output rate limit of `core.predictor.AdaptivePredictor`.

Issue 13, hypothesis 4: where the output's source changes (cascade fallback ↔ network, old → new
network) the estimate used to jump. With ``switch_blend_time`` T > 0 it ramps smoothly from the
old source's value to the new one's; ``max_output_rate`` bounds how fast it moves. Both are off
by default and then change nothing. Small Algorithm 4.1 windows at h = 1 s as in
test_predictor.py (first training after 120 samples, Δ = 20 samples), inline trainings.
"""
from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray
import pytest

from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from sim_ros.simulation import load_scenario, simulate

pytestmark = pytest.mark.filterwarnings(
    'ignore:`torch.jit.script` is deprecated:DeprecationWarning'
)

FloatArray = NDArray[np.float64]
SMALL = PredictorParams(ndof=1, sample_time=1.0, retrain_period=20.0, training_window=200.0,
                        transient_length=10.0, filter_window=60.0, append_length=40.0,
                        estimation_window=480.0, max_epochs=5, nu=4, ny=12)
FIRST_TRAINING = 120  # [samples] the first network is in service from the next sample on
GUARD_WINDOW = (250, 280)  # [samples] the network is forced to lose in this window
N_SAMPLES = 330


@functools.cache
def onedof_record(seed: int, duration: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(t, measured pose, thrust) of the onedof_excited scenario at h = 1 s."""
    record = simulate(load_scenario('onedof_excited'), seed, duration)
    return record.t, record.measured_pose, record.thrust


def run(forced: tuple[int, int] | None = GUARD_WINDOW, max_trainings: int | None = 1,
        **changes: object) -> tuple[FloatArray, AdaptivePredictor]:
    """Outputs (north) of an inline predictor on seed 5; the guard trips for samples in forced."""
    t, pose, force = onedof_record(5, 400.0)
    predictor = AdaptivePredictor(SMALL.replace(**changes), background=False,
                                  max_trainings=max_trainings)
    plausible = predictor._plausible
    sample = {'k': 0}

    def forced_guard(prediction: FloatArray, y: FloatArray) -> bool:
        if forced is not None and forced[0] <= sample['k'] < forced[1]:
            return False  # the network loses: the cascade stands in
        return plausible(prediction, y)

    predictor._plausible = forced_guard  # type: ignore[method-assign]
    out = []
    for k in range(N_SAMPLES):
        sample['k'] = k
        out.append(predictor.update(float(t[k]), pose[k], force[k])[0])
    return np.array(out), predictor


def largest_step(out: FloatArray, start: int, stop: int) -> float:
    """Largest one-sample change of the output between samples start and stop."""
    return float(np.max(np.abs(np.diff(out[start:stop]))))


# ---- off by default: nothing changes -------------------------------------------------------

def test_defaults_are_off_and_the_output_path_is_untouched(
        monkeypatch: pytest.MonkeyPatch) -> None:
    params = PredictorParams()
    assert params.switch_blend_time == 0.0 and params.max_output_rate == (0.0, 0.0, 0.0)

    def never(*_args: object) -> None:
        raise AssertionError('the bumpless stage runs with the defaults')

    monkeypatch.setattr(AdaptivePredictor, '_bumpless', never)
    out, predictor = run()
    assert predictor.source_switches == 0 and np.all(np.isfinite(out))


def test_blending_changes_the_output_only_within_t_after_a_switch(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Same run with T = 5 s: bit-identical to the default run except in the blend windows.

    The holding network alone (motion gate off): the gate's twin is a predictor of its own with
    its own transfers, which the spy would count as well.
    """
    blend = 5.0
    plain, _ = run(max_trainings=None, motion_gate=False)
    starts: list[float] = []
    begin = AdaptivePredictor._begin_transfer

    def spy(self: AdaptivePredictor, t: float, *args: object) -> None:
        starts.append(t)
        begin(self, t, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(AdaptivePredictor, '_begin_transfer', spy)
    blended, predictor = run(max_trainings=None, motion_gate=False, switch_blend_time=blend)
    # cascade → first network, new networks every Δ = 20 samples, the forced switches
    assert predictor.source_switches == len(starts) >= 8
    t = onedof_record(5, 400.0)[0][:N_SAMPLES]
    inside = np.zeros(N_SAMPLES, dtype=bool)
    for start in starts:
        inside |= (t >= start) & (t < start + blend)
    assert np.array_equal(blended[~inside], plain[~inside])  # bit for bit
    assert np.any(blended[inside] != plain[inside])


# ---- bumpless: forced switches --------------------------------------------------------------

def kicks(out: FloatArray, start: int, stop: int) -> float:
    """Largest change of the one-sample step (a step in rate) between samples start and stop."""
    return float(np.max(np.abs(np.diff(out[start - 2:stop], 2))))


def test_forced_switches_step_with_blending_off_and_ramp_with_it_on() -> None:
    """Cascade → network at the first training, network → cascade → network (forced guard).

    The vessel moves fast here (the outputs' own steps reach 0.6 m/s), so a switch is judged by
    the kick it adds to the output's motion (second difference) and by its step against the
    sources' own steps around it.
    """
    blend = 10.0
    plain, _ = run()
    smooth, predictor = run(switch_blend_time=blend)
    assert predictor.source_switches == 3
    switches = (FIRST_TRAINING, *GUARD_WINDOW)  # the first sample of each new source
    steps = np.abs(np.diff(plain))  # steps[k - 1]: the step into sample k
    normal_kick = kicks(plain, 150, GUARD_WINDOW[0])  # the network alone: 0.24 m
    for k in switches:
        around = max(steps[k - 6:k - 1].max(), steps[k:k + 12].max())  # the sources' own steps
        plain_kick, smooth_kick = kicks(plain, k, k + 1), kicks(smooth, k, k + int(blend))
        assert plain_kick > 3.0 * normal_kick  # today: 1.76, 1.00, 0.83 m
        assert smooth_kick < 0.5 * plain_kick  # blended: 0.36, 0.25, 0.22 m
        assert abs(smooth[k] - smooth[k - 1]) <= around  # no step beyond the sources' own
    assert steps[FIRST_TRAINING - 1] > 1.5 and steps[GUARD_WINDOW[1] - 1] > 1.4  # 1.80, 1.42
    after = slice(GUARD_WINDOW[1] + int(blend), N_SAMPLES)  # the blend is over
    assert np.array_equal(smooth[after], plain[after])


def test_switching_back_during_a_blend_reverses_it_without_a_step() -> None:
    """The network loses for one sample only: the output stays near its smooth course."""
    chatter = (GUARD_WINDOW[0], GUARD_WINDOW[0] + 1)
    plain, _ = run(forced=chatter)
    smooth, predictor = run(forced=chatter, switch_blend_time=10.0)
    assert predictor.source_switches == 3
    k = chatter[0]
    assert kicks(plain, k, k + 2) > 2.0 * kicks(smooth, k, k + 10)
    after = slice(chatter[1] + 10, N_SAMPLES)  # the second blend is over
    assert np.array_equal(smooth[after], plain[after])


def test_new_segment_fades_from_the_last_output() -> None:
    t, pose, force = onedof_record(5, 400.0)
    outputs = {}
    for blend in (0.0, 10.0):
        predictor = AdaptivePredictor(SMALL.replace(switch_blend_time=blend), background=False,
                                      max_trainings=1)
        out = [predictor.update(float(t[k]), pose[k], force[k])[0] for k in range(200)]
        predictor.restart_segment()  # a gap of 2 s: the network cannot predict for ny samples
        out += [predictor.update(float(t[k]), pose[k], force[k])[0] for k in range(202, 230)]
        outputs[blend] = np.array(out)
    plain, smooth = outputs[0.0], outputs[10.0]
    outside = np.r_[0:FIRST_TRAINING, FIRST_TRAINING + 10:200]  # the first blend is over
    assert np.array_equal(plain[outside], smooth[outside])
    assert abs(smooth[200] - smooth[199]) < 0.5 * abs(plain[200] - plain[199])


# ---- rate limit ------------------------------------------------------------------------------

def test_rate_limit_bounds_every_step() -> None:
    rate = 0.05  # [m/s]
    limited, _ = run(max_output_rate=(rate, 0.0, 0.0))
    plain, _ = run()
    assert largest_step(plain, 1, N_SAMPLES) > 3.0 * rate
    assert largest_step(limited, 1, N_SAMPLES) <= rate * SMALL.sample_time + 1e-12


def test_rate_limit_on_a_heading_across_pi() -> None:
    """3 DOF, heading about π: yaw steps wrapped, every DOF within its own limit."""
    n = 60
    t = np.arange(n, dtype=float)
    yaw = np.pi + 0.3 * np.sin(2.0 * math.pi * t / 20.0)
    pose = np.column_stack([np.sin(t / 5.0), np.cos(t / 7.0), yaw - 2.0 * np.pi * (yaw > np.pi)])
    rates = np.array([0.02, 0.03, 0.01])
    predictor = AdaptivePredictor(PredictorParams(max_output_rate=tuple(rates)),
                                  background=False)
    out = np.array([predictor.update(float(t[k]), pose[k], np.zeros(3)) for k in range(n)])
    steps = np.diff(out, axis=0)
    steps[:, 2] = np.pi - np.mod(np.pi - steps[:, 2], 2.0 * np.pi)
    assert np.all(np.abs(steps) <= rates + 1e-12)
    assert np.all(np.abs(out[:, 2]) <= np.pi)


# ---- validation ------------------------------------------------------------------------------

@pytest.mark.parametrize(('changes', 'message'), [
    ({'switch_blend_time': -1.0}, 'switch_blend_time must be ≥ 0'),
    ({'switch_blend_time': math.inf}, 'switch_blend_time must be finite'),
    ({'max_output_rate': (0.1, -0.1, 0.0)}, 'max_output_rate must be ≥ 0'),
    ({'max_output_rate': (0.1, 0.1)}, 'max_output_rate must be three numbers'),
    ({'max_output_rate': (0.1, math.nan, 0.0)}, 'max_output_rate must be finite'),
])
def test_negative_or_malformed_values_are_rejected(changes: dict[str, object],
                                                   message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PredictorParams().replace(**changes)


def test_new_fields_round_trip_through_a_dict() -> None:
    params = PredictorParams.from_dict({'switch_blend_time': 10,
                                        'max_output_rate': [0.5, 0.5, 0.02]})
    assert params.switch_blend_time == 10.0 and params.max_output_rate == (0.5, 0.5, 0.02)
    assert params.to_dict()['max_output_rate'] == [0.5, 0.5, 0.02]
    assert PredictorParams.from_dict(params.to_dict()) == params
