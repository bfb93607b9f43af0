"""The Levenberg–Marquardt Jacobian of the training objective and its normal equations.

`training`'s LM loop (thesis eq. 2.7, w ← w − (JᵀJ + μI)⁻¹ Jᵀε) needs, per epoch, J = dε/dw of
the data residuals (`training_window.data_residuals`) and the damped step. Here:

- ``prediction_jacobian``: dŷLF(t + 1)/dw per row from per-row reverse-mode Jacobians
  (``vmap(jacrev)``) and, in parallel mode, the dynamic-backpropagation recursion through the
  feedback; ``residual_jacobian`` maps it to the residuals' Jacobian (the map is affine);
- for the default network (earth frame, one tanh layer and the linear bypass) the same Jacobian
  written out (bit for bit the autograd one) and the normal equations JᵀJ, Jᵀr built from its
  factors without the dense J (``lm_normal_equations``);
- ``damped_step``: (JᵀJ + diag(b) + μI)⁻¹ g by Cholesky;
- ``window_prediction`` / ``one_layer_prediction``: the window's predictions with a flat weight
  vector (``FlatParameters``), the network not modified.

``LmScratch`` keeps one training's arrays between epochs.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import NamedTuple

import numpy as np
import torch
from torch.func import functional_call, jacrev, vmap

from lf_predictor_ros.core.network import NnarmaxNet, _relative_frame_torch
from lf_predictor_ros.core.training_window import (
    TrainingWindow,
    WindowPredictor,
    data_residuals,
)


@dataclass(frozen=True)
class FlatParameters:
    """Names and shapes of a module's parameters, to move between a flat vector and a dict."""

    names: tuple[str, ...]
    shapes: tuple[torch.Size, ...]
    sizes: tuple[int, ...]

    @classmethod
    def of(cls, module: torch.nn.Module) -> FlatParameters:
        """Layout of ``module.parameters()`` (the order of ``parameters_to_vector``)."""
        named = list(module.named_parameters())
        return cls(
            names=tuple(name for name, _ in named),
            shapes=tuple(param.shape for _, param in named),
            sizes=tuple(param.numel() for _, param in named),
        )

    def unflatten(self, flat: torch.Tensor, prefix: str = '') -> dict[str, torch.Tensor]:
        """Parameter dict for ``functional_call`` from a flat weight vector."""
        parts = flat.split(list(self.sizes))
        return {
            prefix + name: part.view(shape)
            for name, part, shape in zip(self.names, parts, self.shapes, strict=True)
        }


def window_prediction(
    runner: WindowPredictor, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    parallel: bool,
) -> torch.Tensor:
    """Predictions over the window with the weights ``flat`` (the runner is not modified)."""
    buffers = {'net.' + name: value for name, value in runner.net.named_buffers()}
    params = layout.unflatten(flat, prefix='net.')
    prediction: torch.Tensor = functional_call(
        runner, {**params, **buffers}, (window.x_series, window.fb_init, parallel)
    )
    return prediction


