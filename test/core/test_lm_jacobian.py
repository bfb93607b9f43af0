"""Tests of the Levenberg–Marquardt Jacobian and normal equations (core/lm_jacobian.py)."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import torch

from lf_predictor_ros.core import lm_jacobian
from lf_predictor_ros.core.lm_jacobian import (
    FlatParameters,
    LmScratch,
    damped_step,
    one_layer_prediction,
    prediction_jacobian,
    residual_jacobian,
    window_prediction,
)
from lf_predictor_ros.core.network import NnarmaxNet, NnarmaxSpec
from lf_predictor_ros.core.regressors import n_static_regressors
from lf_predictor_ros.core.training import TrainSettings, train
from lf_predictor_ros.core.training_window import WindowPredictor, data_residuals, prepare_window

# the core conftest's ``one_layer_case`` fixture: seed → (spec, net, u, y, x, mask)
OneLayerCase = Callable[[int], tuple[NnarmaxSpec, NnarmaxNet, np.ndarray, np.ndarray,
                                     np.ndarray, np.ndarray]]

# torch loads its forward-AD decompositions once per process via the deprecated torch.jit.script
pytestmark = pytest.mark.filterwarnings(
    'ignore:`torch.jit.script` is deprecated:DeprecationWarning'
)


@pytest.mark.parametrize('mode', ['series_parallel', 'parallel'])
def test_lm_jacobian_equals_forward_mode_autodiff(mode: str) -> None:
    # The LM Jacobian is assembled from per-row Jacobians (+ the feedback recursion in parallel
    # mode); it must equal brute-force forward-mode AD through the whole (unrolled) window.
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=2, nfb=3, hidden_units=4,
                       hidden_layers=2)
    rng = np.random.default_rng(15)
    n = 80
    u = rng.normal(size=(n, 3))
    x = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
    y = x + rng.normal(scale=0.02, size=(n, 3))
    mask = np.arange(n) < n - 10
    net = NnarmaxNet(spec, seed=16)
    net.set_standardization(u, y)
    with torch.no_grad():
        for param in net.parameters():
            param.add_(0.05 * torch.randn(param.shape, dtype=param.dtype,
                                          generator=torch.Generator().manual_seed(17)))
    window = prepare_window(spec, u, y, x, mask)
    runner = WindowPredictor(net, 2 * 3 + 2 * 3, spec.nfb)
    layout = FlatParameters.of(net)
    flat = torch.nn.utils.parameters_to_vector(net.parameters()).detach()
    parallel = mode == 'parallel'

    def residuals(weights: torch.Tensor) -> torch.Tensor:
        prediction = window_prediction(runner, layout, weights, window, parallel)
        return data_residuals(prediction, window, 0.5)

    expected = torch.func.jacfwd(residuals)(flat)
    jac_prediction = prediction_jacobian(runner, layout, flat, window, parallel)
    actual = residual_jacobian(jac_prediction, window, 0.5)
    # kept targets: indices first + 1 = 3 … 69 → 67 samples, 66 differences, 3 channels each
    assert actual.shape == expected.shape == ((67 + 66) * 3, flat.numel())
    scale = float(expected.abs().max())
    np.testing.assert_allclose(actual.numpy(), expected.numpy(), rtol=0, atol=1e-10 * scale)


@pytest.mark.parametrize('derivative_weight', [0.0, 0.5])
def test_stacked_residual_jacobian_is_bitwise_the_per_column_map(derivative_weight: float
                                                                 ) -> None:
    # The earth-frame fast path of _residual_jacobian must give the vmap'ed per-column map's
    # bits and memory layout: the LM step (J^T J, solve) and so every replay output depend on it.
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=2, nfb=0, hidden_units=4)
    rng = np.random.default_rng(21)
    n = 90
    u = rng.normal(size=(n, 3))
    x = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
    y = x + rng.normal(scale=0.02, size=(n, 3))
    mask = (np.arange(n) < n - 10) & (np.arange(n) % 7 != 3)
    window = prepare_window(spec, u, y, x, mask)
    assert window.body is None
    jac_prediction = torch.from_numpy(rng.normal(size=(window.target.shape[0] + 1, 3, 40)))
    offset = data_residuals(torch.zeros(jac_prediction.shape[:2], dtype=torch.float64),
                                      window, derivative_weight)

    def linear_part(prediction: torch.Tensor) -> torch.Tensor:
        return data_residuals(prediction, window, derivative_weight) - offset

    expected = torch.func.vmap(linear_part, in_dims=2, out_dims=1)(jac_prediction)
    actual = residual_jacobian(jac_prediction, window, derivative_weight)
    assert torch.equal(actual, expected)
    assert actual.stride() == expected.stride()


@pytest.mark.parametrize('ramp_invariant', [False, True])
def test_one_layer_jacobian_is_bitwise_vmap_jacrev(ramp_invariant: bool) -> None:
    # The written-out Jacobian of the default network shape (one tanh layer + bypass) must give
    # vmap(jacrev)'s bits, zero signs included: the LM step and every replay output depend on it.
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=3, ny=4, nfb=0, hidden_units=2,
                       relative=True, ramp_invariant=ramp_invariant)
    rng = np.random.default_rng(23)
    n = 120
    u = rng.normal(size=(n, 3))
    x = np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)
    y = x + rng.normal(scale=0.02, size=(n, 3))
    net = NnarmaxNet(spec, seed=24)
    net.set_standardization(u, y)
    window = prepare_window(spec, u, y, x, np.arange(n) % 9 != 4)
    layout = FlatParameters.of(net)
    flat = torch.nn.utils.parameters_to_vector(net.parameters()).detach()
    buffers = dict(net.named_buffers())

    def one_row(weights: torch.Tensor, x_row: torch.Tensor) -> torch.Tensor:
        return torch.func.functional_call(net, {**layout.unflatten(weights), **buffers},
                                          (x_row[None, :],))[0]

    generator = torch.Generator().manual_seed(25)
    scratch = LmScratch()  # reused across the two weights, as in the LM epochs
    for weights in (flat, flat + 0.3 * torch.randn(flat.shape, generator=generator,
                                                   dtype=torch.float64)):
        expected = torch.func.vmap(torch.func.jacrev(one_row), in_dims=(None, 0))(
            weights, window.x_series)
        actual = lm_jacobian._one_layer_jacobian(net, layout, weights, window.x_series)
        assert actual is not None
        assert torch.equal(actual.view(torch.int64), expected.view(torch.int64))
        # the LM's residual Jacobian built straight from it (MSE only): same bits and layout
        runner = WindowPredictor(net, n_static_regressors(spec), spec.nfb)
        reference = residual_jacobian(expected, window, 0.0)
        direct = lm_jacobian.lm_jacobian(runner, layout, weights, window, False, 0.0)
        assert direct.stride() == reference.stride()
        assert torch.equal(direct.view(torch.int64), reference.view(torch.int64))
        reused = lm_jacobian.lm_jacobian(runner, layout, weights, window, False, 0.0, scratch)
        assert torch.equal(reused.view(torch.int64), reference.view(torch.int64))
        with torch.no_grad():  # the LM's candidate forward pass, x_s kept in scratch
            forward = window_prediction(runner, layout, weights, window, False)
            kept = one_layer_prediction(runner, layout, weights, window, False,
                                                  scratch)
        assert kept is not None
        assert torch.equal(kept.view(torch.int64), forward.view(torch.int64))
    two_layers = NnarmaxNet(NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=3, ny=4, nfb=0,
                                        hidden_units=2, hidden_layers=2), seed=1)
    assert lm_jacobian._one_layer_jacobian(two_layers, FlatParameters.of(two_layers),
                                        flat, window.x_series) is None


def test_blockwise_normal_equations_equal_the_dense_products(one_layer_case: OneLayerCase) -> None:
    # The LM's fast path builds Jᵀ J and Jᵀ r from the factors of the Jacobian's columns; they
    # must be the dense products of the residual Jacobian (up to rounding), exactly symmetric,
    # with exact zeros between two outputs' own columns.
    spec, net, u, y, x, mask = one_layer_case(31)
    window = prepare_window(spec, u, y, x, mask)
    layout = FlatParameters.of(net)
    flat = torch.nn.utils.parameters_to_vector(net.parameters()).detach()
    generator = torch.Generator().manual_seed(32)
    scratch = LmScratch()  # reused across the weights, as in the LM epochs
    for weights in (flat, flat + 0.3 * torch.randn(flat.shape, generator=generator,
                                                   dtype=torch.float64)):
        jacobian = lm_jacobian._one_layer_residual_jacobian(net, layout, weights, window, 0.0)
        assert jacobian is not None
        dense = jacobian.clone()
        residuals = torch.randn(dense.shape[0], generator=generator, dtype=torch.float64)
        found = lm_jacobian._one_layer_normal_equations(net, layout, weights, window, 0.0,
                                                     residuals, scratch)
        assert found is not None
        matrix, gradient = found
        expected = dense.T @ dense
        assert torch.equal(matrix, matrix.T)
        np.testing.assert_allclose(matrix.numpy(), expected.numpy(), rtol=1e-12,
                                   atol=1e-12 * float(expected.abs().max()))
        expected_gradient = dense.T @ residuals
        np.testing.assert_allclose(gradient.numpy(), expected_gradient.numpy(), rtol=1e-12,
                                   atol=1e-12 * float(expected_gradient.abs().max()))
        # W2 row 0 against W2 row 1: disjoint outputs' own columns
        n_in = window.x_series.shape[1]
        shared = 2 * (n_in + 1)  # W1 (2 × n_in), b1
        assert torch.all(matrix[shared:shared + 2, shared + 2:shared + 4] == 0.0)
        assert torch.all(expected[shared:shared + 2, shared + 2:shared + 4] == 0.0)
        # output i's rows of J: its non-zero columns are the factors times e_i or â_i
        factors = scratch.factors
        assert factors is not None
        by_output = dense.view(-1, 3, flat.numel())
        w2 = layout.unflatten(weights)['output.weight']
        for i in range(3):
            e_i = net.y_std[i] / (window.scale[i] * np.sqrt(by_output.shape[0] * 3))
            a_i = e_i * w2[i]
            # W2 row i (3 × 2), b2_i, bypass row i (3 × n_in)
            own = list(range(shared + 2 * i, shared + 2 * i + 2)) + [shared + 6 + i] + list(
                range(shared + 9 + i * n_in, shared + 9 + (i + 1) * n_in))
            scale = torch.cat((a_i.repeat_interleave(n_in), a_i, e_i.repeat(len(own))))
            expected_rows = by_output[:, i, list(range(shared)) + own]
            actual_rows = (factors * scale[:, None]).T
            np.testing.assert_allclose(actual_rows.numpy(), expected_rows.numpy(), rtol=0,
                                       atol=1e-13 * float(expected_rows.abs().max()))
            others = [c for c in range(flat.numel()) if c >= shared and c not in own]
            assert torch.all(by_output[:, i, others] == 0.0)
    two_layers = NnarmaxNet(NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=3, ny=4, nfb=0,
                                        hidden_units=2, hidden_layers=2), seed=1)
    assert lm_jacobian._one_layer_normal_equations(
        two_layers, FlatParameters.of(two_layers), flat, window, 0.0,
        torch.zeros(1, dtype=torch.float64)) is None
    assert lm_jacobian._one_layer_normal_equations(net, layout, flat, window, 0.5,
                                                torch.zeros(1, dtype=torch.float64)) is None


def test_cholesky_step_equals_the_lu_step(one_layer_case: OneLayerCase) -> None:
    spec, net, u, y, x, mask = one_layer_case(33)
    window = prepare_window(spec, u, y, x, mask)
    layout = FlatParameters.of(net)
    flat = torch.nn.utils.parameters_to_vector(net.parameters()).detach()
    dense = lm_jacobian._one_layer_residual_jacobian(net, layout, flat, window, 0.0)
    assert dense is not None
    matrix = dense.T @ dense
    matrix = 0.5 * (matrix + matrix.T)
    gradient = torch.from_numpy(np.random.default_rng(34).normal(size=flat.numel()))
    identity = torch.eye(flat.numel(), dtype=torch.float64)
    for mu in (1e-3, 1e-1, 1e3):
        lu = torch.linalg.solve(matrix + mu * identity, gradient)
        cholesky = damped_step(matrix, mu, gradient)
        np.testing.assert_allclose(cholesky.numpy(), lu.numpy(), rtol=0,
                                   atol=1e-9 * float(lu.abs().max()))
    # not positive definite: the LU fallback, the same bits as linalg.solve
    indefinite = matrix - 10.0 * identity
    step = damped_step(indefinite, 1e-3, gradient)
    assert torch.equal(step, torch.linalg.solve(indefinite + 1e-3 * identity, gradient))
    assert torch.all(torch.isfinite(step))


def test_lm_fast_path_trains_to_the_dense_paths_loss(
        monkeypatch: pytest.MonkeyPatch, one_layer_case: OneLayerCase) -> None:
    # Blockwise normal equations + Cholesky against the dense J^T J + LU of before: the same
    # LM (eq. 2.7, trainlm μ), so after 30 epochs the same losses up to rounding: relative
    # 1e-9 asserted (2e-14 seen).
    spec, net, u, y, x, mask = one_layer_case(35)
    settings = TrainSettings(max_epochs=30, max_seconds=60.0, min_grad=0.0)
    calls = []
    fast_path = lm_jacobian._one_layer_normal_equations

    def counted(*args: object, **kwargs: object) -> object:
        found = fast_path(*args, **kwargs)  # type: ignore[arg-type]
        calls.append(found is not None)
        return found

    monkeypatch.setattr(lm_jacobian, '_one_layer_normal_equations', counted)
    fast = train(net, u, y, x, mask, settings)
    assert calls and all(calls)
    monkeypatch.setattr(lm_jacobian, '_one_layer_normal_equations', lambda *args: None)
    dense = train(net, u, y, x, mask, settings)
    print(f'fast {fast.loss!r} ({fast.epochs} epochs), dense {dense.loss!r} ({dense.epochs})')
    assert fast.loss < 0.5 * fast.initial_loss
    assert fast.epochs == dense.epochs
    assert fast.loss == pytest.approx(dense.loss, rel=1e-9)
    np.testing.assert_allclose(fast.loss_history, dense.loss_history, rtol=1e-9)
