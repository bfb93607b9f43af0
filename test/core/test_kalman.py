"""Tests of the Kalman filter machinery and the oracle estimator (analytic answers)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lf_predictor_ros.core.baselines.kalman import (
    GaussMarkov,
    KalmanEstimator,
    OracleModel,
    kf_correct,
    kf_predict,
    steady_state_gain,
    van_loan,
)
from lf_predictor_ros.core.estimator import LfEstimator


def test_van_loan_gauss_markov_closed_form() -> None:
    # ḃ = −b/T + w, E[w w] = 2σ²/T: Φ = e^{−h/T}, Q_d = σ²(1 − Φ²)
    tau, sigma, h = 60.0, 2.0, 0.7
    phi, qd = van_loan(np.array([[-1.0 / tau]]), np.array([[2.0 * sigma**2 / tau]]), h)
    assert phi[0, 0] == pytest.approx(math.exp(-h / tau), rel=1e-12)
    assert qd[0, 0] == pytest.approx(sigma**2 * (1.0 - math.exp(-2.0 * h / tau)), rel=1e-10)


def test_van_loan_double_integrator_closed_form() -> None:
    # ẍ = w, intensity q: Q_d = q [[h³/3, h²/2], [h²/2, h]] (Brown & Hwang 2012 §3.9)
    q, h = 0.3, 2.0
    phi, qd = van_loan(np.array([[0.0, 1.0], [0.0, 0.0]]), np.diag([0.0, q]), h)
    np.testing.assert_allclose(phi, [[1.0, h], [0.0, 1.0]], atol=1e-14)
    np.testing.assert_allclose(qd, q * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]]),
                               rtol=1e-10)


def test_constant_with_white_noise_is_the_sample_mean() -> None:
    # x constant, y_k = x + v_k; with a diffuse prior the KF estimate is the running mean
    rng = np.random.default_rng(4)
    y = 3.0 + 0.5 * rng.standard_normal(200)
    x, p = np.zeros(1), np.array([[1e12]])
    h, r = np.eye(1), np.array([[0.25]])
    for k, value in enumerate(y):
        x, p = kf_predict(x, p, np.eye(1), np.zeros((1, 1)))
        x, p, _ = kf_correct(x, p, np.array([value]) - h @ x, h, r)
        assert x[0] == pytest.approx(float(np.mean(y[: k + 1])), abs=1e-9)
    assert p[0, 0] == pytest.approx(0.25 / len(y), rel=1e-6)


def test_gain_converges_to_the_dare_solution() -> None:
    # random walk + noise: scalar DARE P = P − P²/(P + r) + q ⇒ P = (q + √(q² + 4qr))/2
    q, r = 0.01, 1.0
    phi, h = np.eye(1), np.eye(1)
    p_inf, gain = steady_state_gain(phi, h, np.array([[q]]), np.array([[r]]))
    expected = (q + math.sqrt(q * q + 4.0 * q * r)) / 2.0
    assert p_inf[0, 0] == pytest.approx(expected, rel=1e-10)
    x, p = np.zeros(1), np.array([[100.0]])
    k_last = np.zeros((1, 1))
    for _ in range(500):
        x, p = kf_predict(x, p, phi, np.array([[q]]))
        x, p, k_last = kf_correct(x, p, np.zeros(1), h, np.array([[r]]))
    assert k_last[0, 0] == pytest.approx(gain[0, 0], rel=1e-9)


def test_kf_correct_does_not_modify_inputs() -> None:
    x, p = np.array([1.0, 2.0]), np.eye(2)
    h, r, eps = np.array([[1.0, 0.0]]), np.array([[0.5]]), np.array([0.3])
    copies = [a.copy() for a in (x, p, h, r, eps)]
    kf_correct(x, p, eps, h, r)
    for original, copy in zip((x, p, h, r, eps), copies, strict=True):
        np.testing.assert_array_equal(original, copy)


def _linear_model(**overrides: object) -> OracleModel:
    values: dict[str, object] = {
        'ndof': 3, 'sample_time': 1.0, 'sensor_period': 0.1,
        'mass': np.diag([6.0e6, 1.0e7, 4.0e9]), 'damping': np.diag([7.0e4, 2.5e5, 3.8e8]),
        'wave_model': 'motion', 'wave_sigma': (1.0, 1.0, 0.03), 'wave_peak_freq': 0.8,
        'force_biases': (GaussMarkov((1e4, 1e4, 1e5), (1e4, 1e4, 1e5), 300.0),),
        'position_std': 0.1, 'heading_std': 0.001,
    }
    values.update(overrides)
    return OracleModel(**values)  # type: ignore[arg-type]


def test_estimator_protocol_status_and_reset() -> None:
    est = KalmanEstimator(_linear_model())
    assert isinstance(est, LfEstimator)
    assert est.status().state == 'warming_up'
    out = est.update(1.0, np.array([1.0, 2.0, 3.1]), np.zeros(3))
    np.testing.assert_allclose(out[:2], [1.0, 2.0], atol=0.5)
    assert est.status().state == 'ok'
    est.reset()
    assert est.status().state == 'warming_up'
    assert np.all(np.isnan(est.estimate()))


def test_heading_wrap_and_nan_input() -> None:
    est = KalmanEstimator(_linear_model())
    pose = np.array([0.0, 0.0, math.pi - 0.001])
    force = np.zeros(3)
    pose_copy, force_copy = pose.copy(), force.copy()
    for k in range(30):
        heading = math.remainder(math.pi - 0.001 + 0.0005 * k, 2.0 * math.pi)
        out = est.update(float(k + 1), np.array([0.0, 0.0, heading]), force)
        assert -math.pi < out[2] <= math.pi
        assert abs(math.remainder(out[2] - heading, 2.0 * math.pi)) < 0.01
    np.testing.assert_array_equal(pose, pose_copy)
    np.testing.assert_array_equal(force, force_copy)
    before = est.lf_std.copy()
    out = est.update(31.0, np.array([math.nan, 0.0, 0.0]), np.array([math.nan, 0.0, 0.0]))
    assert np.all(np.isfinite(out)) and est.skipped_measurements == 1
    assert est.lf_std[0] > before[0]  # prediction only: the uncertainty grows


def test_one_dof_components_beyond_ndof_are_zero() -> None:
    model = OracleModel(ndof=1, sample_time=1.0, sensor_period=1.0, mass=np.eye(3) * 1471.0,
                        damping=np.zeros((3, 3)), quad_damping=(-0.017, 0.0, 0.0),
                        wave_operating_speed=(0.1, 0.1, 0.02), wave_model='force',
                        wave_sigma=(85.0, 0.0, 0.0), position_std=0.05, input_hold='last')
    est = KalmanEstimator(model)
    out = est.update(1.0, np.array([2.0, 7.0, 1.0]), np.array([5.0, 1.0, 1.0]))
    assert out[1] == 0.0 and out[2] == 0.0


def test_model_validation_messages() -> None:
    with pytest.raises(ValueError, match='wave_model'):
        _linear_model(wave_model='rao')
    with pytest.raises(ValueError, match='sensor_period'):
        _linear_model(sensor_period=2.0)
    with pytest.raises(ValueError, match='quad_damping'):
        _linear_model(quad_damping=(0.1, 0.0, 0.0))


def test_consistent_on_its_own_linear_model() -> None:
    # truth drawn from the filter's own model (motion waves, bias, 1-DOF linear vessel, exact
    # discretization at the sensor period): realized RMSE within 30 % of the predicted std
    model = OracleModel(ndof=1, sample_time=1.0, sensor_period=0.25, mass=np.eye(3) * 1e6,
                        damping=np.eye(3) * 2e4, wave_model='motion', wave_sigma=(1.0, 0, 0),
                        wave_peak_freq=0.8,
                        force_biases=(GaussMarkov((0.0, 0.0, 0.0), (5e3, 0.0, 0.0), 100.0),),
                        position_std=0.1)
    est = KalmanEstimator(model)
    rng = np.random.default_rng(3)
    lay = est._lay  # noqa: SLF001 - the test draws the truth in the filter's state layout
    core = lay.core
    x = np.zeros(core)
    x[:lay.eta.start] = np.linalg.cholesky(est._prior_covariance(0.0)[:2, :2]) @ (  # noqa: SLF001
        rng.standard_normal(2))
    jac = np.zeros((core, core))
    for i in range(core):
        e = np.zeros(core)
        e[i] = 1.0
        jac[:, i] = est.rates(e, np.zeros(1)) - est.rates(np.zeros(core), np.zeros(1))
    phi, qd = van_loan(jac, est._noise_intensity(), 0.25)  # noqa: SLF001
    chol = np.linalg.cholesky(qd + 1e-18 * np.eye(core))
    h = est._h_total  # noqa: SLF001
    errors, stds = [], []
    for k in range(700):
        poses = []
        for _ in range(4):
            x = phi @ x + chol @ rng.standard_normal(core)
            poses.append(float((h @ x)[0]) + 0.1 * rng.standard_normal())
        out = est.update(float(k + 1), np.array([np.mean(poses), 0.0, 0.0]), np.zeros(3))
        if k >= 100:
            errors.append(out[0] - x[lay.eta][0])
            stds.append(est.lf_std[0])
    realized = math.sqrt(float(np.mean(np.square(errors))))
    predicted = math.sqrt(float(np.mean(np.square(stds))))
    assert realized == pytest.approx(predicted, rel=0.3)