def prediction_jacobian(
    runner: WindowPredictor, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    parallel: bool,
) -> torch.Tensor:
    """dŷLF(t + 1)/dw for every row, shape (rows, n_out, n_weights).

    Each row's output depends on its own regressor only, so the per-row Jacobians come from a
    reverse-mode Jacobian of one row, vectorized over the rows (``vmap(jacrev)``): n_out backward
    passes of a tiny network instead of n_weights forward passes over the window. In parallel
    mode the feedback regressors are earlier outputs, and the total derivative follows the
    dynamic-backpropagation recursion (Narendra & Parthasarathy 1991, IEEE TNN 2(2)):

        S_r = ∂f/∂w|_r + Σ_k ∂f/∂fb_k|_r · S_{r−k−1},   S_r = dŷ_r/dw,

    where fb_k is feedback lag k and rows before the first see targets (S = 0).
    """
    net = runner.net
    buffers = dict(net.named_buffers())

    def one_row(weights: torch.Tensor, x_row: torch.Tensor) -> torch.Tensor:
        params = layout.unflatten(weights)
        out: torch.Tensor = functional_call(net, {**params, **buffers}, (x_row[None, :],))
        return out[0]

    if not parallel or runner.nfb == 0:
        written_out = _one_layer_jacobian(net, layout, flat, window.x_series)
        if written_out is not None:
            return written_out
        jac_w: torch.Tensor = vmap(jacrev(one_row), in_dims=(None, 0))(flat, window.x_series)
        return jac_w
    nfb, n_out = runner.nfb, window.target.shape[1]
    with torch.no_grad():
        prediction = window_prediction(runner, layout, flat, window, parallel=True)
    history = torch.cat((window.fb_init, prediction))  # feedback values, oldest first
    rows = prediction.shape[0]
    lag_index = (nfb - 1 + torch.arange(rows))[:, None] - torch.arange(nfb)[None, :]
    x_parallel = torch.cat(
        (window.x_series[:, : runner.n_static], history[lag_index].reshape(rows, nfb * n_out)),
        dim=1,
    )
    jac_w, jac_x = vmap(jacrev(one_row, argnums=(0, 1)), in_dims=(None, 0))(flat, x_parallel)
    direct = jac_w.numpy()
    feedback_gain = jac_x[:, :, runner.n_static :].reshape(rows, n_out, nfb, n_out).numpy()
    total = np.empty_like(direct)
    for row in range(rows):
        sensitivity = direct[row].copy()
        for lag in range(min(nfb, row)):
            sensitivity += feedback_gain[row, :, lag, :] @ total[row - lag - 1]
        total[row] = sensitivity
    return torch.from_numpy(total)


_ONE_LAYER_NAMES = ('hidden.0.weight', 'hidden.0.bias', 'output.weight', 'output.bias',
                    'bypass.weight')


class _OneLayerParts(NamedTuple):
    """The forward values the written-out Jacobian of a one-tanh-layer network is made of."""

    x_s: torch.Tensor  # (rows, n_in) standardized regressors
    tanh: torch.Tensor  # (rows, hidden) tanh layer output
    g_pre: torch.Tensor  # (rows, n_out, hidden) tanh_backward(y_std_i · W2_i, tanh)
    y_std: torch.Tensor  # (n_out,)


@dataclass
class LmScratch:
    """One training's reusable LM Jacobian arrays (what they hold is valid until the next use).

    ``columns``: the residual Jacobian array (its zero blocks stay zero, every other entry is
    written again); ``x_s``: the standardized regressors, which depend on the window and the
    network's standardization only, not on the weights.
    """

    columns: torch.Tensor | None = None
    x_s: torch.Tensor | None = None
    # the window forward's own (batched) standardized regressors and relative base
    forward_x_s: torch.Tensor | None = None
    forward_base: torch.Tensor | None = None
    # the factors of the residual Jacobian's columns (``_one_layer_factors``)
    factors: torch.Tensor | None = None


def _one_layer_parts(
    net: NnarmaxNet, layout: FlatParameters, flat: torch.Tensor, x: torch.Tensor,
    scratch: LmScratch | None = None,
) -> _OneLayerParts | None:
    """Forward values for ``_one_layer_jacobian``; None unless earth frame, 1 layer, bypass."""
    spec = net.spec
    if spec.body_frame or spec.hidden_layers != 1 or layout.names != _ONE_LAYER_NAMES:
        return None
    params = layout.unflatten(flat)
    w1, b1, w2 = params['hidden.0.weight'], params['hidden.0.bias'], params['output.weight']
    rows = x.shape[0]
    n_out, hidden = w2.shape
    with torch.no_grad():
        x_s = scratch.x_s if scratch is not None and scratch.x_s is not None else \
            _standardized_rows(net, x)
        if scratch is not None:
            scratch.x_s = x_s
        tanh = torch.tanh(torch.nn.functional.linear(x_s, w1, b1))
        y_std = net.y_std
        g_pre = torch.ops.aten.tanh_backward(
            (y_std[:, None] * w2)[None].expand(rows, n_out, hidden), tanh[:, None, :])
    return _OneLayerParts(x_s, tanh, g_pre, y_std)


