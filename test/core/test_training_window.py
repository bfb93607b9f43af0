"""Tests of the training window and the objective's data residuals (core/training_window.py)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from lf_predictor_ros.core.network import NnarmaxSpec
from lf_predictor_ros.core.training_window import (
    data_residuals,
    loss_scale,
    mse_residuals,
    prepare_window,
    window_mse,
)


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


def window_case(seed: int, n: int = 60) -> tuple[NnarmaxSpec, np.ndarray, np.ndarray,
                                                np.ndarray, np.ndarray]:
    """A 3-DOF window with a mask that drops single samples and the last five."""
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=3, nfb=0, hidden_units=2,
                       relative=True)
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    x = np.cumsum(rng.normal(scale=0.1, size=(n, 3)), axis=0)
    y = x + rng.normal(scale=0.05, size=(n, 3))
    mask = (np.arange(n) % 7 != 3) & (np.arange(n) < n - 5)
    return spec, u, y, x, mask


def test_prepare_window_aligns_targets_masks_and_scales_with_the_rows() -> None:
    """Row t (from first = max(nu, ny) − 1) is trained on yT(t + 1); pairs need both kept."""
    spec, u, y, x, mask = window_case(1)
    window = prepare_window(spec, u, y, x, mask)
    first = 2
    assert window.first == first
    np.testing.assert_array_equal(window.target.numpy(), x[first + 1:])
    np.testing.assert_array_equal(window.keep.numpy(), mask[first + 1:])
    np.testing.assert_array_equal(window.keep_pair.numpy(),
                                  mask[first + 1:][1:] & mask[first + 1:][:-1])
    assert window.x_series.shape == (60 - first, 2 * 3 + 3 * 3)
    kept = mask[first + 1:]
    step = (x[first + 1:] - y[first:-1])[kept]
    np.testing.assert_allclose(window.scale.numpy(), np.sqrt(np.mean(step ** 2, axis=0)),
                               rtol=1e-14)
    pairs = np.diff(x[first + 1:], axis=0)[window.keep_pair.numpy()]
    np.testing.assert_allclose(window.diff_scale.numpy(), np.sqrt(np.mean(pairs ** 2, axis=0)),
                               rtol=1e-14)
    assert window.body is None


def test_data_residuals_square_to_the_mse_and_the_weighted_derivative_mse() -> None:
    """‖ε‖² = MSE + d · MSE_Δ, each a mean over the kept samples (pairs) and channels."""
    spec, u, y, x, mask = window_case(2)
    window = prepare_window(spec, u, y, x, mask)
    rng = np.random.default_rng(3)
    prediction = torch.from_numpy(window.target.numpy().mean(axis=0)
                                  + rng.normal(size=(window.x_series.shape[0], 3)))
    scale, diff_scale = window.scale.numpy(), window.diff_scale.numpy()
    fitted, target = prediction.numpy()[:-1], window.target.numpy()
    keep, keep_pair = window.keep.numpy(), window.keep_pair.numpy()
    mse = np.mean(((fitted - target) / scale)[keep] ** 2)
    steps = (np.diff(fitted, axis=0) - np.diff(target, axis=0)) / diff_scale
    mse_diff = np.mean(steps[keep_pair] ** 2)
    assert float(torch.sum(mse_residuals(prediction, window) ** 2)) == pytest.approx(
        mse, rel=1e-13)
    assert window_mse(prediction, window) == pytest.approx(mse, rel=1e-13)
    assert float(torch.sum(data_residuals(prediction, window, 0.0) ** 2)) == pytest.approx(
        mse, rel=1e-13)
    assert float(torch.sum(data_residuals(prediction, window, 0.5) ** 2)) == pytest.approx(
        mse + 0.5 * mse_diff, rel=1e-13)


def test_prepare_window_refuses_bad_windows_with_what_to_do() -> None:
    spec, u, y, x, mask = window_case(4)
    with pytest.raises(ValueError, match='mask must have shape'):
        prepare_window(spec, u, y, x, mask[:-1])
    with pytest.raises(ValueError, match='window too short'):
        prepare_window(spec, u[:4], y[:4], x[:4], None)  # 2 rows
    bad = x.copy()
    bad[10, 1] = np.nan
    with pytest.raises(ValueError, match='must be finite'):
        prepare_window(spec, u, y, bad, mask)
    with pytest.raises(ValueError, match='fewer than 2 training targets'):
        prepare_window(spec, u, y, x, np.zeros(60, dtype=bool))
    with pytest.raises(ValueError, match='same length'):
        prepare_window(spec, u, y[:-1], x, mask)
