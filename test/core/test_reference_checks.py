"""Position-reference checks: each fault flagged, counted, rejected; a clean hour passes."""
from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray
import pytest

from lf_predictor_ros.core import reference_checks
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.reference_checks import (
    ReferenceChecker,
    ReferenceCheckSettings,
    Verdict,
)
from sim_ros.simulation import SimRecord, load_scenario, simulate

FloatArray = NDArray[np.float64]
OMEGA0 = 0.8  # [rad/s] wave peak of supply_closed_loop


@functools.cache
def supply(duration: float = 3600.0) -> SimRecord:
    """The supply vessel in DP (10 Hz GNSS + gyro, waves at 0.8 rad/s), its own seed; 1 h."""
    return simulate(load_scenario('supply_closed_loop'), 6, duration)


def run(record: SimRecord, poses: FloatArray | None = None, *,
        stop: int | None = None) -> tuple[ReferenceChecker, list[Verdict], list[int]]:
    """Stream the record's valid poses (up to ``stop``) through a checker."""
    checker = ReferenceChecker(ReferenceCheckSettings(), 3)
    poses = record.measured_pose if poses is None else poses
    verdicts, indices = [], []
    for k in range(len(record.t) if stop is None else stop):
        if not record.measured_valid[k]:
            continue
        verdicts.append(checker.check_pose(float(record.t[k]), poses[k], OMEGA0))
        indices.append(k)
    return checker, verdicts, indices


def test_settings_are_validated() -> None:
    with pytest.raises(ValueError, match='frozen_time must be a positive'):
        ReferenceCheckSettings(frozen_time=0.0)
    with pytest.raises(ValueError, match='jump_floor must be three'):
        ReferenceCheckSettings(jump_floor=(0.5, 0.5))
    with pytest.raises(ValueError, match='motion_ratio must lie in'):
        ReferenceCheckSettings(motion_ratio=1.5)
    with pytest.raises(ValueError, match='ndof must be 1 or 3'):
        ReferenceChecker(ReferenceCheckSettings(), 2)
    assert ReferenceCheckSettings(jump_floor=[1, 1, 0.1]).jump_floor == (1.0, 1.0, 0.1)  # type: ignore[arg-type]


def test_a_clean_hour_raises_no_flag() -> None:
    """1 h of the supply vessel at 10 Hz: no pose rejected, no drift against the cascade."""
    record = supply()
    checker, verdicts, _ = run(record)
    assert all(v.accepted and not v.restart for v in verdicts)
    # the drift test at 1 s against a causal LF estimate (what the predictor outputs in warm-up)
    cascade = CascadeFilter(3, 1.0, OMEGA0)
    predicted = None
    for k in range(9, len(record.t), 10):
        t, pose = float(record.t[k]), record.measured_pose[k]
        assert checker.check_sample(t, pose, predicted).accepted
        predicted = cascade.update(t, pose, record.thrust[k])
    assert checker.rejected == 0 and checker.faults == ()
    assert all(count == 0 for count in checker.counters.values()), checker.counters
    assert checker.status() == ('OK', '')


def test_frozen_reference_is_rejected_until_it_moves_again() -> None:
    record = supply()
    poses = record.measured_pose.copy()
    poses[3000:3100] = poses[2999]  # stuck for 10 s at 10 Hz
    checker, verdicts, indices = run(record, poses, stop=3200)
    by_k = dict(zip(indices, verdicts, strict=True))
    assert all(by_k[k].accepted for k in indices if k < 3000 + 29)  # < 3 s: not yet frozen
    detected = [k for k in indices if by_k[k].fault == 'frozen']
    assert detected[0] == 2999 + 30 and by_k[detected[0]].restart  # 3 s after the freeze began
    assert all(not by_k[k].accepted for k in range(detected[0], 3100))
    assert by_k[3100].accepted  # a live value again
    assert checker.counters['frozen'] == 1 and checker.rejected == 3100 - detected[0]


