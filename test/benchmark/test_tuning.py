"""The tuning runner: one line per override set, the adaptive RMSE on the tuning seed."""
from __future__ import annotations

import ast

import pytest

from lf_predictor_ros.benchmark import tuning


def test_one_line_per_override_set_with_a_useful_rmse(capsys: pytest.CaptureFixture[str]) -> None:
    code = tuning.main(["{'max_epochs': 2}", "{'max_epochs': 2, 'ny': 12}",
                        '--scenarios', 'onedof_reference', '--duration', '700'])
    lines = capsys.readouterr().out.strip().splitlines()
    assert code == 0 and len(lines) == 2
    for line in lines:
        rmse = ast.literal_eval(line.split('onedof_reference: ')[1].split(' (')[0])
        assert 0.0 < rmse[0] < 0.25  # [m] raw measurement ≈ 0.47 m on this scenario


def test_a_broken_override_is_a_usage_error() -> None:
    with pytest.raises(SystemExit) as info:
        tuning.main(['[1, 2]'])
    assert info.value.code == 2
