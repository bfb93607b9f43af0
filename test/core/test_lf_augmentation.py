"""LF-motion augmentation and thrust validation (issue 13): motion, window copy, gating."""
from __future__ import annotations

import functools

import numpy as np
import pytest
import torch

from lf_predictor_ros.core.augmentation import LF_MOTION_BAND, lf_motion, periodic_zero_phase
from lf_predictor_ros.core.network import (
    NnarmaxNet,
    NumpyNnarmax,
    predict_step,
    without_force_inputs,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import (
    Snapshot,
    network_spec,
    run_retraining,
    target_filter,
    thrust_predicts_motion,
    training_data,
    training_window,
)
from sim_ros.simulation import load_scenario, simulate

pytestmark = pytest.mark.filterwarnings(
    'ignore:`torch.jit.script` is deprecated:DeprecationWarning')


def test_lf_motion_has_the_rms_velocity_and_stays_below_the_dp_band() -> None:
    rng = np.random.default_rng(0)
    motion = lf_motion(2000, 1.0, np.array([0.1, 0.2, 0.0]), rng)
    velocity = np.sqrt(np.mean(np.diff(motion, axis=0) ** 2, axis=0))
    np.testing.assert_allclose(velocity, [0.1, 0.2, 0.0], rtol=1e-12, atol=1e-15)
    spectrum = np.abs(np.fft.rfft(motion[:, 0])) ** 2
    omega = 2.0 * np.pi * np.fft.rfftfreq(2000, d=1.0)
    assert spectrum[omega > LF_MOTION_BAND[1] + 1e-9].sum() < 1e-20 * spectrum.sum()
    with pytest.raises(ValueError, match='rms_velocity'):
        lf_motion(100, 1.0, np.array([-0.1]), rng)


@functools.cache
def _snapshot() -> Snapshot:
    record = simulate(load_scenario('onedof_excited'), 1, 1500.0)
    return Snapshot(u=np.array(record.thrust[:, :1]), y=np.array(record.measured_pose[:, :1]),
                    end_index=len(record.t) - 1, segment=1)


def test_lf_copy_adds_the_motion_to_positions_and_its_filtered_version_to_the_targets() -> None:
    params = PredictorParams(ndof=1, lf_augmentation=(0.1, 0.0, 0.0))
    snapshot = _snapshot()
    torch.set_num_threads(1)
    result = run_retraining(PredictorParams(ndof=1), snapshot, None, None, None)
    u, y, targets, mask = training_window(params, snapshot, result.targets)
    omega = result.frequency.wave_peak_freq
    u2, y2, t2, m2 = training_data(params, snapshot, u, y, targets, mask, np.ones(1), omega)
    n = len(y)
    assert y2.shape == (2 * n, 1)
    np.testing.assert_array_equal(u2, np.concatenate([u, u]))  # the thrust is not changed
    motion = y2[n:] - y
    velocity = np.sqrt(np.mean(np.diff(motion[:, 0]) ** 2))
    assert velocity == pytest.approx(0.1, rel=1e-9)
    expected = periodic_zero_phase(motion, target_filter(params, omega), params.sample_time)
    np.testing.assert_allclose(t2[n:] - targets, expected, atol=1e-12)
    # below the DP band the target filter passes the motion almost unchanged (notch ζ 0.8)
    assert np.sqrt(np.mean((expected - motion) ** 2)) < 0.1 * np.sqrt(np.mean(motion ** 2))
    assert not m2[n:n + params.max_lag + 1].any() and m2[:n].tolist() == mask.tolist()
    # off by default: the window is returned as it is
    plain = training_data(PredictorParams(ndof=1), snapshot, u, y, targets, mask, np.ones(1),
                          omega)
    assert plain[1] is y


def test_a_heading_entry_leaves_a_1dof_training_untouched() -> None:
    """The yaw entry of ``lf_augmentation`` does not exist on a 1-DOF vessel: same network."""
    snapshot = _snapshot()
    torch.set_num_threads(1)
    plain = run_retraining(PredictorParams(ndof=1), snapshot, None, None, None)
    heading = run_retraining(PredictorParams(ndof=1, lf_augmentation=(0.0, 0.0, 0.00025)),
                             snapshot, None, None, None)
    assert plain.accepted and heading.accepted
    assert heading.loss == plain.loss
    assert plain.state_dict is not None and heading.state_dict is not None
    for name, value in plain.state_dict.items():
        assert torch.equal(heading.state_dict[name], value), name
    # the north entry does act on the same vessel
    north = run_retraining(PredictorParams(ndof=1, lf_augmentation=(0.05, 0.0, 0.0)),
                           snapshot, None, None, None)
    assert north.state_dict is not None
    assert not all(torch.equal(north.state_dict[name], value)
                   for name, value in plain.state_dict.items())


@pytest.mark.parametrize('hidden_units', [0, 2])
def test_without_force_inputs_makes_the_output_independent_of_the_thrust(hidden_units: int,
                                                                         ) -> None:
    params = PredictorParams(hidden_units=hidden_units)
    spec = network_spec(params)
    net = NnarmaxNet(spec, seed=3)
    with torch.no_grad():
        if hidden_units:
            net.output.weight.normal_()  # a network that does use its tanh part
        else:
            net.bypass.weight.normal_(std=1e-3)  # a linear network that uses the thrust
    state = net.state_dict()
    before = {k: v.clone() for k, v in state.items()}
    gated = NumpyNnarmax.from_module(NnarmaxNet.from_state(spec, without_force_inputs(state,
                                                                                      spec)))
    rng = np.random.default_rng(1)
    y_hist, fb = rng.normal(size=(params.ny, 3)), np.zeros((1, 3))
    a = predict_step(gated, rng.normal(size=(params.nu, 3)) * 1e5, y_hist, fb)
    b = predict_step(gated, rng.normal(size=(params.nu, 3)) * 1e5, y_hist, fb)
    np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12)
    ungated = NumpyNnarmax.from_module(net)
    assert np.max(np.abs(predict_step(ungated, rng.normal(size=(params.nu, 3)) * 1e5, y_hist,
                                      fb) - a)) > 1e-3
    for name, value in state.items():
        assert torch.equal(value, before[name])  # the input state is not modified