def test_no_wave_motion_is_flagged_where_waves_were_seen_before() -> None:
    record = supply()
    poses = record.measured_pose.copy()
    # from 600 s the reference outputs a smooth slow signal (a smoothed / held receiver)
    t = record.t[6000:]
    poses[6000:, :2] = poses[5999, :2] + 0.001 * (t - t[0])[:, None]
    poses[6000:, 2] = poses[5999, 2]
    checker, verdicts, indices = run(record, poses, stop=9000)
    flagged = [k for k, v in zip(indices, verdicts, strict=True) if v.fault == 'no_wave_motion']
    assert flagged and flagged[0] > 6000
    block = 6.0 * 2.0 * math.pi / OMEGA0 * 10  # [samples] one judging block
    assert flagged[0] < 6000 + 2 * block + 10
    assert checker.counters['no_wave_motion'] == 1 and 'no_wave_motion' in checker.faults
    assert checker.status()[0] == 'ERROR'
    assert all(k > 6000 for k in flagged)


def test_a_block_of_thousands_of_poses_gives_the_detrended_rms_of_its_waves() -> None:
    # 100 Hz over 60 s (arrays grown): a line plus a sinusoid of amplitude a and 8 whole
    # periods (ωT = 16π) per DOF, the heading wrapping past ±π on its way. About the best line
    # the RMS is a·√(1/2 − 12/(ωT)²): the line takes up the sinusoid's correlation with t,
    # ∫(t − T/2) sin ωt dt = −T/ω, of variance T²/12
    block = reference_checks._PoseBlock(3)
    t = 1000.0 + np.arange(6000) * 0.01
    amplitude = np.array([0.4, 0.25, 0.02])
    line = np.column_stack([2.0 + 0.05 * t, -1.0 - 0.02 * t, 3.12 + 0.001 * (t - t[0])])
    omega = 16.0 * math.pi / 60.0  # [rad/s]
    poses = line + amplitude * np.sin(omega * (t - t[0]))[:, None]
    poses[:, 2] = np.angle(np.exp(1j * poses[:, 2]))  # wrapped, as measured
    assert poses[:, 2].min() < -3.0 < 3.0 < poses[:, 2].max()  # it crosses ±π
    for k in range(t.size):
        block.append(float(t[k]), poses[k])
    assert block.size == 6000 and block.start == 1000.0
    times, values = block.arrays()
    np.testing.assert_array_equal(times, t)
    np.testing.assert_array_equal(values, poses)
    rms = reference_checks._detrended_rms(times, values, 3)
    expected = amplitude * math.sqrt(0.5 - 12.0 / (16.0 * math.pi) ** 2)
    np.testing.assert_allclose(rms, expected, rtol=1e-3)
    np.testing.assert_array_equal(block.arrays()[1], poses)  # its copy was unwrapped, not this
    block.clear()
    block.append(5.0, np.zeros(3))
    assert block.size == 1 and block.start == 5.0


def test_outlier_is_rejected_and_a_persistent_step_becomes_the_new_level() -> None:
    record = supply()
    poses = record.measured_pose.copy()
    poses[1500, 0] += 5.0  # a 5 m GNSS spike at 150 s (under the 20 m/s speed limit: 50 m)
    poses[1800, 2] += 0.3  # a 17° gyro glitch
    poses[2400:, 1] += 8.0  # the reference steps 8 m east at 240 s and stays
    checker, verdicts, indices = run(record, poses, stop=3000)
    by_k = dict(zip(indices, verdicts, strict=True))
    assert by_k[1500].fault == 'jump' and not by_k[1500].accepted
    assert by_k[1800].fault == 'jump' and not by_k[1800].accepted
    assert by_k[1501].accepted and by_k[1801].accepted
    step = [k for k in indices if by_k[k].fault == 'step']
    assert len(step) == 1 and by_k[step[0]].accepted and by_k[step[0]].restart, step
    assert 2400 + 20 <= step[0] <= 2400 + 25  # after jump_confirm = 2 s of consistent samples
    assert all(not by_k[k].accepted for k in range(2400, step[0]))
    assert all(by_k[k].accepted for k in indices if k > step[0])
    assert checker.counters['step'] == 1 and checker.counters['jump'] == 2 + step[0] - 2400
    assert checker.last_reason.startswith('step: the reference stepped by 8.')