def _one_layer_jacobian(
    net: NnarmaxNet, layout: FlatParameters, flat: torch.Tensor, x: torch.Tensor
) -> torch.Tensor | None:
    """``vmap(jacrev(one_row))`` of an earth-frame network with one tanh layer and a bypass.

    Written out, the backward pass of the basis vector e_i through ŷ = y_mean + y_std ·
    (W2 tanh(W1 x_s + b1) + b2 + Wb x_s) gives single products only: y_std_i · x_s (Wb row i),
    y_std_i · tanh (W2 row i), y_std_i (b2), g = tanh_backward(y_std_i · W2_i, tanh) (b1) and
    g · x_s (W1); every other entry is 0. Computed as such over the whole window, each entry is
    bit for bit the autograd one (zeros +0, as its accumulating products give them): checked on
    every Jacobian of a 1800 s replay and by a test. The standardized regressors of a
    ramp-invariant network come from ``vmap`` over the rows as in ``jacrev`` (its line fit
    rounds differently over a batch). Returns None for any other network (the caller's vmap).
    """
    parts = _one_layer_parts(net, layout, flat, x)
    if parts is None:
        return None
    rows = x.shape[0]
    n_out = parts.y_std.shape[0]
    jac = torch.zeros(rows, n_out, flat.numel(), dtype=torch.float64)
    _fill_one_layer(jac.permute(2, 0, 1), parts)
    return jac


def _fill_one_layer(out: torch.Tensor, parts: _OneLayerParts,
                    residual: _ResidualMap | None = None) -> None:
    """Write the Jacobian into zeroed ``out`` (n_weights, rows, n_out), weights in flat order.

    Only the non-zero blocks are written. With ``residual`` each block is then mapped to the
    residual Jacobian's (``_ResidualMap``): a zero entry maps to +0 exactly, so the zero blocks
    need no work.
    """
    x_s, tanh, g_pre, y_std = parts
    n_in = x_s.shape[1]
    n_out, hidden = g_pre.shape[1:]
    with torch.no_grad():
        w1_end = hidden * n_in
        w1 = out[:w1_end].unflatten(0, (hidden, n_in))
        torch.mul(g_pre.permute(2, 0, 1)[:, None], x_s.T[None, :, :, None], out=w1)
        w1 += 0.0  # −0 products to +0, as autograd's accumulating products
        if residual is not None:
            residual.apply(out[:w1_end])
        b1 = out[w1_end:w1_end + hidden]
        b1.copy_(g_pre.permute(2, 0, 1))
        b1 += 0.0
        if residual is not None:
            residual.apply(b1)
        w2 = out[w1_end + hidden:w1_end + hidden + n_out * hidden].unflatten(0, (n_out, hidden))
        b2 = out[w1_end + hidden + n_out * hidden:w1_end + hidden + n_out * (hidden + 1)]
        wb = out[w1_end + hidden + n_out * (hidden + 1):].unflatten(0, (n_out, n_in))
        for i in range(n_out):
            torch.mul(tanh.T, y_std[i], out=w2[i, :, :, i])
            w2[i, :, :, i] += 0.0
            b2[i, :, i] = y_std[i]
            torch.mul(x_s.T, y_std[i], out=wb[i, :, :, i])
            wb[i, :, :, i] += 0.0
            if residual is not None:
                residual.apply(w2[i, :, :, i], i)
                residual.apply(b2[i, :, i], i)
                residual.apply(wb[i, :, :, i], i)


