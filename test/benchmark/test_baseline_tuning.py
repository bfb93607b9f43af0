"""Tests of benchmark.baseline_tuning: config round trip, search, builders, defaults."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from lf_predictor_ros.benchmark import baseline_tuning as bt
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from lf_predictor_ros.core.baselines.smoother import smooth_poses
from lf_predictor_ros.core.params import PredictorParams
from sim_ros.physics.vessels import LinearModel
from sim_ros.simulation import Simulator, load_scenario


def _tuned_config() -> dict[str, object]:
    return {
        'cascade': {'notch_zeta': 0.2, 'notch_depth': 0.07, 'lowpass_offset': None,
                    'lowpass_order': 2},
        'cascade_loop_safe': {'notch_zeta': 0.35, 'notch_depth': 0.05, 'lowpass_offset': 0.3,
                              'lowpass_order': 1},
        'observer': {'k3_scale': 10.0, 'k4_scale': 30.0, 'cutoff_ratio': 1.01,
                     'relative_damping': 2.0, 'bias_time': 1.0e4},
        'smoother_targets': {'notch_zeta': 0.8, 'notch_depth': 0.05, 'lowpass_offset': 0.2},
        'smoother_tuned': {'notch_zeta': 0.5, 'notch_depth': 0.0, 'lowpass_offset': 1.0,
                           'lowpass_order': 2},
        'tuning': {'command': 'x', 'seeds': [1, 2], 'scores': {'cascade': {'rmse': [0.21]}}},
    }


def test_config_round_trip(tmp_path: Path) -> None:
    config = _tuned_config()
    path = bt.write_baseline_config(bt.config_path('demo', tmp_path), config,
                                    ['a header line', 'Command: python -m x'])
    text = path.read_text(encoding='utf-8')
    assert text.startswith('# a header line\n# Command: python -m x\n')
    loaded = bt.load_baseline_config('demo', tmp_path)
    assert loaded == config


def test_missing_file_gives_the_untuned_defaults(tmp_path: Path) -> None:
    config = bt.load_baseline_config('no_such_scenario', tmp_path)
    assert config['tuning'] == {'source': 'defaults'}
    assert config['cascade'] == bt.CASCADE_DEFAULT
    assert config['observer'] == bt.OBSERVER_DEFAULT
    params = PredictorParams()
    assert bt.smoother_settings(config, 'smoother_targets') == {
        'notch_zeta': params.notch_zeta, 'notch_depth': params.notch_depth,
        'lowpass_offset': params.lowpass_offset, 'lowpass_order': 2}
    assert bt.smoother_settings(config, 'smoother_tuned') == bt.CASCADE_DEFAULT
    # a partial file keeps the defaults of the entries it does not name
    (tmp_path / 'partial.yaml').write_text('cascade: {notch_zeta: 0.2}\n', encoding='utf-8')
    partial = bt.load_baseline_config('partial', tmp_path)
    assert partial['cascade'] == {'notch_zeta': 0.2}
    assert partial['observer'] == bt.OBSERVER_DEFAULT
    assert bt.make_cascade(partial['cascade'], 1, 1.0, 0.8) is not None


def test_grid_search_returns_the_minimum() -> None:
    grid = {'notch_zeta': (0.1, 0.2, 0.4), 'notch_depth': (0.0, 0.1),
            'lowpass': ((None, 2), (0.3, 1))}
    points = bt.grid_points(grid)
    assert len(points) == 12

    def score(point: bt.Point) -> bt.Evaluation:
        offset = point['lowpass_offset']
        value = (abs(math.log(point['notch_zeta'] / 0.2)) + abs(point['notch_depth'] - 0.1)
                 + (0.0 if offset is None else 0.5))
        return bt.Evaluation(point, value)

    objective = bt.CachedObjective(score)
    best = bt.grid_search(objective, points)
    assert best.point == {'notch_zeta': 0.2, 'notch_depth': 0.1, 'lowpass_offset': None,
                          'lowpass_order': 2}
    assert best.score == min(score(p).score for p in points)
    assert len(objective.cache) == 12
    # refinement never makes it worse, and moves towards a continuous optimum off the grid
    shifted = bt.CachedObjective(lambda p: bt.Evaluation(
        p, abs(math.log(p['notch_zeta'] / 0.27)) + abs(p['notch_depth'] - 0.1)))
    refined = bt.refine(shifted, bt.grid_search(shifted, points))
    assert refined.score < bt.grid_search(shifted, points).score
    assert abs(refined.point['notch_zeta'] - 0.27) < 0.03


def test_coordinate_search_finds_the_separable_minimum() -> None:
    grid = {'k3_scale': (1.0, 3.0, 10.0), 'k4_scale': (1.0, 3.0, 10.0)}
    objective = bt.CachedObjective(lambda p: bt.Evaluation(
        p, (math.log(p['k3_scale'] / 3.0)) ** 2 + (math.log(p['k4_scale'] / 10.0)) ** 2))
    best = bt.coordinate_search(objective, {'k3_scale': 1.0, 'k4_scale': 1.0}, grid, 2)
    assert best.point == {'k3_scale': 3.0, 'k4_scale': 10.0}


def test_search_on_a_short_recording_returns_its_best_grid_point() -> None:
    case = bt.prepare_case('onedof_excited', [1], duration=600.0)
    assert case.constant_omega and case.begin == 300
    objective = bt.cascade_objective(case)
    points = bt.grid_points({'notch_zeta': (0.1, 0.5), 'notch_depth': (0.05,),
                             'lowpass': ((None, 2), (0.2, 2))})
    best = bt.grid_search(objective, points)
    scores = [objective(p).score for p in points]
    assert best.score == min(scores) and len(set(scores)) == 4
    assert best.score < objective(bt.CASCADE_DEFAULT).score  # the default is not the best
    # the normalized score is the RMSE ratio to the raw measurement (1 DOF: one ratio)
    assert best.score == pytest.approx(best.rmse[0] / case.raw_rmse[0][0])


def test_vectorized_cascade_equals_the_streaming_filter() -> None:
    rng = np.random.default_rng(3)
    n = 400
    t = np.arange(1, n + 1, dtype=np.float64)
    y = np.column_stack([np.cumsum(rng.normal(0, 0.1, n)) + 0.5 * np.sin(0.8 * t),
                         rng.normal(0, 0.3, n),
                         np.angle(np.exp(1j * (3.0 + 0.01 * t + 0.02 * np.sin(0.8 * t))))])
    for config in ({}, {'lowpass_offset': None, 'notch_zeta': 0.2},
                   {'lowpass_order': 1, 'lowpass_offset': 0.3, 'notch_depth': 0.0}):
        filt = bt.make_cascade(config, 3, 1.0, 0.8)
        streamed = np.array([filt.update(float(t[k]), y[k], np.zeros(3)) for k in range(n)])
        fast = bt.cascade_outputs(y, 3, 1.0, 0.8, config)
        err = fast - streamed
        err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
        assert np.max(np.abs(err)) < 1e-9


def test_builders_produce_working_estimators() -> None:
    config = _tuned_config()
    cascade = bt.make_cascade(config['cascade'], 3, 1.0, 0.8)  # type: ignore[arg-type]
    assert isinstance(cascade, CascadeFilter)
    out = cascade.update(1.0, np.array([1.0, 2.0, 0.1]), np.zeros(3))
    assert np.allclose(out, [1.0, 2.0, 0.1])  # steady state at the first sample
    with pytest.raises(ValueError, match='unknown cascade'):
        bt.make_cascade({'zeta': 0.2}, 1, 1.0, 0.8)
    model = Simulator(load_scenario('supply_closed_loop'), 1).true_model()
    observer = bt.make_observer(config['observer'], model, 3, 1.0, 0.8)  # type: ignore[arg-type]
    mistuned = bt.make_observer(config['observer'], model, 3, 1.0, 0.8,  # type: ignore[arg-type]
                                mistuned=True)
    assert isinstance(observer, PassiveObserver)
    base_k3, base_k4 = bt.observer_base_gains(model.mass)
    assert np.allclose(observer.gains.k4, 30.0 * base_k4)
    assert np.allclose(observer.gains.k3, 10.0 * base_k3)
    assert np.allclose(observer.gains.k2, 1.01 * 0.8)
    assert np.allclose(mistuned.gains.k4, 30.0 * 1.3 * base_k4)
    assert mistuned.wave_peak_freq == pytest.approx(0.96)
    for _ in range(5):
        estimate = observer.update(_ + 1.0, np.array([1.0, 2.0, 0.1]), np.zeros(3))
    assert np.all(np.isfinite(estimate)) and np.allclose(estimate, [1.0, 2.0, 0.1], atol=0.5)
    explicit = bt.make_observer({'k3': [1.0], 'k4': [2.0]}, LinearModel(
        np.eye(3) * 1000.0, np.eye(3) * 10.0, (0.0, 0.0, 0.0)), 1, 1.0, 0.8)
    assert np.allclose(explicit.gains.k3, [1.0]) and np.allclose(explicit.gains.k4, [2.0])
    settings = bt.smoother_settings(config, 'smoother_tuned')
    smoothed = smooth_poses(np.zeros((50, 3)) + 1.0, 1.0, 0.8, 1, **settings)
    assert np.allclose(smoothed[:, 0], 1.0)
    params = PredictorParams(notch_zeta=0.7)
    assert bt.smoother_settings(config, 'smoother_targets', params)['notch_zeta'] == 0.7


def test_loop_safe_choice_and_seed_guard() -> None:
    def score(name: str, stable: bool, pos: float, thrust: float) -> bt.LoopScore:
        return bt.LoopScore({'name': name}, stable, pos, math.nan, thrust, (thrust,))

    scores = [score('best_rmse', True, 1.0, 0.9), score('quiet', True, 1.08, 0.2),
              score('too_far', True, 1.2, 0.01), score('unstable', False, 0.9, 0.0)]
    assert bt.choose_loop_safe(scores, 1).point == {'name': 'quiet'}
    for bad in ([3], [1, 11], []):
        with pytest.raises(ValueError, match='tuning seeds'):
            bt.check_seeds(bad)
    bt.check_seeds([1, 2])


def test_loop_candidates_take_the_best_per_lowpass_option() -> None:
    ranked = [bt.Evaluation({'notch_zeta': z, 'lowpass_offset': off, 'lowpass_order': 2}, s)
              for s, (z, off) in enumerate([(0.1, None), (0.2, None), (0.3, None), (0.1, 0.3),
                                            (0.2, 0.3), (0.3, 0.3)])]
    extra = {'notch_zeta': 0.5, 'lowpass_offset': 0.2, 'lowpass_order': 2}
    out = bt.loop_candidates(ranked, [extra, ranked[0].point], per_lowpass=2)
    assert out == [extra, ranked[0].point, ranked[1].point, ranked[3].point, ranked[4].point]
