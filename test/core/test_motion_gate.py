"""Motion gate (``core.motion_gate``, ``PredictorParams.motion_gate``; issue 13).

The gain g = r²/(1 + r²), r = s²/(k·s̄²), against its analytic values; the blend on the
circle; the gate shut while the vessel does what it usually does and open in a move, also right
after a gap; the gated predictor's output equal, sample by sample, to the blend of the two
networks run on their own; and the twin's checkpoint beside the holding network's.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
import functools
import math
from pathlib import Path
import threading
import time
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray
import pytest
import torch

from lf_predictor_ros.core import yaw_moment_trigger
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.motion_gate import (
    GATE_MIN_FILL,
    GATE_RATIO,
    MotionGate,
    blend,
    dead_zoned,
    gate_gain,
    gate_validated,
    moving_offset,
)
from lf_predictor_ros.core.network import load_checkpoint, save_checkpoint
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor, twin_checkpoint_path
from lf_predictor_ros.core.retraining import run_retraining
from lf_predictor_ros.core.targets import TargetWindow
from lf_predictor_ros.core.yaw_moment_trigger import YawMomentTrigger

FloatArray = NDArray[np.float64]
# The holding network alone (a test switches the gate on); the gate's shaping off, unlike the
# shipped defaults, so that the gated output is the plain blend and a test sets the stage it
# checks: no low-pass (motion_gate_smoothing 0), no dead zone, the heading gated too by the
# velocity gain (not the yaw moment's), and a line (ramp_order 1) for the twin
# (SMALL.replace(ramp_invariant=True), the same network).
SMALL = PredictorParams(ndof=3, sample_time=1.0, retrain_period=20.0, training_window=200.0,
                        transient_length=10.0, filter_window=60.0, append_length=40.0,
                        estimation_window=480.0, max_epochs=5, nu=4, ny=12,
                        motion_gate=False, motion_gate_smoothing=0.0, motion_gate_dead_zone=0.0,
                        motion_gate_yaw=True, motion_gate_yaw_moment_ratio=0.0, ramp_order=1)


def test_gain_is_half_where_the_velocity_is_sqrt_k_times_usual() -> None:
    usual = np.array([0.01, 0.04, 1e-6])
    assert gate_gain(GATE_RATIO * usual, usual) == pytest.approx([0.5, 0.5, 0.5])
    assert gate_gain(np.zeros(3), usual) == pytest.approx(np.zeros(3))
    assert gate_gain(np.ones(3), np.zeros(3)) == pytest.approx(np.ones(3))
    assert gate_gain(np.zeros(3), np.zeros(3)) == pytest.approx(np.zeros(3))  # nothing seen
    assert gate_gain(usual, usual, ratio=1.0) == pytest.approx([0.5, 0.5, 0.5])
    assert gate_gain(usual, usual) == pytest.approx(np.full(3, 1.0 / (1.0 + GATE_RATIO ** 2)))
    assert gate_gain(3.0 * GATE_RATIO * usual, usual) == pytest.approx(np.full(3, 0.9))


def test_blend_takes_the_short_way_round_and_keeps_its_inputs() -> None:
    holding = np.array([1.0, 2.0, math.pi - 0.1])
    moving = np.array([3.0, 0.0, -math.pi + 0.1])
    out = blend(holding, moving, np.array([0.5, 0.25, 0.5]), 3)
    assert out == pytest.approx([2.0, 1.5, math.pi], abs=1e-12) or \
        out == pytest.approx([2.0, 1.5, -math.pi], abs=1e-12)
    assert holding[2] == math.pi - 0.1 and moving[0] == 3.0
    one = blend(np.array([1.0, 5.0, 0.3]), np.array([3.0, 9.0, 0.9]), np.array([0.5]), 1)
    assert one == pytest.approx([2.0, 5.0, 0.3])  # 1 DOF: only north is blended


def test_gate_stays_shut_while_holding_and_opens_in_a_move() -> None:
    gate = MotionGate(3, 1.0, time_constant=10.0, window=600.0)
    rng = np.random.default_rng(4)
    pose = np.zeros(3)
    gains = []
    for _k in range(1200):  # holding: slow random LF motion, RMS step ≈ 0.01 m, 2e-4 rad
        pose = 0.99 * pose + rng.normal(0.0, [0.01, 0.01, 0.0002])
        gains.append(gate.update(pose))
    holding = np.array(gains[600:])
    assert np.all(np.mean(holding, axis=0) < 0.3)
    velocity = np.array([0.3, -0.2, 0.005])  # [m/s, m/s, rad/s]: a setpoint move and a turn
    for k in range(60):
        gain = gate.update(pose + (k + 1) * velocity)
    assert np.all(gain > 0.9)
    assert np.all(gate.update(np.array([np.nan, 0.0, 0.0])) == 0.0)
    gate.restart()  # a gap: the usual velocity is kept, the move is still unusual
    for k in range(60):
        gain = gate.update(pose + 40.0 + (k + 1) * velocity)
    assert np.all(gain > 0.9)
    gate.reset()  # everything forgotten: shut until a quarter of the window is seen again
    for k in range(149):
        assert np.all(gate.update(pose + (k + 1) * velocity) == 0.0)
    assert np.all(gate.update(pose + 150 * velocity) > 0.0)


def test_a_fade_in_ramps_the_gains_when_the_warm_up_ends_in_a_move() -> None:
    """The warm-up (a quarter of the window: 150 samples) ends while the vessel moves.

    Without a fade-in the gain steps from 0 to its full value (> 0.9) in one sample; with
    ``fade_in`` 10 s at h = 1 s the n-th sample after the warm-up gets n/10 of the same gain,
    the tenth and every later one all of it. ``reset`` fades in again; a bad fade-in is refused
    and the predictor hands its parameter over.
    """
    rng = np.random.default_rng(4)
    poses = np.cumsum(rng.normal(0.0, [0.01, 0.01, 0.0002], size=(200, 3)), axis=0)
    velocity = np.array([0.3, -0.2, 0.005])  # [m/s, m/s, rad/s]: the move from sample 120
    poses[120:] += np.arange(1, 81)[:, None] * velocity
    runs = {}
    for fade_in in (0.0, 10.0):
        gate = MotionGate(3, 1.0, time_constant=10.0, window=600.0, fade_in=fade_in)
        runs[fade_in] = np.array([gate.update(pose) for pose in poses])
    plain, faded = runs[0.0], runs[10.0]
    np.testing.assert_array_equal(plain[:149], 0.0)
    assert np.all(plain[149] > 0.9)  # the step the fade-in is for
    for n in range(1, 11):
        np.testing.assert_allclose(faded[148 + n], plain[148 + n] * n / 10.0, rtol=1e-12)
    np.testing.assert_array_equal(faded[158:], plain[158:])
    np.testing.assert_array_equal(faded[:149], 0.0)
    gate = MotionGate(3, 1.0, time_constant=10.0, window=600.0, fade_in=10.0)
    for pose in poses:
        gate.update(pose)
    gate.reset()
    again = np.array([gate.update(pose) for pose in poses[:151]])
    np.testing.assert_allclose(again[149:], faded[149:151], rtol=1e-12)
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match='fade_in must be finite and >= 0'):
            MotionGate(3, 1.0, fade_in=bad)
    with pytest.raises(ValueError, match='motion_gate_fade_in must be ≥ 0'):
        PredictorParams(motion_gate_fade_in=-1.0)
    predictor = AdaptivePredictor(SMALL.replace(motion_gate=True, motion_gate_fade_in=4.0),
                                  background=False)
    try:
        assert predictor._gate is not None and predictor._gate._fade_samples == round(
            4.0 / SMALL.sample_time)
    finally:
        predictor.close()


def test_motion_gate_time_sets_how_soon_a_move_opens_the_gate() -> None:
    """At T = h the first step of a move opens the gate; at T = 10 h only 1/10 of it counts."""
    first_gains = {}
    for time_constant in (1.0, 10.0):
        gate = MotionGate(3, 1.0, time_constant=time_constant, window=600.0)
        rng = np.random.default_rng(4)
        pose = np.zeros(3)
        for _k in range(1200):  # holding, as above: RMS step ≈ 0.01 m, 2e-4 rad
            pose = 0.99 * pose + rng.normal(0.0, [0.01, 0.01, 0.0002])
            gate.update(pose)
        # a slow move: 3 × the RMS holding step per sample
        first_gains[time_constant] = gate.update(pose + np.array([0.03, -0.03, 0.0006]))
    assert np.all(first_gains[1.0] > 0.75)
    assert np.all(first_gains[10.0] < 0.1)
    # The predictor hands its parameter to its gate: α = h / T.
    predictor = AdaptivePredictor(SMALL.replace(motion_gate=True, motion_gate_time=4.0),
                                  background=False)
    try:
        assert predictor._gate is not None and predictor._gate._alpha == 0.25
    finally:
        predictor.close()


def test_gate_rejects_bad_settings() -> None:
    with pytest.raises(ValueError, match='ndof 1 or 3'):
        MotionGate(2, 1.0)
    with pytest.raises(ValueError, match='time_constant'):
        MotionGate(3, 1.0, time_constant=0.0)
    with pytest.raises(ValueError, match='motion_gate blends'):
        PredictorParams(motion_gate=True, ramp_invariant=True)
    with pytest.raises(ValueError, match='ramp rule'):
        PredictorParams(motion_gate=True, nfb=1)


def moving_run(n: int, seed: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(t, pose, force): holding with waves, then a 30 m setpoint move and a 45° turn."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.float64)
    lf = np.zeros((n, 3))
    ramp = np.clip((t - 0.75 * n) / 100.0, 0.0, 1.0)
    lf[:, 0] = 30.0 * ramp
    lf[:, 2] = 0.2 + math.radians(45.0) * ramp
    waves = np.sin(0.8 * t[:, None] + rng.uniform(0, 6, size=3)) * np.array([0.4, 0.3, 0.01])
    pose = lf + waves + rng.normal(0.0, [0.02, 0.02, 0.001], size=(n, 3))
    force = rng.normal(0.0, 1.0, size=(n, 3))
    return t, pose, force


@dataclass(frozen=True, eq=False)
class Trace:
    """One predictor run over ``moving_run(600, 2)``, read right after every `update`.

    The arrays are read-only copies (a test cannot change what the next one reads).

    Attributes:
        out: the outputs, shape (600, 3).
        gain: `motion_gain`, shape (600, ndof).
        untaken: `untaken_twin_offset`, shape (600, ndof).
        valid: `motion_gate_valid`, shape (600, ndof).
        using_network: the predictor's `using_network`, shape (600,).
        twin_using_network: the twin's (``_moving``) `using_network`; None without a twin.
        targets: the `targets` window (the same object until a new window comes).
        counters: the `counters` after the last sample.

    """

    out: FloatArray
    gain: FloatArray
    untaken: FloatArray
    valid: NDArray[np.bool_]
    using_network: NDArray[np.bool_]
    twin_using_network: NDArray[np.bool_] | None
    targets: tuple[TargetWindow | None, ...]
    counters: Mapping[str, int]


def _frozen(rows: list[Any], dtype: type) -> NDArray[Any]:
    array: NDArray[Any] = np.array(rows, dtype=dtype)  # a new array: every row copied
    array.setflags(write=False)
    return array


def _run(params: PredictorParams) -> Trace:
    """Run `params` (background=False, deterministic) over ``moving_run(600, 2)``."""
    return _run_on(params, *moving_run(600, 2))


def _run_on(params: PredictorParams, t: FloatArray, pose: FloatArray, force: FloatArray
            ) -> Trace:
    """Run `params` (background=False, deterministic) over 600 samples (t, pose, force)."""
    torch.set_num_threads(1)  # one core, whoever calls it (as the autouse fixture sets)
    predictor = AdaptivePredictor(params, background=False)
    out: list[FloatArray] = []
    gain: list[FloatArray] = []
    untaken: list[FloatArray] = []
    valid: list[NDArray[np.bool_]] = []
    on_network: list[bool] = []
    twin_on_network: list[bool] = []
    targets: list[TargetWindow | None] = []
    for k in range(t.size):
        out.append(np.array(predictor.update(t[k], pose[k], force[k]), dtype=np.float64))
        gain.append(np.array(predictor.motion_gain, dtype=np.float64))
        untaken.append(np.array(predictor.untaken_twin_offset, dtype=np.float64))
        valid.append(np.array(predictor.motion_gate_valid, dtype=bool))
        on_network.append(bool(predictor.using_network))
        twin = predictor._moving
        if twin is not None:
            twin_on_network.append(bool(twin.using_network))
        targets.append(predictor.targets)  # immutable: values read-only, frozen
    assert t.size == 600 and len(twin_on_network) in (0, t.size)
    return Trace(out=_frozen(out, np.float64), gain=_frozen(gain, np.float64),
                 untaken=_frozen(untaken, np.float64),
                 valid=_frozen(valid, bool), using_network=_frozen(on_network, bool),
                 twin_using_network=_frozen(twin_on_network, bool) if twin_on_network else None,
                 targets=tuple(targets),
                 counters=MappingProxyType(dict(predictor.counters)))


@pytest.fixture(scope='module')
def trace() -> Callable[[PredictorParams], Trace]:
    """`_run`, cached for the module: each configuration runs once (PredictorParams hashes)."""
    return functools.cache(_run)


def test_gated_output_is_the_blend_of_the_two_networks_run_alone(
        trace: Callable[[PredictorParams], Trace]) -> None:
    gated = trace(SMALL.replace(motion_gate=True))
    assert not SMALL.motion_gate
    holding = trace(SMALL)
    moving = trace(SMALL.replace(ramp_invariant=True))
    blended = 0
    for k in range(gated.out.shape[0]):
        out, a, b = gated.out[k], holding.out[k], moving.out[k]
        gain = gated.gain[k]
        if moving.using_network[k]:
            assert out == pytest.approx(blend(a, b, gain, 3), abs=1e-9)
            blended += int(np.any(gain > 0.5))
            # what the gate left out: (1 − g) · (moving − holding), heading wrapped
            offset = b - a
            offset[2] = wrap_angle(offset[2])
            assert gated.untaken[k] == pytest.approx((1.0 - gain) * offset, abs=1e-9)
        else:
            assert np.all(gain == 0.0) and np.all(gated.untaken[k] == 0.0)
            assert out == pytest.approx(a, abs=1e-12)
    counters = gated.counters
    assert counters['moving_trainings'] == moving.counters['trainings'] > 0
    assert counters['trainings'] == holding.counters['trainings']
    assert blended > 20  # the move opened the gate (not a test of the zero gain only)
    assert np.all(holding.untaken == 0.0)  # no gate: nothing left out
    assert np.max(np.abs(gated.untaken[:, 0])) > 0.02  # the move: the twin ahead [m]


def test_without_yaw_the_gate_blends_north_and_east_and_keeps_the_holding_heading(
        trace: Callable[[PredictorParams], Trace]) -> None:
    """motion_gate_yaw false: yaw gain 0, heading = holding network's, north/east as gated."""
    no_yaw = trace(SMALL.replace(motion_gate=True, motion_gate_yaw=False))
    gated = trace(SMALL.replace(motion_gate=True))
    holding = trace(SMALL)
    assert np.all(no_yaw.gain[:, 2] == 0.0)
    assert np.array_equal(no_yaw.gain[:, :2], gated.gain[:, :2])
    assert no_yaw.out[:, :2] == pytest.approx(gated.out[:, :2], abs=1e-12)
    assert no_yaw.out[:, 2] == pytest.approx(holding.out[:, 2], abs=1e-12)
    assert np.count_nonzero(gated.gain[:, 2] > 0.5) > 20  # the turn opens the gate in yaw
    assert np.max(np.abs(gated.out[:, 2] - holding.out[:, 2])) > 1e-3  # and that shows


