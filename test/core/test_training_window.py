"""Tests of the training window and the objective's data residuals (core/training_window.py)."""
from __future__ import annotations

import numpy as np
import pytest

from lf_predictor_ros.core.network import NnarmaxSpec
from lf_predictor_ros.core.training_window import loss_scale


def test_loss_scale_is_the_size_of_what_the_network_predicts() -> None:
    """Absolute: std of yT(t+1); relative: RMS of yT(t+1) − y(t) (not the window's drift)."""
    y_now = np.arange(100.0)[:, None]  # a vessel drifting 1 m per sample
    target = y_now + 1.0 + 0.5 * np.cos(np.arange(100.0))[:, None]
    keep = np.ones(100, dtype=bool)
    absolute = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=2, nfb=0, hidden_units=2)
    relative = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=2, nfb=0, hidden_units=2,
                           relative=True)
    assert loss_scale(absolute, y_now, target, keep)[0] == pytest.approx(target.std())
    step = target - y_now
    assert loss_scale(relative, y_now, target, keep)[0] == pytest.approx(
        np.sqrt(np.mean(step ** 2)))
    assert loss_scale(relative, y_now, target, keep)[0] < 0.05 * target.std()