def test_drift_against_the_prediction_latches_until_reset() -> None:
    checker = ReferenceChecker(ReferenceCheckSettings(drift_time_constant=60.0), 3)
    rng = np.random.default_rng(1)
    verdicts = []
    for k in range(400):
        t = float(k)
        truth = np.array([0.3 * math.sin(0.8 * t), 0.2 * math.cos(0.8 * t), 0.01])
        measured = truth + rng.normal(0.0, 0.05, 3) * np.array([1.0, 1.0, 0.01])
        if t >= 200.0:
            measured[0] += 0.02 * (t - 200.0)  # the reference drifts north at 2 cm/s
        verdicts.append(checker.check_sample(t, measured, truth))
    first = next(k for k, v in enumerate(verdicts) if not v.accepted)
    assert all(v.accepted for v in verdicts[:200])
    assert verdicts[first].fault == 'drift' and verdicts[first].restart
    assert 200 < first < 300
    assert all(not v.accepted for v in verdicts[first:])  # latched
    assert not checker.check_pose(401.0, np.zeros(3)).accepted  # poses rejected too
    assert checker.counters['drift'] == 1 and checker.status()[0] == 'ERROR'
    checker.reset()  # the operator re-selects the reference
    assert checker.check_pose(402.0, np.zeros(3)).accepted and checker.faults == ()


def test_one_innovation_after_a_dropout_does_not_latch_a_drift() -> None:
    """After a 32 s gap the first innovation (made right after a restart) counts as one sample.

    Weighted by the gap (32 s / 120 s) a single 2 m innovation latched a drift in the DDS loop
    through a dropout (measured: east mean −0.18 → −0.67 m, limit 0.5 m).
    """
    checker = ReferenceChecker(ReferenceCheckSettings(), 3)
    rng = np.random.default_rng(2)
    for k in range(300):
        checker.check_sample(float(k), rng.normal(0.0, 0.05, 3) * np.array([1, 1, 0.01]),
                             np.zeros(3))
    verdict = checker.check_sample(331.0, np.array([0.24, -2.02, 0.0]), np.zeros(3))
    assert verdict.accepted and checker.counters['drift'] == 0
    mean = checker.drift_mean
    assert mean is not None and abs(mean[1]) < 0.1  # one sample of 120: ≈ −2.02 / 120
    for k in range(332, 340):  # and the following ordinary samples are weighted as before
        assert checker.check_sample(float(k), np.zeros(3), np.zeros(3)).accepted


def test_dropout_is_flagged_on_the_callers_clock_and_counted_once() -> None:
    checker = ReferenceChecker(ReferenceCheckSettings(dropout_timeout=3.0), 1)
    assert checker.silent_for(100.0) is None  # nothing seen yet: no claim
    checker.seen(100.0)
    assert checker.silent_for(102.0) == pytest.approx(2.0) and checker.status()[0] == 'OK'
    checker.silent_for(104.0)
    checker.silent_for(105.0)
    assert checker.counters['dropout'] == 1 and checker.faults == ('dropout',)
    level, reason = checker.status()
    assert level == 'ERROR' and 'no measured pose for more than 3 s' in reason
    checker.seen(106.0)
    assert checker.faults == () and checker.status()[0] == 'OK'
    # a gap in the stamps of the stream is counted too
    checker.check_pose(0.0, np.array([1.0, 0.0, 0.0]))
    checker.check_pose(10.0, np.array([1.1, 0.0, 0.0]))
    assert checker.counters['dropout'] == 2
    # one dropout seen both ways (the clock watch while it lasts, then the stamp gap of the
    # first pose after it) is one dropout
    checker.seen(200.0)
    checker.silent_for(204.0)
    assert checker.counters['dropout'] == 3
    checker.seen(204.5)
    checker.check_pose(14.5, np.array([1.1, 0.0, 0.0]))  # stamp gap 4.5 s > 3 s
    assert checker.counters['dropout'] == 3
    checker.check_pose(20.0, np.array([1.1, 0.0, 0.0]))  # a later gap is a new dropout
    assert checker.counters['dropout'] == 4


def test_checks_can_be_switched_off() -> None:
    checker = ReferenceChecker(ReferenceCheckSettings(reference_checks=False), 3)
    for k in range(100):
        assert checker.check_pose(float(k), np.ones(3)).accepted  # frozen, but not checked
    assert checker.check_sample(1.0, np.ones(3), np.ones(3) * 100).accepted


