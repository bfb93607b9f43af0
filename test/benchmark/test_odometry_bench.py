"""The odometry benchmark (issue 14): statistics and a fast smoke run on a short scenario."""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from lf_predictor_ros.benchmark import odometry_bench
from lf_predictor_ros.benchmark.odometry_bench import (
    DRIFT_TIMES,
    LOOP_FD,
    LOOP_ODOM,
    _odometry_overrides,
    calibrate,
    chi2_mean_bounds,
    consistency,
    default_dropouts,
    dropout_coverage,
    dropout_deviation,
    dropout_mean_table,
    dropout_shift_for_seed,
    dropout_trust_table,
    integrated_autocorrelation_time,
    move_dropouts,
    pid_velocity,
    report,
    run_odometry_case,
    true_twist,
)
from lf_predictor_ros.benchmark.suite import schedule_shift_for_seed
from lf_predictor_ros.core.odometry import OdometryEstimate
from lf_predictor_ros.core.odometry_params import OdometryParams
from lf_predictor_ros.core.params import PredictorParams
from sim_ros.simulation import ClosedLoopRun, SimRecord, load_scenario


def test_autocorrelation_time_white_and_ar1() -> None:
    rng = np.random.default_rng(0)
    assert abs(integrated_autocorrelation_time(rng.standard_normal(20000)) - 0.5) < 0.1
    a = 0.9
    x = np.zeros(50000)
    noise = rng.standard_normal(x.size)
    for k in range(1, x.size):
        x[k] = a * x[k - 1] + noise[k]
    expected = (1 + a) / (2 * (1 - a))  # 9.5 samples
    assert abs(integrated_autocorrelation_time(x) - expected) < 0.15 * expected


def test_consistent_errors_pass_and_scaled_ones_fail() -> None:
    rng = np.random.default_rng(1)
    samples = 4000
    std = np.array([0.1, 0.2, 0.01])
    error = rng.standard_normal((samples, 3)) * std
    cov = np.repeat(np.diag(std**2)[None], samples, axis=0)
    ok = consistency(error, cov)
    assert all(d['inside'] for d in ok['dof']) and ok['joint']['inside']
    bad = consistency(error, cov / 4.0)  # covariance 4× too small: NEES ≈ 4
    assert not any(d['inside'] for d in bad['dof'])
    assert abs(bad['joint']['mean_nees'] - 4.0) < 0.4
    low, high = chi2_mean_bounds(100.0)
    assert low < 1.0 < high and math.isclose(high - low, 0.56, abs_tol=0.05)


def test_calibrate_is_geometric_mean_times_scale() -> None:
    def case(pose: list[float], twist: list[float], scale: float) -> dict[str, object]:
        return {'pose_cov_scale': scale, 'twist_cov_scale': 1.0,
                'tracking': {'pose': {'dof': [{'mean_nees': v} for v in pose]},
                             'twist': {'dof': [{'mean_nees': v} for v in twist]}}}

    out = calibrate([case([2.0, 8.0], [1.0], 2.0), case([4.0], [4.0], 2.0)])  # type: ignore
    assert math.isclose(out['pose_cov_scale'], 8.0)
    assert math.isclose(out['twist_cov_scale'], 2.0)
    # spread of log(scale × NEES): logs of 4, 16, 8 (pose) → std of (2, 4, 3) · ln 2
    assert math.isclose(out['pose_log_spread'], math.sqrt(2.0 / 3.0) * math.log(2.0))
    lagged = [{**case([2.0], [1.0], 1.0), 'pose_lag_scale': lag} for lag in (1.0, 8.0)]
    per_value = calibrate(lagged)  # type: ignore[arg-type]
    assert sorted(per_value) == ['pose_lag_scale 1', 'pose_lag_scale 8']
    assert math.isclose(per_value['pose_lag_scale 8']['pose_cov_scale'], 2.0)
    # against the seen LF truth where a run has it
    seen = case([2.0, 8.0], [1.0], 2.0)
    seen['tracking']['pose_seen'] = {'dof': [{'mean_nees': 1.0}, {'mean_nees': 1.0}]}  # type: ignore[index]
    assert math.isclose(calibrate([seen])['pose_cov_scale'], 2.0)  # type: ignore[list-item]


