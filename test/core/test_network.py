"""Tests of the NNARMAX network, its regressors, the numpy predict path and checkpoints."""
from __future__ import annotations

from pathlib import Path
import statistics
import time

import numpy as np
import pytest
import torch

from lf_predictor_ros.core.network import (
    CHECKPOINT_FORMAT,
    NnarmaxNet,
    NnarmaxSpec,
    NumpyNnarmax,
    load_checkpoint,
    predict_step,
    relative_spread,
    save_checkpoint,
    solve_ridge,
)
from lf_predictor_ros.core.regressors import build_regressors, regressor_vector

SPEC_3DOF = NnarmaxSpec(
    n_outputs=3, n_inputs_u=3, nu=2, ny=3, nfb=2, hidden_units=8, hidden_layers=2
)


def _random_series(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forces [N], positions [m, m, rad] and LF feedback with realistic magnitudes."""
    rng = np.random.default_rng(seed)
    u = rng.normal(scale=[2e5, 1e5, 3e6], size=(n, 3))
    y = np.cumsum(rng.normal(scale=[0.2, 0.2, 0.01], size=(n, 3)), axis=0) + [120.0, -40.0, 2.0]
    fb = y + rng.normal(scale=0.05, size=(n, 3))
    return u, y, fb


def _trained_looking_net(spec: NnarmaxSpec, seed: int) -> NnarmaxNet:
    """A network with non-trivial (random) output weights and data-based standardization."""
    net = NnarmaxNet(spec, seed=seed)
    u, y, _ = _random_series(300, seed)
    net.set_standardization(u, y, preserve_function=False)
    generator = torch.Generator().manual_seed(seed + 100)
    with torch.no_grad():
        for name, param in net.named_parameters():
            size = 0.01 if name.startswith('bypass') else 0.1  # keep the recursion stable
            param.add_(size * torch.randn(param.shape, generator=generator, dtype=param.dtype))
    return net


def test_spec_rejects_broken_rules() -> None:
    with pytest.raises(ValueError, match='n_outputs must be 1 or 3'):
        NnarmaxSpec(n_outputs=2, n_inputs_u=1, nu=1, ny=1, nfb=1, hidden_units=4)
    with pytest.raises(ValueError, match='ny \\+ nfb ≥ 1'):
        NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=2, ny=0, nfb=0, hidden_units=4)
    with pytest.raises(ValueError, match='hidden_units must be an int ≥ 0'):
        NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=1, nfb=1, hidden_units=-1)
    with pytest.raises(ValueError, match='hidden_units = 0 .* needs linear_bypass'):
        NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=1, nfb=1, hidden_units=0,
                    linear_bypass=False)
    with pytest.raises(ValueError, match='nu must be an int ≥ 0'):
        NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=-1, ny=1, nfb=1, hidden_units=3)
    assert SPEC_3DOF.n_regressors == 2 * 3 + (3 + 2) * 3
    assert SPEC_3DOF.first_index == 2


def test_build_regressors_layout_is_lag_major_newest_first() -> None:
    spec = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=2, ny=3, nfb=1, hidden_units=2)
    n = 7
    u = 100.0 + np.arange(n, dtype=float)
    y = 200.0 + np.arange(n, dtype=float)
    fb = 300.0 + np.arange(n, dtype=float)
    u_before = u.copy()
    x, first = build_regressors(u, y, fb, spec)
    assert first == 2
    assert x.shape == (n - 2, 2 + 3 + 1)
    # row k is time t = first + k: [u(t), u(t−1), y(t), y(t−1), y(t−2), fb(t)]
    np.testing.assert_array_equal(x[0], [102, 101, 202, 201, 200, 302])
    np.testing.assert_array_equal(x[-1], [106, 105, 206, 205, 204, 306])
    np.testing.assert_array_equal(u, u_before)


def test_build_regressors_three_channels_and_vector_path_agree() -> None:
    u, y, fb = _random_series(50, 1)
    x, first = build_regressors(u, y, fb, SPEC_3DOF)
    t = 20
    row = x[t - first]
    np.testing.assert_array_equal(row[:3], u[t])
    np.testing.assert_array_equal(row[3:6], u[t - 1])
    np.testing.assert_array_equal(row[6:9], y[t])
    np.testing.assert_array_equal(row[12:15], y[t - 2])
    np.testing.assert_array_equal(row[15:18], fb[t])
    np.testing.assert_array_equal(row[18:21], fb[t - 1])
    np.testing.assert_array_equal(
        regressor_vector(u[: t + 1], y[: t + 1], fb[: t + 1], SPEC_3DOF), row
    )


def test_build_regressors_refuses_misaligned_or_short_series() -> None:
    u, y, fb = _random_series(10, 2)
    with pytest.raises(ValueError, match='same length'):
        build_regressors(u[:-1], y, fb, SPEC_3DOF)
    with pytest.raises(ValueError, match='shape \\(n, 3\\)'):
        build_regressors(u[:, :2], y, fb, SPEC_3DOF)
    with pytest.raises(ValueError, match='need more than'):
        build_regressors(u[:2], y[:2], fb[:2], SPEC_3DOF)


def test_untrained_network_is_persistence_of_the_feedback() -> None:
    u, y, fb = _random_series(40, 3)
    net = NnarmaxNet(SPEC_3DOF, seed=5)
    net.set_standardization(u, y)
    x, first = build_regressors(u, y, fb, SPEC_3DOF)
    with torch.no_grad():
        prediction = net(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(prediction, fb[first:], rtol=0, atol=1e-9)


def test_standardization_buffers_and_function_preservation() -> None:
    net = _trained_looking_net(SPEC_3DOF, seed=7)
    u, y, fb = _random_series(200, 8)
    y_shifted = y + [500.0, 300.0, 0.0]  # the vessel moved: new mean, same spread
    x = torch.from_numpy(build_regressors(u, y_shifted, fb + [500.0, 300.0, 0.0], SPEC_3DOF)[0])
    with torch.no_grad():
        before = net(x)
    net.set_standardization(u, y_shifted)
    np.testing.assert_allclose(net.y_mean.numpy(), y_shifted.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(net.u_std.numpy(), u.std(axis=0), rtol=1e-12)
    with torch.no_grad():
        after = net(x)
    np.testing.assert_allclose(after.numpy(), before.numpy(), rtol=0, atol=1e-8)
    net.set_standardization(u * 3.0, y, preserve_function=False)
    with torch.no_grad():
        changed = net(x)
    assert float(torch.max(torch.abs(changed - before))) > 1e-3


def test_constant_channel_is_not_divided_by_zero() -> None:
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=1, ny=1, nfb=1, hidden_units=3)
    net = NnarmaxNet(spec)
    u, y, _ = _random_series(30, 9)
    y[:, 2] = 0.7  # heading held perfectly constant
    net.set_standardization(u, y)
    assert float(net.y_std[2]) == 1.0
    assert np.isfinite(net.y_std.numpy()).all()


def test_free_run_equals_row_by_row_forward() -> None:
    net = _trained_looking_net(SPEC_3DOF, seed=11)
    u, y, fb = _random_series(60, 12)
    x, first = build_regressors(u, y, fb, SPEC_3DOF)
    n_static = 2 * 3 + 3 * 3
    fb_init = torch.from_numpy(fb[first - 1 : first + 1])
    with torch.no_grad():
        fast = net.free_run(torch.from_numpy(x[:, :n_static]), fb_init).numpy()
        feedback = [fb[first - 1], fb[first]]
        slow = []
        for row in x:
            regressor = np.concatenate((row[:n_static], feedback[-1], feedback[-2]))
            slow.append(net(torch.from_numpy(regressor)[None, :])[0].numpy())
            feedback.append(slow[-1])
        fast_numpy = net.free_run(
            torch.from_numpy(x[:, :n_static]), fb_init, differentiable=False
        ).numpy()
    assert np.abs(fast).max() < 1e4  # a stable recursion, not an overflow
    np.testing.assert_allclose(fast, np.array(slow), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(fast_numpy, fast, rtol=1e-12, atol=1e-9)


def test_predict_step_equals_batch_forward_and_is_fast() -> None:
    net = _trained_looking_net(SPEC_3DOF, seed=13)
    fast_net = NumpyNnarmax.from_module(net)
    u, y, fb = _random_series(100, 14)
    x, first = build_regressors(u, y, fb, SPEC_3DOF)
    with torch.no_grad():
        batch = net(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(fast_net.forward(x), batch, rtol=0, atol=1e-9)
    for t in (first, 50, 99):
        hist = (u[: t + 1], y[: t + 1], fb[: t + 1])
        np.testing.assert_allclose(predict_step(fast_net, *hist), batch[t - first], atol=1e-9)
        np.testing.assert_allclose(predict_step(net, *hist), batch[t - first], atol=1e-9)
    window = (u[-10:], y[-10:], fb[-10:])
    durations = []
    for _ in range(1000):
        start = time.perf_counter()
        predict_step(fast_net, *window)
        durations.append(time.perf_counter() - start)
    median_us = statistics.median(durations) * 1e6
    print(f'predict_step (NumpyNnarmax, 3-DOF, 2×8 tanh): median {median_us:.1f} µs over 1000')
    assert median_us < 2000.0


def test_numpy_copy_is_immutable_and_independent_of_the_module() -> None:
    net = _trained_looking_net(SPEC_3DOF, seed=15)
    fast_net = NumpyNnarmax.from_module(net)
    with pytest.raises(ValueError, match='read-only'):
        fast_net.output_weight[0, 0] = 1.0
    u, y, fb = _random_series(20, 16)
    before = predict_step(fast_net, u, y, fb)
    with torch.no_grad():
        net.output.weight.mul_(2.0)
    np.testing.assert_array_equal(predict_step(fast_net, u, y, fb), before)


def test_predict_step_refuses_short_history() -> None:
    fast_net = NumpyNnarmax.from_module(NnarmaxNet(SPEC_3DOF))
    u, y, fb = _random_series(5, 17)
    with pytest.raises(ValueError, match='y_hist must have shape'):
        predict_step(fast_net, u, y[-2:], fb)


def test_checkpoint_round_trip_gives_identical_predictions(tmp_path: Path) -> None:
    net = _trained_looking_net(SPEC_3DOF, seed=19)
    path = tmp_path / 'net.pt'
    meta = {'loss': 1.25e-3, 'wave_peak_freq': 0.61, 'note': 'unit test'}
    save_checkpoint(path, SPEC_3DOF, net.state_dict(), meta)
    spec, state, loaded_meta = load_checkpoint(path, expected_spec=SPEC_3DOF)
    assert spec == SPEC_3DOF
    assert loaded_meta == meta
    restored = NnarmaxNet.from_state(spec, state)
    u, y, fb = _random_series(80, 20)
    x = torch.from_numpy(build_regressors(u, y, fb, SPEC_3DOF)[0])
    with torch.no_grad():
        assert torch.equal(restored(x), net(x))
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_checkpoint_refuses_corrupt_truncated_and_foreign_files(tmp_path: Path) -> None:
    good = tmp_path / 'good.pt'
    save_checkpoint(good, SPEC_3DOF, NnarmaxNet(SPEC_3DOF).state_dict())
    garbage = tmp_path / 'garbage.pt'
    garbage.write_bytes(np.random.default_rng(0).bytes(2000))
    with pytest.raises(ValueError, match='corrupt'):
        load_checkpoint(garbage)
    truncated = tmp_path / 'truncated.pt'
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ValueError, match='corrupt'):
        load_checkpoint(truncated)
    foreign = tmp_path / 'foreign.pt'
    torch.save({'weights': torch.zeros(3)}, foreign)
    with pytest.raises(ValueError, match='not an NNARMAX checkpoint'):
        load_checkpoint(foreign)
    with pytest.raises(FileNotFoundError):
        load_checkpoint(tmp_path / 'missing.pt')


def test_checkpoint_refuses_other_version_and_other_spec(tmp_path: Path) -> None:
    path = tmp_path / 'net.pt'
    save_checkpoint(path, SPEC_3DOF, NnarmaxNet(SPEC_3DOF).state_dict())
    other_spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=3, nfb=2, hidden_units=9)
    with pytest.raises(ValueError, match='was expected'):
        load_checkpoint(path, expected_spec=other_spec)
    payload = torch.load(path, weights_only=True)
    payload['version'] = 99
    future = tmp_path / 'future.pt'
    torch.save(payload, future)
    with pytest.raises(ValueError, match='format version 99'):
        load_checkpoint(future)
    payload['version'] = 1
    payload['spec'] = other_spec.to_dict()  # state of an 8-unit net under a 9-unit spec
    mismatched = tmp_path / 'mismatched.pt'
    torch.save(payload, mismatched)
    assert payload['format'] == CHECKPOINT_FORMAT
    with pytest.raises(ValueError, match='does not fit'):
        load_checkpoint(mismatched)
    with pytest.raises(ValueError, match='does not fit'):
        save_checkpoint(path, other_spec, NnarmaxNet(SPEC_3DOF).state_dict())
    with pytest.raises(ValueError, match='JSON'):
        save_checkpoint(path, SPEC_3DOF, NnarmaxNet(SPEC_3DOF).state_dict(), {'x': object()})


def test_relative_spread_of_a_ramp_is_the_rms_of_the_lag_offsets() -> None:
    """y(t) = c·t: y(t − i) − y(t) = −i·c, so the RMS over i = 1…ny−1 is c·√(mean i²)."""
    c = 0.3  # m/sample
    y = c * np.arange(200.0)[:, None]
    ny = 5
    expected = c * np.sqrt(np.mean(np.arange(1, ny) ** 2))  # √7.5·c
    assert relative_spread(y, ny)[0] == pytest.approx(expected, rel=1e-12)
    assert relative_spread(y, 1)[0] == pytest.approx(c, rel=1e-12)  # one lag at least


def test_relative_standardization_uses_the_regressor_span_not_the_window_spread() -> None:
    """A drifting window (spread ≈ 58 m) with 0.1 m steps: y_std is ≈ the step size scale."""
    spec = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=3, nfb=0, hidden_units=2,
                       relative=True)
    y = 0.1 * np.arange(2000.0)[:, None]  # m
    net = NnarmaxNet(spec)
    net.set_standardization(np.ones((2000, 1)) + np.arange(2000.0)[:, None], y)
    assert float(net.y_mean[0]) == 0.0
    assert float(net.y_std[0]) == pytest.approx(0.1 * np.sqrt(2.5), rel=1e-9)


@pytest.mark.parametrize('relative', [False, True])
def test_fit_linear_bypass_recovers_a_linear_arx_system_exactly(relative: bool) -> None:
    """Noise-free y(t+1) = 1.6 y(t) − 0.6 y(t−1) + 0.2 u(t) + 0.1: one solve, error ~ 1e-9.

    The y coefficients sum to 1 (a vessel without a position spring), so the system is
    translation invariant and the relative network can represent it as well.
    """
    rng = np.random.default_rng(3)
    n = 400
    u = rng.normal(size=(n, 1))
    y = np.zeros((n, 1))
    for t in range(1, n - 1):
        y[t + 1] = 1.6 * y[t] - 0.6 * y[t - 1] + 0.2 * u[t] + 0.1
    spec = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=2, nfb=0, hidden_units=3,
                       relative=relative)
    net = NnarmaxNet(spec, seed=1)
    net.set_standardization(u, y)
    x, first = build_regressors(u, y, y, spec)
    x_t = torch.from_numpy(x[:-1])
    target = torch.from_numpy(y[first + 1:])
    keep = torch.ones(len(target), dtype=torch.bool)
    keep[:5] = False  # rows left out must not matter for an exact fit
    net.fit_linear_bypass(x_t, target, keep, ridge=0.0)
    with torch.no_grad():
        error = net(x_t) - target
    assert float(error.abs().max()) < 1e-8


def test_solve_ridge_pulls_towards_the_prior() -> None:
    """The minimizer of ‖D w − y‖² + rows λ (w − p)²: (DᵀD + rows λ) w = Dᵀy + rows λ p.

    One regressor x with y = 2 x (+ bias 0.5, unpenalized): λ 0 gives 2; λ = mean x² gives the
    mean of 2 and the prior 5, i.e. 3.5; with no prior the same λ gives 1 (towards 0).
    """
    rng = np.random.default_rng(8)
    x = rng.normal(size=500)
    x -= x.mean()
    design = torch.from_numpy(np.column_stack((x, np.ones_like(x))))
    wanted = torch.from_numpy((2.0 * x + 0.5)[:, None])
    lam = float(np.mean(x * x))
    prior = torch.tensor([[5.0]], dtype=torch.float64)
    assert float(solve_ridge(design, wanted, torch.tensor([0.0], dtype=torch.float64),
                             prior)[0, 0]) == pytest.approx(2.0, abs=1e-9)
    pulled = solve_ridge(design, wanted, torch.tensor([lam], dtype=torch.float64), prior)
    assert float(pulled[0, 0]) == pytest.approx(3.5, abs=1e-9)
    assert float(pulled[1, 0]) == pytest.approx(0.5, abs=1e-9)  # the bias is free
    shrunk = solve_ridge(design, wanted, torch.tensor([lam], dtype=torch.float64))
    assert float(shrunk[0, 0]) == pytest.approx(1.0, abs=1e-9)


def test_force_prior_keeps_force_weights_the_window_cannot_identify() -> None:
    """A window whose force is a copy of the newest position: the force weight is unidentified.

    Plain ridge: the minimum-norm split between the force and the position weight. With
    ``force_prior``: the force weight stays at its warm-start value (within 1e-3 relative: the
    position weight's own ridge LINEAR_RIDGE towards 0 pulls a little the other way) and the
    position weight takes the rest, so the prediction on the window is as good. A window
    where the force is independent identifies its weight whatever the prior.
    """
    rng = np.random.default_rng(9)
    n = 600
    spec = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=1, nfb=0, hidden_units=0,
                       relative=False)
    y = np.cumsum(rng.normal(size=(n, 1)), axis=0) * 0.1
    for collinear in (True, False):
        u = y.copy() if collinear else rng.normal(size=(n, 1))
        x, first = build_regressors(u, y, y, spec)
        x_t = torch.from_numpy(x[:-1])  # rows t = first … n − 2, predicting ŷ(t + 1)
        target = torch.from_numpy(0.9 * y[first:-1] + (0.0 if collinear else 0.3 * u[first:-1]))
        keep = torch.ones(len(target), dtype=torch.bool)
        warm = NnarmaxNet(spec, seed=1)
        warm.set_standardization(u, y)
        with torch.no_grad():
            warm.bypass.weight[0, 0] = 0.25  # the warm start's force weight (standardized)
        plain, pulled = NnarmaxNet.from_state(spec, warm.state_dict()), \
            NnarmaxNet.from_state(spec, warm.state_dict())
        plain.fit_linear_bypass(x_t, target, keep)
        pulled.fit_linear_bypass(x_t, target, keep, force_prior=0.01)
        with torch.no_grad():
            force_weight = float(pulled.bypass.weight[0, 0])
            plain_weight = float(plain.bypass.weight[0, 0])
            error = float((pulled(x_t) - target).abs().max())
        if collinear:
            assert force_weight == pytest.approx(0.25, rel=1e-3)
            assert plain_weight != pytest.approx(0.25, rel=1e-2)
            assert error < 1e-6
        else:
            true_weight = 0.3 * float(plain.u_std[0]) / float(plain.y_std[0])
            assert force_weight == pytest.approx(true_weight, rel=0.02)


def test_hold_forces_keeps_the_force_weights_and_solves_the_rest_given_them() -> None:
    """``hold_forces``: the force weights stay bit for bit, the rest is the reduced solution.

    A window with an independent force (its true weight 0.3 in raw units) and a warm start whose
    force weight is wrong (0.25 standardized): the held fit keeps 0.25 and its position weight
    and bias are the least-squares solution of the target minus the held force part (numpy's
    lstsq on the reduced problem), while the free fit finds the true force weight.
    """
    rng = np.random.default_rng(10)
    n = 600
    spec = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=1, nfb=0, hidden_units=0,
                       relative=False)
    y = np.cumsum(rng.normal(size=(n, 1)), axis=0) * 0.1
    u = rng.normal(size=(n, 1))
    x, first = build_regressors(u, y, y, spec)
    x_t = torch.from_numpy(x[:-1])
    target = torch.from_numpy(0.9 * y[first:-1] + 0.3 * u[first:-1] + 0.05)
    keep = torch.ones(len(target), dtype=torch.bool)
    warm = NnarmaxNet(spec, seed=1)
    warm.set_standardization(u, y)
    with torch.no_grad():
        warm.bypass.weight[0, 0] = 0.25
    held, free = NnarmaxNet.from_state(spec, warm.state_dict()), \
        NnarmaxNet.from_state(spec, warm.state_dict())
    held.fit_linear_bypass(x_t, target, keep, hold_forces=True, force_prior=0.5)
    free.fit_linear_bypass(x_t, target, keep)
    weights, bias = held.bypass.weight.detach(), held.output.bias.detach()
    assert float(weights[0, 0]) == 0.25
    design, wanted = held.linear_problem(x_t, target, keep)
    reduced = (wanted - 0.25 * design[:, :1]).numpy()
    expected = np.linalg.lstsq(design[:, 1:].numpy(), reduced, rcond=None)[0]
    assert float(weights[0, 1]) == pytest.approx(float(expected[0, 0]), abs=1e-6)
    assert float(bias[0]) == pytest.approx(float(expected[1, 0]), abs=1e-6)
    true_weight = 0.3 * float(free.u_std[0]) / float(free.y_std[0])
    assert float(free.bypass.weight.detach()[0, 0]) == pytest.approx(true_weight, rel=0.02)
    assert abs(true_weight - 0.25) > 0.05  # the held weight is a real constraint here


def test_linear_network_is_the_bypass_plus_a_bias() -> None:
    """hidden_units 0: ŷ = y_mean + y_std · (v_0 + B x_s), weights n_reg · n_out + n_out."""
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=3, nfb=0, hidden_units=0,
                       relative=True, body_frame=True)
    assert spec.linear and not SPEC_3DOF.linear
    net = NnarmaxNet(spec, seed=4)
    assert sum(p.numel() for p in net.parameters()) == spec.n_regressors * 3 + 3
    u, y, _ = _random_series(60, seed=5)
    net.set_standardization(u, y)
    rng = np.random.default_rng(6)
    bias = torch.tensor([0.3, -0.2, 0.01], dtype=torch.float64)
    with torch.no_grad():
        net.bypass.weight.copy_(torch.from_numpy(rng.normal(scale=0.01,
                                                            size=(3, spec.n_regressors))))
        x_t = torch.from_numpy(build_regressors(u, y, y, spec)[0])
        without_bias = net(x_t)
        net.output.bias.copy_(bias)
        got = net(x_t)
    # the bias is one body-frame step v_0 · y_std, turned to north/east by the newest heading
    psi = torch.from_numpy(y[spec.first_index:, 2])
    step = bias * net.y_std
    expected = torch.stack((torch.cos(psi) * step[0] - torch.sin(psi) * step[1],
                            torch.sin(psi) * step[0] + torch.cos(psi) * step[1],
                            step[2].expand_as(psi)), dim=1)
    assert torch.allclose(got - without_bias, expected, atol=1e-12)
    assert np.allclose(NumpyNnarmax.from_module(net).forward(x_t.numpy()), got.numpy(),
                       atol=1e-12)
