"""sea_change: the learned filter's gain probe and the per-Δ report."""
from __future__ import annotations

import math

import pytest
import torch

from lf_predictor_ros.benchmark.sea_change import main, sine_gain
from lf_predictor_ros.core import retraining
from lf_predictor_ros.core.network import NnarmaxNet, NnarmaxSpec, NumpyNnarmax

pytestmark = pytest.mark.filterwarnings(
    'ignore:`torch.jit.script` is deprecated:DeprecationWarning'
)


def persistence(nu: int, ny: int) -> NumpyNnarmax:
    """A relative network with every weight 0: ŷLF(t + 1) = y(t), gain 1 at every frequency."""
    net = NnarmaxNet(NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=nu, ny=ny, nfb=0, hidden_units=2,
                                 relative=True))
    with torch.no_grad():
        for parameter in net.parameters():
            parameter.zero_()
    return NumpyNnarmax.from_module(net)


@pytest.mark.parametrize('omega', [0.1, 0.8, 2.5])
def test_persistence_has_unit_gain(omega: float) -> None:
    assert sine_gain(persistence(2, 4), omega) == pytest.approx(1.0, abs=1e-9)


def test_two_tap_mean_has_the_analytic_gain() -> None:
    """ŷ = (y(t) + y(t − 1)) / 2 has |H(ω)| = |cos(ω/2)| (h = 1 s)."""
    model = persistence(1, 2)
    # relative regressors: y(t − 1) − y(t) in the second y column, standardized by x_std
    weight = model.bypass_weight.copy() if model.bypass_weight is not None else None
    assert weight is not None
    weight[0, 2] = 0.5 * model.x_std[2] / model.y_std[0]
    model = NumpyNnarmax(**{**vars(model), 'bypass_weight': weight})
    for omega in (0.3, 1.0, 2.0):
        assert sine_gain(model, omega) == pytest.approx(abs(math.cos(omega / 2)), abs=1e-9)


def test_report_lists_every_delta_and_the_gains(capsys: pytest.CaptureFixture[str]) -> None:
    overrides = ("{'training_window': 300.0, 'estimation_window': 600.0, 'max_epochs': 2}")
    original = retraining.sea_state_changed
    assert main([overrides, '--duration', '900', '--gain-times', '850', '--omegas', '0.3',
                 '1.25', '--no-restart']) == 0
    assert retraining.sea_state_changed is original  # the comparison switch is per run
    out = capsys.readouterr().out
    gain_line = next(line for line in out.splitlines() if line.startswith('gain at t = 850'))
    assert gain_line.count("'") == 4  # two gains, both numbers (a network is in service)
    rows = [line for line in out.splitlines() if line.strip()[:1].isdigit()]
    assert len(rows) == 15  # 900 s / Δ 60 s
    assert all(math.isfinite(float(row.split()[1])) for row in rows[-5:])