def test_pid_velocity_of_a_ramp() -> None:
    t = np.arange(200.0)
    poses = np.column_stack([0.1 * t, 0.0 * t, np.full(t.size, math.pi / 2)])
    v = pid_velocity(poses, 1.0, 3)
    assert np.allclose(v[-1], [0.0, -0.1, 0.0], atol=1e-9)  # heading east: north = −sway


def test_default_dropouts_after_first_training() -> None:
    params = PredictorParams(ndof=3)
    drops = default_dropouts(params, 1800.0)
    assert len(drops) == 3 and drops[0][0] >= 480.0
    pairs = zip(drops[:-1], drops[1:], strict=True)
    assert all(a + length + 60.0 <= b for (a, length), (b, _) in pairs)
    # a shift delays every dropout by the same time; one that no longer fits is refused
    shifted = default_dropouts(params, 1800.0, shift=100.0)
    assert [a for a, _ in shifted] == [a + 100.0 for a, _ in drops]
    spacing = drops[1][0] - drops[0][0]
    with pytest.raises(ValueError, match='do not fit'):
        default_dropouts(params, 1800.0, shift=spacing - 130.0 - 59.0)
    for bad in (-1.0, math.nan):
        with pytest.raises(ValueError, match='dropout shift'):
            default_dropouts(params, 1800.0, shift=bad)


def test_dropout_shift_is_the_seeds_own_draw() -> None:
    """U(0, spread) per seed, reproducible, apart from the schedule's draw; 0 without spread."""
    shifts = [dropout_shift_for_seed(seed, 300.0) for seed in range(11, 31)]
    assert all(0.0 <= v < 300.0 for v in shifts) and len(set(shifts)) == 20
    assert 100.0 < float(np.mean(shifts)) < 200.0  # U(0, 300): mean 150, sd of the mean 19
    assert dropout_shift_for_seed(11, 300.0) == shifts[0]
    assert dropout_shift_for_seed(11, 300.0) != schedule_shift_for_seed(11, 300.0)
    assert dropout_shift_for_seed(11, 0.0) == 0.0


def test_move_dropouts_start_in_each_setpoint_move() -> None:
    """rao_supply's six rows (600 … 3100 s): one dropout each, U(20, 60) s into the move."""
    scenario = load_scenario('rao_supply')
    params = PredictorParams(ndof=3)
    rows = [row[0] for row in scenario.controller.setpoint_schedule]
    drops = move_dropouts(scenario, params, 11, 3600.0, (20.0, 60.0))
    assert [length for _, length in drops] == [60.0] * len(rows)
    delays = [a - t for (a, _), t in zip(drops, rows, strict=True)]
    assert all(20.0 <= d <= 60.0 for d in delays) and len(set(delays)) == len(rows)
    assert move_dropouts(scenario, params, 11, 3600.0, (20.0, 60.0)) == drops
    assert move_dropouts(scenario, params, 12, 3600.0, (20.0, 60.0)) != drops
    fixed = move_dropouts(scenario, params, 11, 3600.0, (30.0, 30.0))
    assert [a for a, _ in fixed] == [t + 30.0 for t in rows]
    # the run's end: the 3100 s row's dropout plus 120 s after it needs 3100 + 30 + 180 s
    assert [a for a, _ in move_dropouts(scenario, params, 11, 3300.0, (30.0, 30.0))] == \
        [t + 30.0 for t in rows[:-1]]
    # a row before the first training (360 s) is skipped; rows too close: the later skipped
    early = dataclasses.replace(scenario, controller=dataclasses.replace(
        scenario.controller, setpoint_schedule=((100.0, 1.0, 0.0, 0.0), (600.0, 5.0, 0.0, 0.0),
                                                (700.0, 9.0, 0.0, 0.0),
                                                (760.0, 9.0, 9.0, 0.0))))
    assert move_dropouts(early, params, 11, 3600.0, (10.0, 10.0)) == ((610.0, 60.0),
                                                                      (770.0, 60.0))
    holding = load_scenario('supply_closed_loop')
    with pytest.raises(ValueError, match='no setpoint schedule'):
        move_dropouts(holding, params, 11, 3600.0, (20.0, 60.0))
    for bad in ((60.0, 20.0), (-60.0, 5.0), (-70.0, -65.0), (0.0, math.nan)):
        with pytest.raises(ValueError, match='move delay'):
            move_dropouts(scenario, params, 11, 3600.0, bad)
    with pytest.raises(ValueError, match='leaves room'):
        move_dropouts(scenario, params, 11, 700.0, (20.0, 60.0))