def test_lost_poses_do_not_turn_wave_motion_into_steps() -> None:
    """60 losses of 0.5–1.5 s (best-effort DDS under load): the stale local line must not reject.

    Without the gate growth (jump_rate ≈ 0) the same stream gives false jumps and 'steps' that
    restart the data (seen in the DDS demo: two false 1 m steps in 1800 s).
    """
    record = supply(1800.0)
    rng = np.random.default_rng(0)
    keep = record.measured_valid == 1
    for start in rng.choice(len(record.t) - 20, 60, replace=False):
        keep[start:start + rng.integers(5, 15)] = False
    counts = {}
    for label, rate in (('stale', (1e-9, 1e-9, 1e-9)), ('default', None)):
        settings = ReferenceCheckSettings() if rate is None else \
            ReferenceCheckSettings(jump_rate=rate)
        checker = ReferenceChecker(settings, 3)
        for k in np.flatnonzero(keep):
            checker.check_pose(float(record.t[k]), record.measured_pose[k], OMEGA0)
        counts[label] = dict(checker.counters)
    assert counts['default']['jump'] == 0 and counts['default']['step'] == 0, counts
    assert counts['stale']['jump'] > 10, counts  # the failure the gate growth removes


def test_a_repeated_first_stamp_changes_nothing_and_outliers_are_still_caught() -> None:
    """A re-offered first sample (same stamp, same pose) is passed on and changes nothing.

    A lockstep simulator re-offers its first sample until the loop starts. Two such poses once
    made the local line's time spread zero, and every later pose then raised ZeroDivisionError,
    so the node dropped every pose for the whole run.
    """
    record = supply()
    poses = record.measured_pose.copy()
    poses[1500, 0] += 5.0  # the spike of the outlier test
    checker = ReferenceChecker(ReferenceCheckSettings(), 3)
    for _ in range(4):
        assert checker.check_pose(0.0, poses[0], OMEGA0).accepted
    verdicts = {k: checker.check_pose(float(record.t[k]), poses[k], OMEGA0)
                for k in range(1, 1600) if record.measured_valid[k]}
    assert verdicts[1500].fault == 'jump' and not verdicts[1500].accepted
    assert all(v.accepted for k, v in verdicts.items() if k != 1500)
    assert checker.counters['jump'] == 1 and checker.counters['frozen'] == 0


def test_a_backward_stamp_restarts_the_local_tests_and_the_checks_go_on() -> None:
    """A simulator reset: the stamps start again from 0; a spike afterwards is still caught."""
    record = supply()
    poses = record.measured_pose.copy()
    poses[900, 0] += 5.0
    checker = ReferenceChecker(ReferenceCheckSettings(), 3)
    for k in range(1200):  # 120 s, then the clock goes back to 0 with the same data
        checker.check_pose(float(record.t[k]), poses[k], OMEGA0)
    before = checker.counters['jump']
    assert before == 1
    verdicts = [checker.check_pose(float(record.t[k]), poses[k], OMEGA0) for k in range(1000)]
    assert not verdicts[900].accepted and verdicts[900].fault == 'jump'
    assert sum(not v.accepted for v in verdicts) == 1
    assert checker.counters['jump'] == 2 and checker.counters['dropout'] == 0


def test_renewed_checks_restart_their_statistics_and_keep_the_counters() -> None:
    """Other settings or ndof (a run-time parameter change): counters carry on, faults do not."""
    checker = ReferenceChecker(ReferenceCheckSettings(frozen_time=2.0), 3)
    pose = np.array([1.0, 2.0, 0.1])
    verdicts = [checker.check_pose(float(t), pose) for t in range(6)]
    assert not verdicts[-1].accepted and checker.counters['frozen'] == 1
    rejected = checker.rejected
    renewed = checker.renewed(ReferenceCheckSettings(frozen_time=4.0), 1)
    assert renewed.settings.frozen_time == 4.0 and renewed.ndof == 1
    assert renewed.counters == checker.counters and renewed.counters is not checker.counters
    assert renewed.rejected == rejected >= 1
    assert not renewed.faults  # a fresh reference: no active fault
    assert renewed.check_pose(6.0, pose).accepted  # the freeze is not carried over
