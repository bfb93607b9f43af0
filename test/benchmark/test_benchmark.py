"""The benchmark suite's smoke run (issue 6 fast mode): not a timing test."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lf_predictor_ros.benchmark.benchmark import main
from lf_predictor_ros.benchmark.suite import ESTIMATORS, run_case


@pytest.mark.slow
def test_fast_suite_writes_results_page_and_json(tmp_path: Path) -> None:
    page, raw = tmp_path / 'RESULTS.md', tmp_path / 'results.json'
    assert main(['--fast', '-o', str(page), '--json', str(raw)]) == 0
    text = page.read_text()
    assert '### onedof_feedback' in text and '### supply_closed_loop' in text
    assert 'adaptive / cascade ≤ 0.5' in text
    cases = json.loads(raw.read_text())['cases']
    assert {c['scenario'] for c in cases} == {'onedof_feedback', 'supply_closed_loop'}
    for case in cases:
        assert set(case['metrics']) == set(ESTIMATORS)
        for metrics in case['metrics'].values():
            for dof in ('north', 'east', 'yaw')[:case['ndof']]:
                assert np.isfinite(metrics[dof]['rmse'])
        # The learned filter trained and is far better than no filter at all.
        assert case['info']['adaptive_counters']['trainings'] >= 2
        raw_rmse = case['metrics']['raw']['north']['rmse']
        assert case['metrics']['adaptive']['north']['rmse'] < 0.6 * raw_rmse


def test_unknown_scenario_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(['--scenarios', 'no_such_scenario']) == 2
    assert 'unknown scenario' in capsys.readouterr().err


def test_smoother_beats_raw_and_frozen_stops_training() -> None:
    case = run_case('onedof_feedback', 3, duration=600.0,
                    estimators=('frozen', 'smoother', 'raw'))
    assert case.info['frozen_counters']['trainings'] == 1
    assert case.metrics['smoother'].rmse[0] < 0.5 * case.metrics['raw'].rmse[0]