def test_the_usual_velocity_is_measured_on_the_twins_network_alone(
        trace: Callable[[PredictorParams], Trace]) -> None:
    """Shut until GATE_MIN_FILL of a training window of the twin's network outputs is seen.

    Before its first training the twin publishes its cascade fallback, another filter with
    other velocities (and the switch to the network is a step, not a motion): the gate must
    not count them as the vessel's usual motion. With SMALL (200 s window) the gate needs 50
    samples of the network after the twin's first training, however long the fallback ran.
    """
    gated = trace(SMALL.replace(motion_gate=True))
    twin = gated.twin_using_network
    assert twin is not None
    needed = math.ceil(GATE_MIN_FILL * SMALL.training_window / SMALL.sample_time)
    on_network = 0
    first_open = None
    for k in range(gated.out.shape[0]):
        on_network += int(twin[k])
        if first_open is None and np.any(gated.gain[k] > 0.0):
            first_open = on_network
    assert needed == 50
    assert first_open is not None and first_open >= needed  # the move opens it later
    assert on_network > needed + 100


def test_smoothed_gate_blends_the_low_passed_offset_of_the_two_networks(
        trace: Callable[[PredictorParams], Trace]) -> None:
    """motion_gate_smoothing T: out = holding + g·LP_T(moving − holding), LP restarting at 0."""
    smoothing = 5.0
    gated = trace(SMALL.replace(motion_gate=True, motion_gate_smoothing=smoothing))
    plain = trace(SMALL.replace(motion_gate=True))
    holding = trace(SMALL)
    moving = trace(SMALL.replace(ramp_invariant=True))
    alpha = SMALL.sample_time / smoothing
    low_passed = np.zeros(3)
    smaller = 0
    for k in range(gated.out.shape[0]):
        out, unsmoothed, a, b = gated.out[k], plain.out[k], holding.out[k], moving.out[k]
        if not moving.using_network[k]:
            low_passed = np.zeros(3)
            assert out == pytest.approx(a, abs=1e-12)
            continue
        low_passed = low_passed + alpha * (moving_offset(a, b, 3) - low_passed)
        gain = gated.gain[k]
        expected = a.copy()
        expected[:3] += gain * low_passed
        assert out[:2] == pytest.approx(expected[:2], abs=1e-9)
        assert math.remainder(out[2] - expected[2], 2 * math.pi) == pytest.approx(0, abs=1e-9)
        smaller += int(np.linalg.norm(out[:2] - a[:2]) < np.linalg.norm(unsmoothed[:2] - a[:2]))
    assert gated.counters['moving_trainings'] > 0
    assert smaller > 100  # the low-pass changed the output (not the unsmoothed gate again)


