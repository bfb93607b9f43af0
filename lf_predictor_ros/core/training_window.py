"""The training window as tensors and the data residuals of the objective on it.

One training run (`training.train`) prepares its window once (`prepare_window`: the regressors
with the targets as feedback, the targets yT(t + 1), the masks of the kept samples and pairs, the
loss scales) and runs the network over it (`WindowPredictor`, series-parallel or parallel). The
data terms of the objective (module docstring of `training`: MSE and d · MSE_Δ, per-channel
scaled, body-frame networks in the frame of each row's newest heading) are residual vectors
whose squared sum is the term (`mse_residuals`, `data_residuals`), so the Levenberg–Marquardt
Jacobian (`lm_jacobian`) and the autograd optimizers share them.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
import torch

from lf_predictor_ros.core.network import NnarmaxNet, NnarmaxSpec, rotate_blocks_torch
from lf_predictor_ros.core.regressors import as_series, build_regressors, rotate_blocks

FloatArray = NDArray[np.float64]

_SCALE_FLOOR = 1e-12  # [-] relative floor below which a target channel is not normalized


@dataclass(frozen=True)
class TrainingWindow:
    """Training window as tensors, prepared once per run."""

    x_series: torch.Tensor  # (rows, n_reg) regressors with the targets as feedback
    fb_init: torch.Tensor  # (nfb, n_out) targets at first−nfb+1 … first (oldest first)
    target: torch.Tensor  # (rows − 1, n_out) yT(t + 1) for row t
    keep: torch.Tensor  # (rows − 1,) bool: target counts
    keep_pair: torch.Tensor  # (rows − 2,) bool: both targets of a difference count
    scale: torch.Tensor  # (n_out,) loss normalization (``loss_scale``)
    diff_scale: torch.Tensor  # (n_out,) RMS of kept target differences
    first: int
    # body-frame networks: (cos ψ(t), sin ψ(t)) of each target row's newest heading, (rows − 1,)
    body: tuple[torch.Tensor, torch.Tensor] | None = None


class WindowPredictor(torch.nn.Module):
    """Runs a regressor network over a window, series-parallel (batch) or parallel (unrolled)."""

    def __init__(self, net: NnarmaxNet, n_static: int, nfb: int) -> None:
        """Wrap ``net``; the feedback block is the last ``nfb`` lag blocks of a regressor row."""
        super().__init__()
        self.net = net
        self.n_static = n_static
        self.nfb = nfb

    def forward(
        self, x_series: torch.Tensor, fb_init: torch.Tensor, parallel: bool
    ) -> torch.Tensor:
        """Predictions ŷLF(t + 1) for every row t of the window, shape (rows, n_out)."""
        if not parallel or self.nfb == 0:
            prediction: torch.Tensor = self.net(x_series)
            return prediction
        free_run: torch.Tensor = self.net.free_run(
            x_series[:, : self.n_static], fb_init, differentiable=torch.is_grad_enabled()
        )
        return free_run


def _channel_scale(values: FloatArray) -> FloatArray:
    """Per-channel normalization: the given spread, or 1 for a (near-)constant channel."""
    return np.where(values > _SCALE_FLOOR, values, 1.0)


def _y_series(spec: NnarmaxSpec, y: ArrayLike, n: int) -> FloatArray:
    """The measured positions as an (n, n_outputs) series (validated length)."""
    series = as_series(y, spec.n_outputs, 'y')
    if series.shape[0] != n:
        raise ValueError(f'y has {series.shape[0]} samples, the targets {n}: align them first')
    return series


def loss_frame_errors(spec: NnarmaxSpec, y_now: ArrayLike, errors: ArrayLike) -> FloatArray:
    """Errors (rows, n_out) in the frame of the loss.

    Unchanged, or for a body-frame network rotated into the body frame of each row's newest
    heading ψ(t) = ``y_now[:, 2]``.
    """
    values = np.asarray(errors, dtype=np.float64)
    if not spec.body_frame:
        return values
    heading = as_series(y_now, spec.n_outputs, 'y')[:, 2]
    return rotate_blocks(values, np.cos(heading), -np.sin(heading))


def _in_loss_frame(values: torch.Tensor, body: tuple[torch.Tensor, torch.Tensor] | None,
                   ) -> torch.Tensor:
    """``loss_frame_errors`` on tensors: the body rotation of a window's rows (or none)."""
    if body is None:
        return values
    return rotate_blocks_torch(values, body[0], -body[1])