def _one_layer_kept(
    net: NnarmaxNet, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    derivative_weight: float, scratch: LmScratch | None,
) -> tuple[_OneLayerParts, _ResidualMap] | None:
    """The kept rows' forward values and the MSE residual map, or None (see the callers)."""
    if derivative_weight > 0.0 or window.body is not None:
        return None
    parts = _one_layer_parts(net, layout, flat, window.x_series, scratch)
    if parts is None:
        return None
    rows, n_out = window.x_series.shape[0], parts.y_std.shape[0]
    offset = data_residuals(torch.zeros(rows, n_out, dtype=torch.float64), window, 0.0)
    kept = window.keep.nonzero()[:, 0]
    n_keep = kept.numel()
    residual = _ResidualMap(window.target[kept], window.scale, math.sqrt(n_keep * n_out),
                            offset.view(n_keep, n_out))
    return (_OneLayerParts(parts.x_s[kept], parts.tanh[kept], parts.g_pre[kept], parts.y_std),
            residual)


def _one_layer_residual_jacobian(
    net: NnarmaxNet, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    derivative_weight: float, scratch: LmScratch | None = None,
) -> torch.Tensor | None:
    """``residual_jacobian(prediction_jacobian(...))`` of a one-layer earth-frame network.

    Only the MSE residuals (derivative_weight 0): the kept rows' written-out Jacobian is built
    in the residual Jacobian's own layout (n_weights, n_residuals), and the residual map's
    element-wise steps run on it in place, so neither the whole window's Jacobian nor a
    transposing copy is made. The same numbers: see ``_one_layer_jacobian`` and
    ``_residual_columns``. None when it does not apply. With ``scratch`` (one per training)
    its arrays are reused: the returned Jacobian is then valid until the next call.
    """
    found = _one_layer_kept(net, layout, flat, window, derivative_weight, scratch)
    if found is None:
        return None
    parts, residual = found
    n_keep, n_out = residual.offset.shape
    columns = _zeroed(scratch, (flat.numel(), n_keep, n_out))
    _fill_one_layer(columns, parts, residual)
    return columns.view(flat.numel(), -1).T


def _one_layer_factors(parts: _OneLayerParts, out: torch.Tensor | None = None) -> torch.Tensor:
    """The columns every output's residual Jacobian is a scaling of, transposed: (n_c, n_keep).

    With d = 1 − tanh², output i's prediction Jacobian in row r is y_std_i · W2_ij · d_rj · x_rk
    (W1), y_std_i · W2_ij · d_rj (b1), y_std_i · tanh_rj (W2 row i), y_std_i (b2_i) and
    y_std_i · x_rk (bypass row i), zero elsewhere; the residual map scales output i by
    c_i = 1/(scale_i · √(n_keep · n_out)). So output i's non-zero columns are the shared
    factors B = [d_j x_k, d_j] scaled per hidden unit by a_ij = c_i y_std_i W2_ij and the own
    factors O = [tanh, 1, x] scaled by e_i = c_i y_std_i. Rows: B in flat (W1, b1) order, then O
    in (W2 row, b2, bypass row) order. ``out``: an array to write into.
    """
    x_s, tanh, _, _ = parts
    n_keep, n_in = x_s.shape
    hidden = tanh.shape[1]
    w1_end = hidden * n_in
    shared = w1_end + hidden
    shape = (shared + hidden + 1 + n_in, n_keep)
    if out is None or out.shape != shape:
        out = torch.empty(shape, dtype=torch.float64)
    with torch.no_grad():
        slope = 1.0 - tanh.T * tanh.T  # (hidden, n_keep)
        torch.mul(slope[:, None, :], x_s.T[None], out=out[:w1_end].unflatten(0, (hidden, n_in)))
        out[w1_end:shared] = slope
        out[shared:shared + hidden] = tanh.T
        out[shared + hidden] = 1.0
        out[shared + hidden + 1:] = x_s.T
    return out