@pytest.mark.parametrize(('change', 'runs'), [
    ({}, False), ({'switch_blend_time': 5.0}, True), ({'max_output_rate': (1.0, 1.0, 0.1)}, True)])
def test_the_twin_runs_its_cascade_only_where_its_output_can_reach_something(
        change: dict[str, Any], runs: bool) -> None:
    # The gate reads the twin only while its network serves (nfb 0 and no smoothing: nothing
    # else reads its cascade), so its cascade is neither run nor retuned; the blend test above
    # shows the gated output unchanged against a twin run alone, cascade and all.
    predictor = AdaptivePredictor(SMALL.replace(motion_gate=True, **change), background=False)
    t, pose, force = moving_run(600, 2)
    for k in range(300):
        predictor.update(t[k], pose[k], force[k])
    twin = predictor._moving
    assert twin is not None and twin.counters['trainings'] > 0
    assert twin._fallback._filter.initialized is runs
    assert predictor._fallback._filter.initialized  # the holding side's cascade always runs


def test_the_twin_never_trains_beside_the_holding_network(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """In background mode the two trainings share one lock: they run one after the other."""
    intervals: list[tuple[float, float, str]] = []
    guard = threading.Lock()

    def timed(*args: object, **kwargs: object) -> object:
        start = time.monotonic()
        result = run_retraining(*args, **kwargs)  # type: ignore[arg-type]
        time.sleep(0.05)  # widen the window in which an overlap would show
        with guard:
            intervals.append((start, time.monotonic(), threading.current_thread().name))
        return result

    monkeypatch.setattr('lf_predictor_ros.core.predictor.run_retraining', timed)
    # a stand-in defined here cannot run in the child process (it would import this module):
    # the jobs run on the worker threads, as without a child; the lock is taken the same way
    monkeypatch.setattr('lf_predictor_ros.core.predictor.shared_fit_process', lambda: None)
    t, pose, force = moving_run(300, 3)
    gated = AdaptivePredictor(SMALL.replace(motion_gate=True), background=True)
    try:
        for k in range(t.size):
            gated.update(t[k], pose[k], force[k])
            gated.wait_for_training(timeout=30.0)  # the next sample sees the finished jobs
    finally:
        gated.close()
    counters = gated.counters
    assert counters['trainings'] >= 2 and counters['moving_trainings'] >= 2
    ordered = sorted(intervals)
    assert len(ordered) >= 4
    assert all(b[0] >= a[1] for a, b in zip(ordered, ordered[1:], strict=False))


@pytest.mark.parametrize('order', [1, 2])
def test_the_twin_has_its_own_ny_when_given_and_the_ramp_order(order: int) -> None:
    t, pose, force = moving_run(400, 4)
    gated = AdaptivePredictor(SMALL.replace(motion_gate=True, motion_gate_ny=6, ramp_order=order),
                              background=False)
    moving = AdaptivePredictor(SMALL.replace(ramp_invariant=True, ny=6, ramp_order=order),
                               background=False)
    for k in range(t.size):
        gated.update(t[k], pose[k], force[k])
        moving.update(t[k], pose[k], force[k])
    twin = gated._moving  # the twin, to compare with a ramp-invariant network of ny 6
    assert twin is not None and twin.params.ny == 6 and gated.params.ny == SMALL.ny == 12
    assert twin.model is not None and moving.model is not None
    assert twin.model.spec.ramp_order == order
    assert twin.update(t[-1] + 1, pose[-1], force[-1]) == pytest.approx(
        moving.update(t[-1] + 1, pose[-1], force[-1]), abs=1e-9)


@pytest.mark.parametrize(('value', 'message'), [
    (-1.0, 'motion_gate_smoothing must be ≥ 0'),
    (math.nan, 'motion_gate_smoothing must be finite')])
def test_negative_or_nan_smoothing_is_refused(value: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        SMALL.replace(motion_gate=True, motion_gate_smoothing=value)


@pytest.mark.parametrize(('value', 'message'), [
    (0.0, 'motion_gate_time must be > 0'), (math.inf, 'motion_gate_time must be finite')])
def test_a_gate_time_that_is_not_positive_and_finite_is_refused(value: float,
                                                                 message: str) -> None:
    with pytest.raises(ValueError, match=message):
        SMALL.replace(motion_gate=True, motion_gate_time=value)


def test_wait_for_training_keeps_one_timeout_for_both_networks(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """With the twin's job queued behind the holding network's, the wait still ends on time.

    Each training is held 20 s before it runs, or until the checks are done (``release``): the
    jobs are as busy during the checks as with a plain 20 s sleep, and `close` need not wait
    for both sleeps to end.
    """
    started = threading.Event()
    release = threading.Event()

    def slow(*args: object, **kwargs: object) -> object:
        started.set()
        release.wait(timeout=20.0)
        return run_retraining(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr('lf_predictor_ros.core.predictor.run_retraining', slow)
    # the stand-in runs on the worker threads (the child process could not import it)
    monkeypatch.setattr('lf_predictor_ros.core.predictor.shared_fit_process', lambda: None)
    t, pose, force = moving_run(300, 3)
    gated = AdaptivePredictor(SMALL.replace(motion_gate=True), background=True)
    try:
        for k in range(t.size):
            gated.update(t[k], pose[k], force[k])
            if gated.wait_for_training(timeout=0.0):
                continue  # no job running
            # a training (`slow` sets `started` as it begins) or an ω0 job: wait for either
            deadline = time.monotonic() + 30.0
            while not started.wait(timeout=0.01) and time.monotonic() < deadline:
                if gated.wait_for_training(timeout=0.0):
                    break  # an ω0 job, ended before the next sample
            if started.is_set():
                break  # a training is running (and the twin's queued behind it)
        assert started.is_set(), 'no training started'
        begin = time.monotonic()
        assert not gated.wait_for_training(timeout=4.0)  # both jobs still busy
        # one timeout, not one per network (8 s); 2 s to spare on a loaded machine
        assert time.monotonic() - begin < 6.0
    finally:
        release.set()
        gated.close()


def test_gate_validated_compares_the_mean_squared_errors_per_dof() -> None:
    targets = np.zeros((4, 3))
    holding = np.array([[0.1, 0.3, 3.1]] * 4)
    gated = np.array([[0.2, 0.1, -3.1]] * 4)  # yaw: 0.08 rad from π, closer than 3.1 is to 0
    previous = np.array([True, True, True])
    assert gate_validated(holding, gated, targets, previous, 4).tolist() == [False, True, True]
    # errors wrap: the gated yaw 2π − 0.05 is 0.05 from the target
    gated[:, 2] = 2 * math.pi - 0.05
    assert gate_validated(holding, gated, targets, previous, 4).tolist() == [False, True, True]
    # too few finite rows: the previous verdict, as a copy
    gated[1:, 0] = np.nan
    kept = gate_validated(holding, gated, targets, previous, 2)
    assert kept.tolist() == [True, True, True] and kept is not previous
    assert gate_validated(holding[:1, :1], gated[:1, :1], targets[:1, :1], previous[:1],
                          1).tolist() == [False]
    with pytest.raises(ValueError, match='must be'):
        gate_validated(holding, gated[:, :2], targets, previous, 1)


def _wrapped(error: FloatArray) -> FloatArray:
    out = np.array(error, dtype=np.float64)
    out[..., 2] = np.remainder(out[..., 2] + math.pi, 2 * math.pi) - math.pi
    return out


def test_validated_gate_acts_only_on_dofs_where_it_beat_the_holding_network(
        trace: Callable[[PredictorParams], Trace]) -> None:
    """The published output: the holding one on unchecked DOFs, the gated one on checked ones."""
    params = SMALL.replace(motion_gate=True, motion_gate_smoothing=5.0)
    checked = trace(params.replace(motion_gate_validation=True))
    plain = trace(params)
    holding = trace(SMALL)
    held: dict[int, FloatArray] = {}
    gated: dict[int, FloatArray] = {}
    seen = None
    valid = np.zeros(3, dtype=bool)
    checks = acted = 0
    for k in range(checked.out.shape[0]):
        out = checked.out[k]
        gated[k] = plain.out[k]
        held[k] = holding.out[k]  # the samples up to k only, as when run side by side
        targets = checked.targets[k]
        if targets is not None and targets is not seen:
            seen = targets
            usable = len(targets) - SMALL.transient_samples
            pairs = [(i, index - 1) for i, index in enumerate(targets.indices()[:usable])
                     if index - 1 in held]
            if len(pairs) >= usable // 2:
                values = np.array([targets.values[i] for i, _ in pairs])
                hold_mse = np.mean(_wrapped(np.array([held[j] for _, j in pairs]) - values) ** 2,
                                   axis=0)
                gate_mse = np.mean(_wrapped(np.array([gated[j] for _, j in pairs]) - values) ** 2,
                                   axis=0)
                valid = gate_mse < hold_mse
                checks += 1
        assert checked.valid[k].tolist() == valid.tolist(), k
        expected = held[k] + valid * _wrapped(gated[k] - held[k])
        assert _wrapped(out - expected) == pytest.approx(np.zeros(3), abs=1e-9), k
        acted += int(np.any(valid) and np.max(np.abs(gated[k] - held[k])) > 1e-6)
    assert checks >= 3 and acted > 0
    assert plain.valid[-1].tolist() == [True, True, True]  # without the check: always


def test_dead_zone_shuts_small_gains_and_keeps_a_full_one() -> None:
    gain = np.array([0.0, 0.1, 0.2, 0.6, 1.0])
    assert dead_zoned(gain, 0.2) == pytest.approx([0.0, 0.0, 0.0, 0.5, 1.0])
    assert dead_zoned(gain, 0.0) == pytest.approx(gain) and gain[1] == 0.1
    with pytest.raises(ValueError, match=r'\[0, 1\)'):
        dead_zoned(gain, 1.0)
    with pytest.raises(ValueError, match='motion_gate_dead_zone must be in'):
        SMALL.replace(motion_gate=True, motion_gate_dead_zone=-0.1)


def test_the_dead_zone_scales_the_published_gain(
        trace: Callable[[PredictorParams], Trace]) -> None:
    zoned = trace(SMALL.replace(motion_gate=True, motion_gate_dead_zone=0.3))
    plain = trace(SMALL.replace(motion_gate=True))
    shut = opened = 0
    for k in range(zoned.out.shape[0]):
        zoned_gain, plain_gain = zoned.gain[k], plain.gain[k]
        assert zoned_gain == pytest.approx(dead_zoned(plain_gain, 0.3), abs=1e-12)
        shut += int(np.any((plain_gain > 0.0) & (plain_gain <= 0.3)))
        opened += int(np.any(zoned_gain > 0.5))
    assert shut > 0 and opened > 0


# ---- the twin's checkpoint -------------------------------------------------------------------

GATED = SMALL.replace(motion_gate=True)
GATED_BY_MOMENT = GATED.replace(motion_gate_yaw_moment_ratio=5.0, motion_gate_yaw_hold=30.0)
SAVED_AT = 130  # [samples] the saved predictor trained once, at sample 120
FED = 110  # [samples] fed after loading: fewer than a first training needs (120), no training
RUN = SAVED_AT + FED  # the move starts at 0.75 × RUN = 180, 50 samples after the load


@pytest.fixture(scope='module')
def saved(tmp_path_factory: pytest.TempPathFactory) -> tuple[AdaptivePredictor, Path]:
    """A gated predictor trained once on the holding part of `moving_run`, and its checkpoint.

    Saved by the workers (``checkpoint_path`` set after construction, as the node does).
    """
    torch.set_num_threads(1)  # a module fixture runs before the autouse one
    path = tmp_path_factory.mktemp('twin') / 'gated.pt'
    source = AdaptivePredictor(GATED, background=False, max_trainings=1)
    source.checkpoint_path = str(path)
    t, pose, force = moving_run(RUN, 6)
    for k in range(SAVED_AT):
        source.update(t[k], pose[k], force[k])
    assert source.model is not None and source.twin_model is not None
    return source, path


def _rows(model: object, n: int = 40) -> FloatArray:
    spec = model.spec  # type: ignore[attr-defined]
    return np.random.default_rng(41).normal(size=(n, spec.n_regressors)) * 5.0


def test_the_workers_save_the_twin_beside_the_holding_network(
        saved: tuple[AdaptivePredictor, Path]) -> None:
    source, path = saved
    twin_path = Path(twin_checkpoint_path(str(path)))
    assert twin_path.name == 'gated.pt.twin'
    assert sorted(p.name for p in path.parent.iterdir()) == ['gated.pt', 'gated.pt.twin']
    spec, state, meta = load_checkpoint(twin_path)
    assert spec.ramp_invariant and spec.ny == GATED.ny and meta['sample_time'] == 1.0
    assert source.twin_model is not None
    assert spec == source.twin_model.spec
    source.checkpoint_path = None  # the twin's worker stops saving too
    assert source._moving is not None and source._moving.checkpoint_path is None
    source.checkpoint_path = str(path)
    assert source._moving.checkpoint_path == str(twin_path)


def test_save_and_load_round_trip_the_twin_and_the_gated_output(
        saved: tuple[AdaptivePredictor, Path], tmp_path: Path) -> None:
    source, _ = saved
    path = tmp_path / 'round.pt'
    source.save(str(path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ['round.pt', 'round.pt.twin']
    loaded = AdaptivePredictor(GATED, background=False)
    loaded.load(str(path))
    assert loaded.status().message == 'warm start from round.pt; motion gate twin from ' \
        'round.pt.twin'
    assert source.model is not None and source.twin_model is not None
    assert loaded.model is not None and loaded.twin_model is not None
    rows = _rows(source.twin_model)
    np.testing.assert_array_equal(loaded.twin_model.forward(rows), source.twin_model.forward(rows))
    rows = _rows(source.model)
    np.testing.assert_array_equal(loaded.model.forward(rows), source.model.forward(rows))
    # the loaded predictor is the blend of the two networks loaded on their own, from the first
    # samples on (a cold twin would use its cascade fallback until its first training: no gate)
    holding = AdaptivePredictor(SMALL, background=False)
    holding.load(str(path))
    moving = AdaptivePredictor(SMALL.replace(ramp_invariant=True), background=False)
    moving.load(twin_checkpoint_path(str(path)))
    t, pose, force = moving_run(RUN, 6)
    opened = 0
    for k in range(SAVED_AT, RUN):
        out = loaded.update(t[k], pose[k], force[k])
        a = holding.update(t[k], pose[k], force[k])
        b = moving.update(t[k], pose[k], force[k])
        assert moving.using_network == (k - SAVED_AT + 1 >= GATED.max_lag)
        assert out == pytest.approx(blend(a, b, loaded.motion_gain, 3), abs=1e-9), k
        opened += int(np.any(loaded.motion_gain > 0.5))
    assert loaded.counters['moving_trainings'] == loaded.counters['trainings'] == 0
    assert opened > 20  # the move opened the gate on the loaded twin
    assert loaded.twin_model is not None
    twin = loaded._moving
    assert twin is not None
    assert twin.update(t[-1] + 1, pose[-1], force[-1]) == pytest.approx(
        moving.update(t[-1] + 1, pose[-1], force[-1]), abs=1e-9)


def test_a_plain_checkpoint_loads_with_a_cold_twin_and_a_plain_predictor_saves_one_file(
        tmp_path: Path) -> None:
    plain = AdaptivePredictor(SMALL, background=False, max_trainings=1)
    t, pose, force = moving_run(RUN, 6)
    for k in range(SAVED_AT):
        plain.update(t[k], pose[k], force[k])
    path = tmp_path / 'plain.pt'
    plain.save(str(path))
    assert sorted(p.name for p in tmp_path.iterdir()) == ['plain.pt']  # no twin file
    gated = AdaptivePredictor(GATED, background=False)
    gated.load(str(path))
    assert gated.status().message == 'warm start from plain.pt; motion gate twin cold (no ' \
        'plain.pt.twin)'
    assert plain.model is not None and gated.model is not None and gated.twin_model is None
    rows = _rows(plain.model)
    np.testing.assert_array_equal(gated.model.forward(rows), plain.model.forward(rows))
    # a cold twin: the holding network alone until the twin's first training
    reference = AdaptivePredictor(SMALL, background=False)
    reference.load(str(path))
    for k in range(SAVED_AT, RUN):
        out = gated.update(t[k], pose[k], force[k])
        assert out == pytest.approx(reference.update(t[k], pose[k], force[k]), abs=1e-12), k
        assert np.all(gated.motion_gain == 0.0)
    # saved again with its twin still cold: a stale twin file beside it goes
    stale = Path(twin_checkpoint_path(str(path)))
    stale.write_bytes(b'an older twin')
    gated.save(str(path))
    assert not stale.exists()


def test_a_twin_checkpoint_that_does_not_fit_is_refused_and_nothing_is_loaded(
        saved: tuple[AdaptivePredictor, Path], tmp_path: Path) -> None:
    source, _ = saved
    path = tmp_path / 'gated.pt'
    source.save(str(path))
    twin_path = twin_checkpoint_path(str(path))
    shorter = AdaptivePredictor(GATED.replace(motion_gate_ny=6), background=False)
    with pytest.raises(ValueError, match=r"'ny': 12,.*'ny': 6,.*was expected: change the "
                                         r'predictor parameters or retrain; or delete '
                                         r'.*gated\.pt\.twin \(the motion gate twin of '
                                         r'.*gated\.pt\) to start the twin cold'):
        shorter.load(str(path))
    assert shorter.model is None and shorter.twin_model is None  # all or nothing
    assert shorter.status().message == 'collecting data'
    # strict_twin False (the node's carry-over): the holding network, the twin cold
    shorter.load(str(path), strict_twin=False)
    assert shorter.model is not None and shorter.twin_model is None
    assert shorter.status().message.startswith(
        'warm start from gated.pt; motion gate twin cold (gated.pt.twin not loaded: checkpoint ')
    # another sample time, or a corrupt file: refused alike
    assert source.twin_model is not None and source._moving is not None
    spec, state, meta = load_checkpoint(twin_path)
    save_checkpoint(twin_path, spec, state, {**meta, 'sample_time': 2.0})
    fresh = AdaptivePredictor(GATED, background=False)
    with pytest.raises(ValueError, match=r'trained at sample_time 2.0 s, this predictor runs at '
                                         r'1.0 s: use the same sample_time or retrain; or delete'):
        fresh.load(str(path))
    Path(twin_path).write_bytes(b'not a checkpoint')
    with pytest.raises(ValueError, match=r'corrupt or not a torch file.*; or delete'):
        fresh.load(str(path))
    assert fresh.model is None and fresh.twin_model is None
    # a gate-off predictor reads the holding network alone and never looks at the twin file
    plain = AdaptivePredictor(SMALL, background=False)
    plain.load(str(path))
    assert plain.status().message == 'warm start from gated.pt'


def test_the_yaw_notch_takes_the_wave_peak_out_of_the_gates_heading_difference() -> None:
    """motion_gate_yaw_notch ζ: gain notch_depth at ω0, 1 at DC, north and east untouched."""
    params = SMALL.replace(motion_gate=True, motion_gate_yaw_notch=0.5)
    predictor = AdaptivePredictor(params, background=False)
    predictor._tune_wave_filters(0.8)  # ω0 [rad/s]
    t = np.arange(400.0)  # [s] at h = 1 s
    rows = np.column_stack([np.full(t.size, 0.3), np.full(t.size, -0.2),
                            0.02 * np.sin(0.8 * t)])  # [m, m, rad]
    out = np.array([predictor._yaw_notched(t[k], rows[k]) for k in range(t.size)])
    assert out[:, :2] == pytest.approx(rows[:, :2], abs=0.0)  # north/east pass unchanged
    amplitude = np.max(np.abs(out[-100:, 2]))  # steady state, ≥ 12 periods after the start
    assert amplitude == pytest.approx(params.notch_depth * 0.02, rel=0.1, abs=2e-4)
    still = AdaptivePredictor(params, background=False)
    turned = [still._yaw_notched(float(k), np.array([0.0, 0.0, 0.05]))[2] for k in range(50)]
    assert turned == pytest.approx([0.05] * 50, abs=1e-12)  # a held difference passes (DC 1)
    # only with the heading gated: no notch is built otherwise
    assert AdaptivePredictor(params.replace(motion_gate_yaw=False),
                             background=False)._gate_yaw_notch is None


def test_with_the_yaw_notch_the_gate_changes_the_heading_only(
        trace: Callable[[PredictorParams], Trace]) -> None:
    """The notch acts on the heading difference alone: gains and north/east as without it."""
    notched = trace(SMALL.replace(motion_gate=True, motion_gate_yaw_notch=0.5))
    gated = trace(SMALL.replace(motion_gate=True))
    assert np.array_equal(notched.gain, gated.gain)
    assert notched.out[:, :2] == pytest.approx(gated.out[:, :2], abs=1e-12)
    opened = gated.gain[:, 2] > 0.5
    assert np.count_nonzero(opened) > 20
    assert np.max(np.abs(notched.out[opened, 2] - gated.out[opened, 2])) > 1e-5


# ---- the heading gain from the yaw moment (motion_gate_yaw_moment_ratio) ---------------------


def test_the_yaw_moment_sets_the_heading_gain_and_nothing_else(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """motion_gate_yaw_moment_ratio ρ: yaw gain = `YawMomentTrigger` on the applied N.

    ``moving_run`` with a yaw moment 20 N·m above its noise (σ 1 N·m) while the vessel turns;
    the level's time and the warm-up shortened to 200 s so that a 600 s run holds them. Against
    the velocity gain (ρ 0) on the same data: the same networks, the same north/east gains and
    outputs; the heading gain the trigger's where the twin is on its network (else 0), and the
    heading holding + g·offset, so that out + untaken is the same for both (holding + offset).
    """
    monkeypatch.setattr(yaw_moment_trigger, 'LEVEL_TIME', 200.0)
    t, pose, force = moving_run(600, 2)
    turning = (t >= 450.0) & (t < 550.0)  # the ramp of moving_run(600, …): 0.75·n, 100 s
    force[turning, 2] += 20.0  # [N·m]
    gated = GATED_BY_MOMENT.replace(motion_gate_yaw_warmup=200.0)
    moment = _run_on(gated, t, pose, force)
    velocity = _run_on(gated.replace(motion_gate_yaw_moment_ratio=0.0), t, pose, force)
    reference = YawMomentTrigger(1.0, 5.0, 30.0, 200.0)
    expected = np.array([reference.update(float(n)) for n in force[:, 2]])
    assert moment.twin_using_network is not None
    on = moment.twin_using_network
    assert np.array_equal(moment.gain[:, 2], np.where(on, expected, 0.0))
    assert np.array_equal(moment.gain[:, :2], velocity.gain[:, :2])
    assert np.array_equal(moment.out[:, :2], velocity.out[:, :2])
    assert moment.counters == velocity.counters
    whole = moment.out[:, 2] + moment.untaken[:, 2]  # holding + offset, whatever the gain
    assert np.abs(np.vectorize(wrap_angle)(whole - velocity.out[:, 2] - velocity.untaken[:, 2])
                  ) == pytest.approx(np.zeros(600), abs=1e-12)
    opened = moment.gain[:, 2] == 1.0
    # the turn until its moment is no longer 5× the rising level (about 37 s with a 200 s
    # level), then the 30 s hold
    assert np.count_nonzero(opened) >= 50 and np.all(t[opened] >= 450.0)
    assert np.all(moment.gain[t >= 590.0, 2] == 0.0)  # the hold and the fade end before 590 s
    assert np.max(np.abs(moment.out[:, 2] - velocity.out[:, 2])) > 1e-3  # and that shows


def test_with_the_network_level_the_fallbacks_moments_are_no_evidence(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """motion_gate_yaw_network_level: the trigger is fed the moments of twin-on-network samples.

    ``moving_run`` with a yaw moment of 100 N·m (σ 1) while the twin serves from its fallback,
    the warm-up 50 s and the level's time 200 s: with every moment as evidence the level is
    still above 20 N·m when the turn's 20 N·m more comes and the gain stays shut; with the
    network's moments only the turn opens it, and the gains are those of a trigger fed NaN
    wherever the twin was not on its network.
    """
    monkeypatch.setattr(yaw_moment_trigger, 'LEVEL_TIME', 200.0)
    t, pose, force = moving_run(600, 2)
    gated = GATED_BY_MOMENT.replace(motion_gate_yaw_warmup=50.0)
    probe = _run_on(gated, t, pose, force)
    assert probe.twin_using_network is not None
    first = int(np.argmax(probe.twin_using_network))
    assert 0 < first < 400 and probe.twin_using_network[first:].all()
    force[:first, 2] += 100.0  # [N·m] the fallback's loop
    turning = (t >= 450.0) & (t < 550.0)
    force[turning, 2] += 20.0
    every = _run_on(gated, t, pose, force)
    network = _run_on(gated.replace(motion_gate_yaw_network_level=True), t, pose, force)
    assert every.twin_using_network is not None and network.twin_using_network is not None
    assert np.array_equal(every.twin_using_network, probe.twin_using_network)
    assert np.array_equal(network.twin_using_network, probe.twin_using_network)
    on = probe.twin_using_network
    reference = YawMomentTrigger(1.0, 5.0, 30.0, 50.0)
    expected = np.array([reference.update(float(n) if o else math.nan)
                         for n, o in zip(force[:, 2], on, strict=True)])
    assert np.array_equal(network.gain[:, 2], np.where(on, expected, 0.0))
    assert np.all(every.gain[:, 2] == 0.0)
    assert np.all(network.gain[turning, 2][:20] == 1.0)
    assert np.all(network.gain[t < 450.0, 2] == 0.0)
    assert np.array_equal(network.gain[:, :2], every.gain[:, :2])
    assert np.array_equal(network.out[:, :2], every.out[:, :2])


def test_the_gates_heading_notch_is_planned_by_the_job_with_the_same_numbers(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The job plans the notches at its ω0; applying it designs none of them.

    ``motion_gate_yaw_notch`` 0.2 and ``output_notch_zeta`` 0.3. The same run with the job's
    plans and with the notches' plans dropped (each notch then designs itself in
    `_tune_wave_filters`, as before the seventieth session): the same outputs and gains to the
    bit; with the plans every retune of a notch that applies a training is planned (the ω0 jobs
    before the first training still design theirs).
    """
    from lf_predictor_ros.core import predictor as predictor_module
    from lf_predictor_ros.core.baselines.cascade import CascadeFilter

    t, pose, force = moving_run(600, 2)
    force[(t >= 450.0) & (t < 550.0), 2] += 20.0
    notched = GATED_BY_MOMENT.replace(motion_gate_yaw_notch=0.2, motion_gate_yaw_warmup=50.0,
                                      output_notch_zeta=0.3)
    retunes: list[bool] = []  # per retune of the gate's notch: planned?
    output_retunes: list[bool] = []  # the same of the output notch
    retune = CascadeFilter.set_wave_peak_freq

    def logged(self: CascadeFilter, wave_peak_freq: float, plan: Any = None) -> None:
        if self._design['lowpass_offset'] is None and self._design['notch_zeta'] == 0.2:
            retunes.append(plan is not None)
        if self._design['lowpass_offset'] is None and self._design['notch_zeta'] == 0.3:
            output_retunes.append(plan is not None)
        retune(self, wave_peak_freq, plan)

    monkeypatch.setattr(CascadeFilter, 'set_wave_peak_freq', logged)
    planned = _run_on(notched, t, pose, force)
    with_plan, output_with_plan = list(retunes), list(output_retunes)
    retunes.clear()
    output_retunes.clear()
    plan = predictor_module.retrain_and_plan
    monkeypatch.setattr(predictor_module, 'retrain_and_plan',
                        lambda *args: plan(*args)[:2] + (None,))
    early = predictor_module.estimate_and_plan  # the ω0 jobs before the first training
    monkeypatch.setattr(predictor_module, 'estimate_and_plan',
                        lambda *args: early(*args)[:2] + ({},))
    plain = _run_on(notched, t, pose, force)
    trainings = planned.counters['trainings']
    assert trainings > 1 and plain.counters['trainings'] == trainings
    assert len(retunes) == len(with_plan) and not any(retunes)
    assert sum(with_plan) >= trainings  # every applied training (accepted or not) is planned
    # the output notch (the twin's too): as many retunes, planned where a training applies
    assert len(output_retunes) == len(output_with_plan) and not any(output_retunes)
    assert sum(output_with_plan) >= trainings
    assert np.array_equal(planned.out, plain.out)
    assert np.array_equal(planned.gain, plain.gain)
    assert np.any(planned.gain[:, 2] == 1.0)  # the notched heading offset reached the output


def test_the_yaw_moment_trigger_is_built_only_where_it_acts() -> None:
    assert AdaptivePredictor(GATED_BY_MOMENT, background=False)._yaw_trigger is not None
    for params in (GATED_BY_MOMENT.replace(motion_gate_yaw=False),
                   GATED_BY_MOMENT.replace(motion_gate_yaw_moment_ratio=0.0),
                   GATED_BY_MOMENT.replace(motion_gate=False)):
        assert AdaptivePredictor(params, background=False)._yaw_trigger is None
    with pytest.raises(ValueError, match='motion_gate_yaw_hold must be ≥ 0'):
        GATED_BY_MOMENT.replace(motion_gate_yaw_hold=-1.0)
    with pytest.raises(ValueError, match='motion_gate_yaw_warmup must be ≥ 0'):
        GATED_BY_MOMENT.replace(motion_gate_yaw_warmup=-1.0)
    assert AdaptivePredictor(GATED_BY_MOMENT.replace(motion_gate_yaw_warmup=120.0),
                             background=False)._yaw_trigger.warmup == 120.0
    with pytest.raises(ValueError, match='motion_gate_yaw_moment_ratio must be ≥ 0'):
        GATED_BY_MOMENT.replace(motion_gate_yaw_moment_ratio=-5.0)