def test_move_dropouts_with_a_negative_delay_contain_their_setpoint_change() -> None:
    """A delay in (−60, 0) s: the dropout starts before the change and the move begins inside."""
    scenario = load_scenario('rao_supply')
    params = PredictorParams(ndof=3)
    rows = [row[0] for row in scenario.controller.setpoint_schedule]
    drops = move_dropouts(scenario, params, 11, 3600.0, (-20.0, -5.0))
    assert len(drops) == len(rows)
    for (start, length), t in zip(drops, rows, strict=True):
        assert t - 20.0 <= start <= t - 5.0 and start < t < start + length
    straddle = move_dropouts(scenario, params, 11, 3600.0, (-59.9, -59.9))
    assert [a for a, _ in straddle] == [round(t - 59.9, 1) for t in rows]


def test_smoke_short_onedof_run() -> None:
    case = run_odometry_case('onedof_feedback', 1, 780.0, odometry=OdometryParams(),
                             params_overrides={'max_epochs': 8}, dropouts=((540.0, 130.0),))
    tracking = case['tracking']
    assert tracking['samples'] > 250
    assert math.isfinite(tracking['pose']['joint']['mean_nees'])
    assert math.isfinite(tracking['twist']['joint']['mean_nees'])
    assert all(math.isfinite(v) for v in tracking['twist_rmse'] + tracking['twist_pid_fd_rmse'])
    # the seen truth differs from the twin by the shaping filter's tail below the wave band
    # (≈ 0.005 m RMS). Before the eighteenth session's WF fixes seed 1 carried a slow wave
    # offset of 0.1-0.18 m there and the pose RMSE against the seen truth was < 0.8 × the twin's
    assert abs(tracking['pose_seen_rmse'][0] - tracking['pose_rmse'][0]) < 0.01
    (drop,) = case['dead_reckoning']['dropouts']
    assert set(drop['times']) == {str(w) for w in DRIFT_TIMES}
    for when in DRIFT_TIMES:
        row = drop['times'][str(when)]
        assert row['published'] and row['mode'] == 'dead_reckoning'
        assert math.isfinite(row['error'][0]) and math.isfinite(row['oracle_error'][0])
    assert case['dead_reckoning']['counters']['lost'] == 1  # 130 s > the 120 s timeout
    loops = case['closed_loop']
    assert math.isfinite(loops[LOOP_FD]['position_rmse'])
    assert math.isfinite(loops[LOOP_ODOM]['position_rmse'])
    assert 'Dead-reckoning drift' in report([case]) and '| pose_seen |' in report([case])