def _one_layer_normal_equations(
    net: NnarmaxNet, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    derivative_weight: float, residuals: torch.Tensor, scratch: LmScratch | None = None,
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """(Jᵀ J, Jᵀ r) of ``_one_layer_residual_jacobian``'s J by factors; None where it is None.

    Output i's rows of J are [B diag(â_i), e_i O] in its non-zero columns
    (``_one_layer_factors``; â_i is a_i repeated over each hidden unit's columns), so with
    G = [B O]ᵀ [B O] (one symmetric product, BLAS syrk through numpy) and P = [B O]ᵀ R
    (R: the residuals, one column per output):

        shared × shared  G_BB ∘ Σ_i â_i â_iᵀ      shared × own_i  diag(â_i) G_BO e_i
        own_i × own_i    e_i² G_OO                 own_i × own_j   0 (i ≠ j)
        Jᵀ r: shared Σ_i â_i ∘ P_B,i,  own_i e_i P_O,i.

    The same matrix in exact arithmetic, about n_out × 2 × (n_weights/n_c)² fewer multiply-adds
    than the dense ``J.T @ J``; it differs in the last bits (and in the rounding of the residual
    map's subtract-and-divide, which this skips). Exactly symmetric.
    """
    found = _one_layer_kept(net, layout, flat, window, derivative_weight, scratch)
    if found is None:
        return None
    parts, residual = found
    factors = _one_layer_factors(parts, scratch.factors if scratch is not None else None)
    if scratch is not None:
        scratch.factors = factors
    n_c, n_keep = factors.shape
    n_in = parts.x_s.shape[1]
    n_out, hidden = parts.g_pre.shape[1:]
    shared = hidden * (n_in + 1)
    block = factors.numpy()
    gram = block @ block.T  # numpy: syrk for a matrix times its own transpose
    per_output = np.ascontiguousarray(residuals.view(n_keep, n_out).numpy())
    projected = block @ per_output  # (n_c, n_out)
    w2 = layout.unflatten(flat)['output.weight'].detach().numpy()  # (n_out, hidden)
    own_scale = (parts.y_std / (residual.scale * residual.root)).numpy()  # e_i
    unit_scale = own_scale[:, None] * w2  # a_ij
    # â_i: W1 columns (j, k) then b1 columns j
    shared_scale = np.concatenate((np.repeat(unit_scale, n_in, axis=1), unit_scale), axis=1)
    n_weights = flat.numel()
    matrix = np.zeros((n_weights, n_weights))
    gradient = np.zeros(n_weights)
    # Σ_i â_i â_iᵀ by outer products: exactly symmetric, as G
    outer = sum(np.multiply.outer(scale_i, scale_i) for scale_i in shared_scale)
    matrix[:shared, :shared] = gram[:shared, :shared] * outer
    gradient[:shared] = np.sum(shared_scale.T * projected[:shared], axis=1)
    for i in range(n_out):
        own = np.concatenate((
            np.arange(shared + i * hidden, shared + (i + 1) * hidden),
            [shared + n_out * hidden + i],
            np.arange(shared + n_out * (hidden + 1) + i * n_in,
                      shared + n_out * (hidden + 1) + (i + 1) * n_in)))
        cross = gram[:shared, shared:] * (shared_scale[i][:, None] * own_scale[i])
        matrix[:shared, own] = cross
        matrix[own, :shared] = cross.T
        matrix[np.ix_(own, own)] = gram[shared:, shared:] * own_scale[i] ** 2
        gradient[own] = own_scale[i] * projected[shared:, i]
    return torch.from_numpy(matrix), torch.from_numpy(gradient)


def damped_step(matrix: torch.Tensor, mu: float, gradient: torch.Tensor) -> torch.Tensor:
    """(matrix + μ I)⁻¹ gradient by Cholesky; LU (``linalg.solve``) if it is not positive definite.

    For μ > 0 the damped Gauss–Newton matrix Jᵀ J + diag(b) + μ I is symmetric positive
    definite, so the Cholesky factor exists unless rounding breaks it (then LU as before).
    """
    damped = matrix.clone()
    damped.diagonal().add_(mu)
    factor, info = torch.linalg.cholesky_ex(damped)
    if int(info) != 0:
        lu_step: torch.Tensor = torch.linalg.solve(damped, gradient)
        return lu_step
    step: torch.Tensor = torch.cholesky_solve(gradient[:, None], factor)[:, 0]
    return step


def _zeroed(scratch: LmScratch | None, shape: tuple[int, int, int]) -> torch.Tensor:
    """A zero array of ``shape`` the first time; then the scratch one as it was left."""
    if scratch is not None and scratch.columns is not None and scratch.columns.shape == shape:
        return scratch.columns
    columns = torch.zeros(shape, dtype=torch.float64)
    if scratch is not None:
        scratch.columns = columns
    return columns


@dataclass(frozen=True)
class _ResidualMap:
    """The MSE residual map's element-wise steps ((v − target)/scale)/√n − offset, in place."""

    target: torch.Tensor  # (n_keep, n_out) kept targets
    scale: torch.Tensor  # (n_out,)
    root: float  # √(n_keep · n_out)
    offset: torch.Tensor  # (n_keep, n_out) the map of 0

    def apply(self, values: torch.Tensor, channel: int | None = None) -> None:
        """``values`` (..., n_keep, n_out), or (..., n_keep) of output ``channel``."""
        if channel is None:
            target, scale, offset = self.target, self.scale, self.offset
        else:
            target, scale = self.target[:, channel], self.scale[channel]
            offset = self.offset[:, channel]
        values -= target
        values /= scale
        values /= self.root
        values -= offset


def _standardized_rows(net: NnarmaxNet, x: torch.Tensor) -> torch.Tensor:
    """The standardized (relative) regressors x_s the network's first layers see, (rows, n)."""
    spec = net.spec
    x_mean, x_std = net.regressor_standardization()

    def one(rows: torch.Tensor) -> torch.Tensor:
        if spec.relative:
            rows = rows - _relative_frame_torch(spec, rows)[1]
        return (rows - x_mean) / x_std

    if spec.ramp_invariant:
        per_row: torch.Tensor = vmap(lambda row: one(row[None, :])[0])(x)
        return per_row
    return one(x)


def residual_jacobian(
    jac_prediction: torch.Tensor, window: TrainingWindow, derivative_weight: float
) -> torch.Tensor:
    """Jacobian of the data residuals from that of the predictions (the map is affine).

    Column j is residuals(dŷ/dw_j) − residuals(0). Earth-frame windows compute all columns at
    once (``_residual_columns``), element for element as the per-column map; the result is laid
    out as ``vmap(..., out_dims=1)`` lays it out (transpose of a contiguous (n_weights,
    n_residuals)), so J^T J sees the same operands.
    """
    offset = data_residuals(torch.zeros(jac_prediction.shape[:2], dtype=torch.float64), window,
                             derivative_weight)
    if window.body is None:
        columns = _residual_columns(jac_prediction, window, derivative_weight)
        columns -= offset[:, None]
        return columns.T.contiguous().T

    def linear_part(prediction: torch.Tensor) -> torch.Tensor:
        return data_residuals(prediction, window, derivative_weight) - offset

    jacobian: torch.Tensor = vmap(linear_part, in_dims=2, out_dims=1)(jac_prediction)
    return jacobian


def _residual_columns(
    jac_prediction: torch.Tensor, window: TrainingWindow, derivative_weight: float
) -> torch.Tensor:
    """``data_residuals`` of every column jac_prediction[:, :, j] (earth frame), (n_res, n_w).

    The same element-wise operations in the same order as ``mse_residuals`` and
    ``_derivative_residuals`` (kept rows picked first, which does not change them), in place
    on the (rows, n_out, n_weights) array's layout: few new 15 MB buffers per LM epoch.
    """
    n_weights = jac_prediction.shape[2]
    fitted = jac_prediction[:-1]
    error = fitted[window.keep]
    error -= window.target[window.keep][:, :, None]
    error /= window.scale[:, None]
    mse = error.reshape(-1, n_weights)
    mse /= math.sqrt(error.shape[0] * error.shape[1])
    if not derivative_weight > 0.0:
        return mse
    step = fitted[1:] - fitted[:-1]
    step -= (window.target[1:] - window.target[:-1])[:, :, None]
    step /= window.diff_scale[:, None]
    kept = step[window.keep_pair]
    count = kept.shape[0] * kept.shape[1]
    derivative = kept.reshape(-1, n_weights)
    if count > 0:
        derivative *= math.sqrt(derivative_weight / count)
    return torch.cat((mse, derivative))


def one_layer_prediction(
    runner: WindowPredictor, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    parallel: bool, scratch: LmScratch,
) -> torch.Tensor | None:
    """``window_prediction`` (no grad) of a one-layer earth-frame network, x_s kept in scratch.

    ``NnarmaxNet.forward``'s operations in its order on the weights ``flat``; the standardized
    regressors and the relative base (weight-free) are computed once per training. None when
    it does not apply.
    """
    net = runner.net
    spec = net.spec
    if (parallel and runner.nfb > 0) or spec.body_frame or spec.hidden_layers != 1 or \
            layout.names != _ONE_LAYER_NAMES:
        return None
    if scratch.forward_x_s is None:
        x = window.x_series
        if spec.relative:
            _, shift, scratch.forward_base = _relative_frame_torch(spec, x)
            x = x - shift
        x_mean, x_std = net.regressor_standardization()
        scratch.forward_x_s = (x - x_mean) / x_std
    x_s = scratch.forward_x_s
    params = layout.unflatten(flat)
    linear = torch.nn.functional.linear
    hidden = torch.tanh(linear(x_s, params['hidden.0.weight'], params['hidden.0.bias']))
    out = linear(hidden, params['output.weight'], params['output.bias'])
    out = out + linear(x_s, params['bypass.weight'])
    prediction = net.y_mean + net.y_std * out
    return prediction if scratch.forward_base is None else scratch.forward_base + prediction


def lm_jacobian(
    runner: WindowPredictor, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    parallel: bool, derivative_weight: float, scratch: LmScratch | None = None,
) -> torch.Tensor:
    """Jacobian of the data residuals w.r.t. the weights, (n_residuals, n_weights).

    ``scratch``: see ``_one_layer_residual_jacobian`` (valid until the next call then).
    """
    if not parallel or runner.nfb == 0:
        direct = _one_layer_residual_jacobian(runner.net, layout, flat, window,
                                              derivative_weight, scratch)
        if direct is not None:
            return direct
    return residual_jacobian(prediction_jacobian(runner, layout, flat, window, parallel),
                              window, derivative_weight)


def lm_normal_equations(
    runner: WindowPredictor, layout: FlatParameters, flat: torch.Tensor, window: TrainingWindow,
    parallel: bool, derivative_weight: float, residuals: torch.Tensor, scratch: LmScratch,
) -> tuple[torch.Tensor, torch.Tensor, bool]:
    """(Jᵀ J, Jᵀ r, by_factors): by factors for the default network, else from the dense J."""
    if not parallel or runner.nfb == 0:
        normal = _one_layer_normal_equations(runner.net, layout, flat, window,
                                             derivative_weight, residuals, scratch)
        if normal is not None:
            return normal[0], normal[1], True
    jacobian = lm_jacobian(runner, layout, flat, window, parallel, derivative_weight, scratch)
    return jacobian.T @ jacobian, jacobian.T @ residuals, False
