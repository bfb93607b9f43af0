"""Statistics over seeds: Student-t intervals and per-seed ratios."""
from __future__ import annotations

import math

import pytest

from lf_predictor_ros.benchmark.scoring import fmt_number, interval, ratios, verdict


def test_interval_of_known_values() -> None:
    """Four values, mean 2.5, s = 1.291: half width t(0.975, 3) · s/2 = 2.05426."""
    iv = interval([1.0, 2.0, 3.0, 4.0])
    assert iv.mean == pytest.approx(2.5)
    assert iv.high - iv.mean == pytest.approx(2.05426, abs=1e-5)
    assert iv.mean - iv.low == pytest.approx(iv.high - iv.mean)
    assert iv.n == 4
    assert iv.cell(fmt_number) == '2.5 [0.446, 4.55]'


def test_interval_drops_non_finite_and_degenerates() -> None:
    assert interval([1.0, math.nan, 3.0]).n == 2
    one = interval([2.0])
    assert one.n == 1 and math.isnan(one.low) and one.cell(fmt_number) == '2'
    assert interval([]).cell(fmt_number) == '–'


def test_ratios_per_seed() -> None:
    assert ratios([1.0, 2.0, math.nan], [2.0, 0.0, 1.0])[:2] == [0.5, math.inf]
    assert math.isnan(ratios([math.nan], [1.0])[0])
    assert verdict(True) == 'met' and verdict(False) == 'MISSED'