def loss_scale(spec: NnarmaxSpec, y_now: ArrayLike, target_next: ArrayLike,
               keep: ArrayLike) -> FloatArray:
    """Per-channel normalization of the training loss, shape (n_outputs,).

    Absolute networks: the std of the kept targets yT(t + 1) (thesis: normalized MSE). Relative
    networks (``spec.relative``) predict ŷLF(t + 1) − y(t), so the loss is normalized by the RMS
    of yT(t + 1) − y(t), the size of what they actually predict. The absolute spread would mostly
    measure how far the vessel drifted in the window (tens of metres), make a 0.2 m error look
    like 1e-4 and let the weight penalty (eq. 2.8) dominate the fit.
    ``y_now`` (rows, n_out) is y(t) and ``target_next`` (rows, n_out) yT(t + 1) for the same rows.
    Body-frame networks: the steps in the body frame of ψ(t) (``loss_frame_errors``).
    """
    kept = np.asarray(keep, dtype=bool)
    target = as_series(target_next, spec.n_outputs, 'targets')[kept]
    if not spec.relative:
        return _channel_scale(target.std(axis=0))
    now = as_series(y_now, spec.n_outputs, 'y')[kept]
    step = loss_frame_errors(spec, now, target - now)
    return _channel_scale(np.sqrt(np.mean(step ** 2, axis=0)))


def prepare_window(
    spec: NnarmaxSpec, u: ArrayLike, y: ArrayLike, targets: ArrayLike, mask: ArrayLike | None
) -> TrainingWindow:
    """Validate the arrays and build the regressors, targets and masks of one window."""
    target_series = as_series(targets, spec.n_outputs, 'targets')
    x_series, first = build_regressors(u, y, target_series, spec)
    n = target_series.shape[0]
    keep_all = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if keep_all.shape != (n,):
        raise ValueError(f'mask must have shape ({n},) like the targets, got {keep_all.shape}')
    if n - first < 3:
        raise ValueError(
            f'window too short: {n} samples leave fewer than 3 regressor rows after the first '
            f'{first}; collect more data before training'
        )
    if not (np.all(np.isfinite(x_series)) and np.all(np.isfinite(target_series))):
        raise ValueError('u, y and targets must be finite: drop or fill invalid samples first')
    target = target_series[first + 1 :]
    keep = keep_all[first + 1 :]
    keep_pair = keep[1:] & keep[:-1]
    if keep.sum() < 2:
        raise ValueError('mask keeps fewer than 2 training targets: the window is all transient')
    y_now = _y_series(spec, y, n)[first : n - 1]
    scale = loss_scale(spec, y_now, target, keep)
    diffs = loss_frame_errors(spec, y_now[1:], np.diff(target, axis=0))[keep_pair]
    diff_rms = np.sqrt(np.mean(diffs**2, axis=0)) if diffs.size else np.ones(spec.n_outputs)
    body = None
    if spec.body_frame:
        body = (torch.from_numpy(np.cos(y_now[:, 2])), torch.from_numpy(np.sin(y_now[:, 2])))
    return TrainingWindow(
        x_series=torch.from_numpy(x_series),
        fb_init=torch.from_numpy(target_series[first - spec.nfb + 1 : first + 1].copy()),
        target=torch.from_numpy(target.copy()),
        keep=torch.from_numpy(keep.copy()),
        keep_pair=torch.from_numpy(keep_pair.copy()),
        scale=torch.from_numpy(scale),
        diff_scale=torch.from_numpy(_channel_scale(diff_rms)),
        first=first,
        body=body,
    )


def mse_residuals(prediction: torch.Tensor, window: TrainingWindow) -> torch.Tensor:
    """Normalized errors of the kept samples, scaled so that their squared sum is the MSE."""
    difference = _in_loss_frame(prediction[:-1] - window.target, window.body)
    error = (difference / window.scale)[window.keep]
    return error.reshape(-1) / math.sqrt(error.numel())


def _derivative_residuals(
    prediction: torch.Tensor, window: TrainingWindow, derivative_weight: float
) -> torch.Tensor:
    """Errors of the first differences, scaled so their squared sum is d · MSE_Δ."""
    fitted = prediction[:-1]
    error = ((fitted[1:] - fitted[:-1]) - (window.target[1:] - window.target[:-1]))
    if window.body is not None:  # in the frame of the later row, like ``diff_scale``
        error = _in_loss_frame(error, (window.body[0][1:], window.body[1][1:]))
    error = (error / window.diff_scale)[window.keep_pair]
    if error.numel() == 0:
        return error.reshape(-1)
    return error.reshape(-1) * math.sqrt(derivative_weight / error.numel())


def data_residuals(
    prediction: torch.Tensor, window: TrainingWindow, derivative_weight: float
) -> torch.Tensor:
    """Residual vector of the data terms (MSE and, if weighted, derivative)."""
    parts = [mse_residuals(prediction, window)]
    if derivative_weight > 0.0:
        parts.append(_derivative_residuals(prediction, window, derivative_weight))
    return torch.cat(parts)


def window_mse(prediction: torch.Tensor, window: TrainingWindow) -> float:
    """The MSE part of the objective (the reported loss)."""
    return float(torch.sum(mse_residuals(prediction.detach(), window) ** 2))
