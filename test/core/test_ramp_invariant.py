"""Ramp-invariant regressors (``PredictorParams.ramp_invariant``, issue 13).

A relative network is translation invariant: it sees y(t − i) − y(t). With ``ramp_invariant``
it sees the positions relative to the least-squares line through its ny newest positions and
its output is added to that line's extrapolation y(t) + v̂. A vessel moving at constant velocity
(a ramp in every channel) then leaves only the forces and the constant biases in front of the
network, so the prediction of a ramp is the ramp's next value plus one constant, whatever the
ramp's offset and slope, for any weights. Without the option a network does not have that.
With ``ramp_order`` 2 the same holds for a parabola (constant acceleration).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
import pytest
import torch

from lf_predictor_ros.core.network import (
    NnarmaxNet,
    NnarmaxSpec,
    NumpyNnarmax,
    predict_step,
    ramp_fit_weights,
    ramp_slope_weights,
    relative_spread,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.regressors import rotate_blocks
from lf_predictor_ros.core.retraining import network_spec, train_settings
from lf_predictor_ros.core.training import evaluate_loss, train

FloatArray = NDArray[np.float64]
RAMPS = (((5.0, -3.0, 0.4), (0.2, -0.1, 0.01)), ((50.0, 30.0, -2.0), (-1.0, 0.3, -0.02)))
# A ramp-invariant network alone needs motion_gate false (on by default; the ramp rule refuses
# both); ramp_order is pinned (the default is 2) where a test means a line.


def random_network(params: PredictorParams, seed: int = 3) -> NnarmaxNet:
    """A network with random (not trained) weights and non-trivial standardization."""
    net = NnarmaxNet(network_spec(params), seed=seed)
    rng = np.random.default_rng(seed)
    net.set_standardization(rng.normal(1.0, 2.0, size=(300, 3)), rng.normal(size=(300, 3)))
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        assert net.bypass is not None
        net.bypass.weight.copy_(torch.randn(net.bypass.weight.shape, generator=generator,
                                            dtype=torch.float64))
        net.output.weight.copy_(torch.randn(net.output.weight.shape, generator=generator,
                                            dtype=torch.float64))
    return net


def ramp(offset: tuple[float, ...], velocity: tuple[float, ...], n: int = 40) -> FloatArray:
    """Positions offset + k·velocity, k = 0 … n − 1 (per sample)."""
    return np.asarray(offset) + np.arange(n, dtype=np.float64)[:, None] * np.asarray(velocity)


def parabola(offset: tuple[float, ...], velocity: tuple[float, ...],
             acceleration: tuple[float, ...], n: int = 41) -> FloatArray:
    """Positions offset + k·velocity + k²·acceleration / 2, k = 0 … n − 1 (per sample)."""
    k = np.arange(n, dtype=np.float64)[:, None]
    return (np.asarray(offset) + k * np.asarray(velocity)
            + 0.5 * k ** 2 * np.asarray(acceleration))


def test_slope_weights_return_a_ramps_slope() -> None:
    for ny in (2, 3, 24):
        weights = ramp_slope_weights(ny)
        lags = np.arange(ny)
        assert weights.sum() == pytest.approx(0.0, abs=1e-12)
        assert np.dot(weights, -lags) == pytest.approx(1.0, abs=1e-12)
    assert ramp_slope_weights(2) == pytest.approx([0.5 * 2, -0.5 * 2])  # v̂ = y(t) − y(t−1)
    with pytest.raises(ValueError, match='ny ≥ 2'):
        ramp_slope_weights(1)


@pytest.mark.parametrize('frame', ['earth', 'body'])
def test_a_ramp_is_predicted_up_to_one_constant(frame: str) -> None:
    net = random_network(PredictorParams(motion_gate=False, ramp_invariant=True, ramp_order=1,
                                         regressor_frame=frame))
    fast = NumpyNnarmax.from_module(net)
    forces = np.zeros((40, 3))
    residuals = []
    for offset, velocity in RAMPS:
        y = ramp(offset, velocity)
        if frame == 'body':  # the constant is a body-frame offset: same final heading
            y[:, 2] += 0.7 - y[-1, 2]
        prediction = predict_step(fast, forces, y, y)
        assert predict_step(net, forces, y, y) == pytest.approx(prediction, abs=1e-12)
        residuals.append(prediction - (y[-1] + np.asarray(velocity)))
    assert residuals[0] == pytest.approx(residuals[1], abs=1e-9)
    assert np.max(np.abs(residuals[0])) > 1e-3  # the random constant is there (not a 0 test)


def test_fit_weights_return_a_polynomials_coefficients() -> None:
    assert ramp_fit_weights(24, 1) == pytest.approx(ramp_slope_weights(24)[None, :], abs=1e-15)
    lags = np.arange(12, dtype=np.float64)
    y = 3.0 - 0.5 * lags + 0.02 * lags ** 2  # a₀ + a₁·(−i) + a₂·(−i)², newest first
    weights = ramp_fit_weights(12, 2)
    assert weights.shape == (2, 12)
    assert weights @ y == pytest.approx([0.5, 0.02], abs=1e-12)
    assert weights.sum(axis=1) == pytest.approx([0.0, 0.0], abs=1e-12)
    with pytest.raises(ValueError, match='ny ≥ 3'):
        ramp_fit_weights(2, 2)


@pytest.mark.parametrize('frame', ['earth', 'body'])
def test_a_parabola_is_predicted_up_to_one_constant_with_order_2(frame: str) -> None:
    net = random_network(PredictorParams(motion_gate=False, ramp_invariant=True, ramp_order=2,
                                         regressor_frame=frame))
    fast = NumpyNnarmax.from_module(net)
    forces = np.zeros((41, 3))
    cases = (((5.0, -3.0, 0.4), (0.2, -0.1, 0.01), (0.01, 0.02, -0.001)),
             ((50.0, 30.0, -2.0), (-1.0, 0.3, -0.02), (-0.03, 0.005, 0.002)))
    residuals = []
    for offset, velocity, acceleration in cases:
        y = parabola(offset, velocity, acceleration)
        if frame == 'body':
            y[:, 2] += 0.7 - y[-1, 2]
        next_value = parabola(offset, velocity, acceleration, n=42)[-1]
        next_value[2] += y[-1, 2] - parabola(offset, velocity, acceleration)[-1, 2]
        prediction = predict_step(fast, forces, y, y)
        assert predict_step(net, forces, y, y) == pytest.approx(prediction, abs=1e-12)
        residuals.append(prediction - next_value)
    assert residuals[0] == pytest.approx(residuals[1], abs=1e-8)
    assert np.max(np.abs(residuals[0])) > 1e-3
    line = random_network(PredictorParams(motion_gate=False, ramp_invariant=True, ramp_order=1,
                                          regressor_frame=frame))
    line_fast = NumpyNnarmax.from_module(line)
    y0, y1 = (parabola(*case) for case in cases)
    assert np.max(np.abs((predict_step(line_fast, forces, y0, y0) - y0[-1])
                         - (predict_step(line_fast, forces, y1, y1) - y1[-1]))) > 0.1


def test_without_the_option_a_ramp_is_not_followed() -> None:
    net = random_network(PredictorParams())
    fast = NumpyNnarmax.from_module(net)
    residuals = [predict_step(fast, np.zeros((40, 3)), ramp(o, v), ramp(o, v))
                 - (ramp(o, v)[-1] + np.asarray(v)) for o, v in RAMPS]
    assert np.max(np.abs(residuals[0] - residuals[1])) > 0.1


def test_spread_is_measured_from_the_line() -> None:
    y = ramp((1.0, 2.0, 0.3), (0.5, -0.2, 0.01), n=100)
    assert relative_spread(y, 24, ramp_invariant=True) == pytest.approx(np.zeros(3), abs=1e-9)
    assert relative_spread(y, 24)[0] > 1.0
    noise = np.random.default_rng(0).normal(size=(60, 3))
    noise[:, 2] = np.cumsum(noise[:, 2]) * 0.1
    ny = 5
    weights = ramp_slope_weights(ny)
    expected: list[FloatArray] = []
    for t in range(ny - 1, 60):
        lags = noise[t - np.arange(ny)]
        slope = weights @ lags
        offsets = lags[1:] - (lags[0] - np.arange(1, ny)[:, None] * slope)
        heading = lags[0, 2]
        expected.append(rotate_blocks(offsets.reshape(1, -1), np.full(1, np.cos(heading)),
                                      np.full(1, -np.sin(heading))).reshape(ny - 1, 3))
    rms = np.sqrt(np.mean(np.concatenate(expected) ** 2, axis=0))
    assert relative_spread(noise, ny, body_frame=True, ramp_invariant=True) == pytest.approx(
        rms, rel=1e-12)
    curve = parabola((1.0, 2.0, 0.3), (0.5, -0.2, 0.01), (0.01, -0.02, 0.001), n=100)
    assert relative_spread(curve, 24, ramp_invariant=True, ramp_order=2) == pytest.approx(
        np.zeros(3), abs=1e-9)
    assert relative_spread(curve, 24, ramp_invariant=True)[0] > 0.1


def test_rules() -> None:
    with pytest.raises(ValueError, match='ramp_invariant needs relative'):
        NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=4, nfb=1, hidden_units=2,
                    relative=True, ramp_invariant=True)
    with pytest.raises(ValueError, match='ramp_invariant needs relative'):
        NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=1, nfb=0, hidden_units=2,
                    relative=True, ramp_invariant=True)
    with pytest.raises(ValueError, match='ramp rule'):
        PredictorParams(motion_gate=False, ramp_invariant=True, nfb=2)
    spec = network_spec(PredictorParams(motion_gate=False, ramp_invariant=True, ramp_order=1))
    assert spec.to_dict()['ramp_invariant'] is True
    assert NnarmaxSpec.from_dict(spec.to_dict()) == spec
    assert 'ramp_invariant' not in network_spec(PredictorParams()).to_dict()
    assert 'ramp_order' not in spec.to_dict()
    # a plain network: the order changes nothing (both pinned: the default order is 2)
    assert network_spec(PredictorParams(ramp_order=2)) == \
        network_spec(PredictorParams(ramp_order=1))
    parabolic = network_spec(PredictorParams(motion_gate=False, ramp_invariant=True, ramp_order=2))
    assert parabolic.to_dict()['ramp_order'] == 2
    assert NnarmaxSpec.from_dict(parabolic.to_dict()) == parabolic
    with pytest.raises(ValueError, match='ramp_order must be one of'):
        PredictorParams(ramp_order=3)
    with pytest.raises(ValueError, match='needs at least 3, got 2'):
        PredictorParams(motion_gate=True, motion_gate_ny=2, ramp_order=2)
    with pytest.raises(ValueError, match='ramp_order 2 fits a polynomial'):
        NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=2, nfb=0, hidden_units=2,
                    relative=True, ramp_invariant=True, ramp_order=2)


def test_training_on_station_keeping_still_follows_a_ramp() -> None:
    """Trained on a window that never moves, the network still extrapolates a ramp (earth)."""
    params = PredictorParams(motion_gate=False, ramp_invariant=True, ramp_order=1, ny=12, nu=4)
    rng = np.random.default_rng(1)
    n = 400
    t = np.arange(n, dtype=np.float64)
    lf = np.cumsum(rng.normal(0.0, 0.01, size=(n, 3)), axis=0)
    waves = 0.5 * np.sin(0.8 * t)[:, None] * np.array([1.0, 0.7, 0.01])
    y = lf + waves
    u = rng.normal(size=(n, 3))
    net = NnarmaxNet(network_spec(params), seed=0)
    result = train(net, u, y, lf, None, train_settings(params))
    untrained = evaluate_loss(net, network_spec(params), u, y, lf, None, 'series_parallel')
    assert result.loss < 0.5 * untrained  # measured 0.297 against 1.058
    net.load_state_dict(result.state_dict)
    fast = NumpyNnarmax.from_module(net)
    residuals = [predict_step(fast, np.zeros((40, 3)), ramp(o, v), ramp(o, v))
                 - (ramp(o, v)[-1] + np.asarray(v)) for o, v in RAMPS]
    assert residuals[0] == pytest.approx(residuals[1], abs=1e-9)