def test_dead_reckoning_commands_feed_every_samples_thrust_as_the_command(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``dead_reckoning_commands``: item 3 logs each grid sample's thrust as a command."""
    fed: list[tuple[float, np.ndarray]] = []
    original = odometry_bench.LfStateEstimator.command

    def spy(self: odometry_bench.LfStateEstimator, t: float, force: np.ndarray) -> bool:
        fed.append((t, np.array(force)))
        return original(self, t, force)

    monkeypatch.setattr(odometry_bench.LfStateEstimator, 'command', spy)
    for commands in (False, True):
        fed.clear()
        case = run_odometry_case('onedof_feedback', 1, 700.0, odometry=OdometryParams(),
                                 params_overrides={'max_epochs': 2}, dropouts=((540.0, 40.0),),
                                 loops=False, tracking=False, dead_reckoning_commands=commands)
        assert case['dead_reckoning']['commands'] is commands
        samples = int(round(case['duration'] / 1.0))  # h = 1 s
        assert len(fed) == (samples if commands else 0)
    assert [t for t, _ in fed] == sorted(t for t, _ in fed)


def _run_on(t: np.ndarray, truth: np.ndarray, thrust: np.ndarray | None = None) -> ClosedLoopRun:
    zeros = np.zeros_like(truth)
    thrust = zeros if thrust is None else thrust
    record = SimRecord(t, zeros, np.ones(t.size), truth, truth, thrust, zeros, np.ones(t.size))
    return ClosedLoopRun(record, t, truth, 0, None, 0)


def test_dropout_deviation_is_the_worst_distance_per_window() -> None:
    """A vessel moving east at 0.1 m/s from t = 100 s, turning at 1e-3 rad/s: known maxima."""
    t = np.arange(0.0, 400.0, 0.5)
    truth = np.zeros((t.size, 3))
    moving = t >= 100.0
    truth[moving, 1] = 0.1 * (t[moving] - 100.0)
    truth[moving, 2] = 1e-3 * (t[moving] - 100.0)
    reference = np.zeros((t.size, 3))
    # thrust: a 3-4-5 kick of 5e5 N at 170 s (after), a surge ramp to 2e5 N in the dropout
    thrust = np.zeros((t.size, 3))
    thrust[:, 0] = np.where(t < 160.0, 2e5 * np.clip((t - 100.0) / 60.0, 0.0, 1.0), 0.0)
    thrust[t == 170.0, :] = [3e5, -4e5, 1e9]  # the yaw moment is not a horizontal force
    (row,) = dropout_deviation(_run_on(t, truth, thrust), reference, 3, [(100.0, 60.0)],
                               after=120.0)
    assert row['during'] == pytest.approx(0.1 * 59.5)  # last sample before 160 s
    assert row['after'] == pytest.approx(0.1 * 179.5)
    assert row['during_heading'] == pytest.approx(1e-3 * 59.5)
    assert row['during_thrust'] == pytest.approx(2e5 * 59.5 / 60.0)
    assert row['after_thrust'] == pytest.approx(5e5)
    # a run that stopped (aborted) before the end of a window: NaN, not a short maximum
    short = _run_on(t[t < 200.0], truth[t < 200.0])
    (cut,) = dropout_deviation(short, reference, 3, [(100.0, 60.0)], after=120.0)
    assert cut['during'] == pytest.approx(0.1 * 59.5) and math.isnan(cut['after'])
    assert math.isnan(cut['after_thrust'])
    # one DOF: the north offset only
    north = np.zeros((t.size, 3))
    north[:, 0] = -np.where(moving, 0.2, 0.0)
    surge = np.zeros((t.size, 3))
    surge[:, 0], surge[:, 1] = -3e4, 9e9  # 1 DOF: |surge force| only
    (one,) = dropout_deviation(_run_on(t, north, surge), reference, 1, [(100.0, 60.0)])
    assert one['during'] == pytest.approx(0.2) and 'during_heading' not in one
    assert one['during_thrust'] == pytest.approx(3e4)


def test_dropout_coverage_counts_the_truth_inside_the_published_ellipse() -> None:
    """Truth at 0; estimates 1 m east with std 1 m (inside: 1 < 7.81) then 3 m (outside)."""
    t = np.arange(0.0, 200.0, 1.0)
    run = _run_on(t, np.zeros((t.size, 3)))
    cov = np.diag([1.0, 1.0, 1e-4])
    log = [OdometryEstimate(stamp=float(s), pose=np.array([0.0, 1.0 if s < 130 else 3.0, 0.0]),
                            pose_cov=cov, twist=np.zeros(3), twist_cov=np.eye(3),
                            mode='dead_reckoning', dead_reckoning_time=float(s - 100),
                            calibrated=True, reckoner='model')
           for s in range(100, 160)]
    log.append(dataclasses.replace(log[0], stamp=250.0))  # beyond the run: ignored
    (row, empty) = dropout_coverage(log, run, 3, [(100.0, 60.0), (170.0, 10.0)])
    assert row['inside'] == pytest.approx(0.5)  # (3/1)² = 9 > χ²₀.₉₅(3) = 7.81
    assert row['end_std'] == pytest.approx(math.sqrt(2.0))
    assert row['end_error'] == pytest.approx(3.0)
    assert math.isnan(empty['inside'])
    case = {'scenario': 's', 'seed': 1, 'ndof': 3, 'closed_loop': {'dropout_loops': {
        'lf_odom': {'coverage': [row, empty]}}}}
    table = dropout_trust_table([case])
    assert '| s | 1 | 0.5' in table and '| 1/1 |' in table


def test_dropout_mean_table_compares_per_run_means_with_the_observer() -> None:
    """Two runs of two dropouts: means, the per-run ratio, headings and who stayed closer."""
    def run(lf: list[float], obs: list[float]) -> dict[str, object]:
        def rows(values: list[float]) -> list[dict[str, float]]:
            return [{'during': v, 'after': 2 * v, 'during_heading': v / 100,
                     'after_heading': v / 50} for v in values]
        return {'lf_odom': {'with_dropouts': rows(lf)}, 'observer': {'with_dropouts': rows(obs)}}

    cases = [{'scenario': 's', 'seed': k, 'ndof': 3, 'closed_loop': {'dropout_loops': r}}
             for k, r in enumerate([run([2.0, 4.0], [1.0, 5.0]), run([6.0, 6.0], [3.0, 3.0])])]
    table = dropout_mean_table(cases)
    row = table.splitlines()[2].split(' | ')
    assert row[1].startswith('4.5 ')  # per-run means 3 and 6
    assert row[2].startswith('3 ')  # 3 and 3
    assert row[3].startswith('1.5 ')  # ratios 1 and 2
    assert row[4].startswith('9 ')  # after = 2 × during
    assert row[6] == '0.090 / 0.12'  # after_heading = during / 50 is the larger
    assert row[8] == '1/4 |'  # 2.0 < 5.0 only


def test_dropout_loop_velocity_chooses_the_pids_d_term(monkeypatch: pytest.MonkeyPatch) -> None:
    """'odometry': the PID reads lf_odom's twist; 'difference': its own finite difference."""
    given: list[Any] = []

    def run_loop(*args: Any, **kwargs: Any) -> str:
        given.append(kwargs['velocity'])
        return 'run'

    monkeypatch.setattr(odometry_bench, 'run_loop', run_loop)
    scenario = load_scenario('onedof_feedback')
    params = PredictorParams()
    for source in ('odometry', 'difference'):  # pid.VELOCITY_SOURCES
        assert odometry_bench._odometry_loop(  # noqa: SLF001
            scenario, 1, 60.0, params, OdometryParams(), velocity_source=source) == 'run'
    assert callable(given[0]) and given[0]() is None  # no estimate yet: no twist
    assert given[1] is None
    with pytest.raises(ValueError, match='velocity_source'):
        odometry_bench._odometry_loop(scenario, 1, 60.0, params, OdometryParams(),  # noqa: SLF001
                                      velocity_source='twist')
    assert len(given) == 2


def test_odometry_overrides_are_validated() -> None:
    assert _odometry_overrides(['dead_reckoner=hold', 'prior_pose_std=[1, 1, 0.1]']) == {
        'dead_reckoner': 'hold', 'prior_pose_std': (1, 1, 0.1)}
    assert _odometry_overrides(['dead_reckoner=kalman']) is None  # invalid value
    assert _odometry_overrides(['no_such_field=1']) is None
    assert _odometry_overrides(['dead_reckoner']) is None  # no '='


def test_param_reaches_every_case_and_a_bad_one_stops_before_a_run(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Any) -> None:
    seen: list[Any] = []

    def run_specs(specs: Any, *args: Any, **kwargs: Any) -> list[dict[str, Any]]:
        seen.extend(specs)
        return []

    monkeypatch.setattr(odometry_bench, 'run_specs', run_specs)
    monkeypatch.setattr(odometry_bench, 'report', lambda cases: '')
    out = tmp_path / 'x.json'
    assert odometry_bench.main(['run', '--scenarios', 'rao_supply', 'supply_closed_loop',
                                '--seeds', '3', '--param', 'north_east_decoupled=false',
                                '--param', 'lf_augmentation=[0, 0, 0.001]', '-o',
                                str(out)]) == 0
    assert len(seen) == 2
    for spec in seen:
        assert spec.params_overrides == {'north_east_decoupled': False,
                                         'lf_augmentation': (0, 0, 0.001)}
    assert odometry_bench.main(['run', '--seeds', '3', '-o', str(out)]) == 0
    assert seen[-1].params_overrides == {}  # without --param: the defaults
    for bad in ('no_such_field=1', 'north_east_decoupled=3', 'north_east_decoupled'):
        with pytest.raises(SystemExit):
            odometry_bench.main(['run', '--seeds', '3', '--param', bad, '-o', str(out)])
    assert len(seen) == 2 + len(odometry_bench.DEFAULT_SCENARIOS)  # no run was started
    assert all(spec.dropout_spread == 0.0 for spec in seen)
    assert odometry_bench.main(['run', '--scenarios', 'rao_swell', '--seeds', '3',
                                '--dropout-spread', '200', '-o', str(out)]) == 0
    assert seen[-1].dropout_spread == 200.0 and seen[-1].key != seen[0].key
    for bad_spread in ('-1', 'nan'):
        with pytest.raises(SystemExit):
            odometry_bench.main(['run', '--seeds', '3', '--dropout-spread', bad_spread, '-o',
                                 str(out)])
    assert len(seen) == 3 + len(odometry_bench.DEFAULT_SCENARIOS)
    assert odometry_bench.main(['run', '--scenarios', 'rao_supply', '--seeds', '3',
                                '--dropout-loops', '--dropout-moves', '20', '60', '-o',
                                str(out)]) == 0
    assert seen[-1].dropout_moves == (20.0, 60.0) and seen[-1].key != seen[-2].key
    for bad_moves in (['60', '20'], ['-60', '5'], ['nan', '5']):
        with pytest.raises(SystemExit):
            odometry_bench.main(['run', '--scenarios', 'rao_supply', '--seeds', '3',
                                 '--dropout-moves', *bad_moves, '-o', str(out)])
    with pytest.raises(SystemExit):  # no setpoint schedule
        odometry_bench.main(['run', '--scenarios', 'supply_closed_loop', '--seeds', '3',
                             '--dropout-moves', '20', '60', '-o', str(out)])
    assert len(seen) == 4 + len(odometry_bench.DEFAULT_SCENARIOS)
    for velocity in ([], ['--dropout-loop-velocity', 'difference']):
        assert odometry_bench.main(['run', '--scenarios', 'rao_supply', '--seeds', '3',
                                    '--dropout-loops', *velocity, '-o', str(out)]) == 0
    assert [spec.dropout_velocity for spec in seen[-2:]] == ['odometry', 'difference']
    assert seen[-1].key != seen[-2].key
    with pytest.raises(SystemExit):
        odometry_bench.main(['run', '--scenarios', 'rao_supply', '--seeds', '3',
                             '--dropout-loop-velocity', 'twist', '-o', str(out)])
    assert len(seen) == 6 + len(odometry_bench.DEFAULT_SCENARIOS)


def test_true_twist_is_the_body_velocity_across_the_heading_wrap() -> None:
    """1 m/s north while turning at 0.01 rad/s through ±π: u = cos ψ, v = −sin ψ, r = 0.01.

    The heading is wrapped in the truth; the twist is taken on the unwrapped heading (central
    differences: exact for the linear motion and the constant rate, away from the ends).
    """
    h = 1.0
    t = np.arange(200.0) * h
    heading = 3.0 + 0.01 * t  # crosses π at t ≈ 14 s
    truth = np.column_stack([t, np.zeros_like(t), np.angle(np.exp(1j * heading))])
    kept = truth.copy()
    twist = true_twist(truth, h, 3)
    np.testing.assert_allclose(twist[1:-1, 2], 0.01, atol=1e-12)
    np.testing.assert_allclose(twist[1:-1, 0], np.cos(heading[1:-1]), atol=1e-12)
    np.testing.assert_allclose(twist[1:-1, 1], -np.sin(heading[1:-1]), atol=1e-12)
    np.testing.assert_array_equal(truth, kept)