def test_thrust_is_trusted_on_an_excited_vessel_and_not_when_it_is_unrelated() -> None:
    """onedof_excited: the thrust moves the vessel (trusted); a random thrust does not."""
    params = PredictorParams(ndof=1, thrust_validation=True)
    snapshot = _snapshot()
    torch.set_num_threads(1)
    result = run_retraining(PredictorParams(ndof=1), snapshot, None, None, None)
    u, _, targets, mask = training_window(params, snapshot, result.targets)
    assert thrust_predicts_motion(params, u, targets, mask)
    unrelated = np.random.default_rng(5).normal(size=u.shape) * np.std(u)
    assert not thrust_predicts_motion(params, unrelated, targets, mask)


def test_a_retraining_without_trusted_thrust_ignores_the_thrust() -> None:
    params = PredictorParams(ndof=1, thrust_validation=True)
    snapshot = _snapshot()
    scrambled = Snapshot(u=np.random.default_rng(5).normal(size=snapshot.u.shape) * 1e3,
                         y=snapshot.y, end_index=snapshot.end_index, segment=1)
    torch.set_num_threads(1)
    result = run_retraining(params, scrambled, None, None, None)
    assert not result.thrust_used and result.model is not None
    trusted = run_retraining(params, snapshot, None, None, None)
    assert trusted.thrust_used
    y_hist = snapshot.y[-params.ny:]
    a = predict_step(result.model, np.zeros((params.nu, 1)), y_hist, np.zeros((1, 1)))
    b = predict_step(result.model, np.full((params.nu, 1), 1e6), y_hist, np.zeros((1, 1)))
    np.testing.assert_array_equal(a, b)


def test_parameters_are_validated() -> None:
    with pytest.raises(ValueError, match='lf_augmentation must be three numbers'):
        PredictorParams(lf_augmentation=(0.1, 0.1))
    with pytest.raises(ValueError, match='lf_augmentation must be ≥ 0'):
        PredictorParams(lf_augmentation=(0.1, -0.1, 0.0))
    with pytest.raises(ValueError, match='thrust_validation must be true or false'):
        PredictorParams(thrust_validation=1)  # type: ignore[arg-type]
