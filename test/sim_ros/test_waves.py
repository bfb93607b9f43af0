"""Shaping filters: PSD peak and variance of the exactly discretized wave processes.

The analytic variance is C P Cᵀ with P from the continuous Lyapunov equation; the sampled
process must match it (and its PSD peak must sit at ω0) for two different step sizes, because
the discretization is exact (Van Loan) with continuous-time noise intensity.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from sim_ros.physics import schedule, waves

PEAK_FREQ = 0.8  # rad/s
DAMPING = 0.1  # λ
# s per DOF, three independent DOFs pooled; the narrower-band force process needs more data
# for the same relative error of the variance (≈ 1.3 % std at these lengths, so 5 % is ≈ 4σ)
DURATION = {'motion': 30000.0, 'force': 60000.0}


def _series(model: str, step: float, seed: int) -> np.ndarray:
    gen = waves.WaveGenerator(model, DAMPING, np.ones(3), schedule.constant(PEAK_FREQ), step,
                              np.random.default_rng(seed))
    out, peak = gen.next_block(int(DURATION[model] / step))
    assert np.all(peak == PEAK_FREQ)
    return out


def _analytic_peak(model: str) -> float:
    omega = np.linspace(0.3, 1.5, 120001)
    num, den = scipy.signal.ss2tf(*_abcd(model))
    _, resp = scipy.signal.freqs(num[0], den, worN=omega)
    return float(omega[np.argmax(np.abs(resp))])


def _abcd(model: str) -> tuple[np.ndarray, ...]:
    f = waves.make_filter(model, PEAK_FREQ, DAMPING)
    return f.a, f.g, f.c, np.zeros((1, 1))


@pytest.mark.parametrize('model', ['motion', 'force'])
@pytest.mark.parametrize('step', [0.05, 0.2])
def test_variance_and_psd_peak_independent_of_step(model: str, step: float) -> None:
    """Variance within 5 % of C P Cᵀ, PSD peak within 3 % of ω0, at dt = 0.05 s and 0.2 s."""
    series = _series(model, step, seed=11 if step < 0.1 else 12)
    expected = waves.analytic_variance(model, PEAK_FREQ, DAMPING, 1.0)
    assert series.var(axis=0).mean() == pytest.approx(expected, rel=0.05)
    seg = int(round(409.6 / step))  # Δω = 2π/409.6 s ≈ 0.015 rad/s
    freq, psd = scipy.signal.welch(series, fs=1.0 / step, nperseg=seg, axis=0)
    omega = 2 * np.pi * freq
    smooth = np.convolve(psd.mean(axis=1), np.ones(5) / 5, mode='same')
    peak = omega[np.argmax(smooth)]
    assert peak == pytest.approx(PEAK_FREQ, rel=0.03)
    # the one-sided PSD integrates to the variance as well
    assert np.trapezoid(psd.mean(axis=1), freq) == pytest.approx(expected, rel=0.06)


def test_analytic_values() -> None:
    """Closed forms: motion variance λω0σ²; force peak of |H_HO| within 3 % of ω0."""
    assert waves.analytic_variance('motion', 0.8, 0.1, 2.0) == pytest.approx(0.1 * 0.8 * 4.0)
    assert _analytic_peak('motion') == pytest.approx(PEAK_FREQ, abs=1e-4)
    assert _analytic_peak('force') == pytest.approx(PEAK_FREQ, rel=0.03)
    # |H_HO(jω0)| = K_ω ω0² / (2λω0²)³ = σ / (4 λ² ω0)  (eq. 5.2-5.3)
    f = waves.force_filter(0.8, 0.1, 3.0)
    s = 1j * 0.8
    resp = (f.c @ np.linalg.solve(s * np.eye(6) - f.a, f.g))[0, 0]
    assert abs(resp) == pytest.approx(3.0 / (4 * 0.1**2 * 0.8), rel=1e-9)


def test_van_loan_matches_covariance_propagation() -> None:
    """Ad P Adᵀ + Qd = P for the stationary P (exact discretization keeps P invariant)."""
    for model in ('motion', 'force'):
        for step in (0.05, 0.2, 1.0):
            disc = waves.discretize(model, 0.6, 0.1, step)
            p = disc.stationary_cov
            q = disc.noise_factor @ disc.noise_factor.T
            np.testing.assert_allclose(disc.ad @ p @ disc.ad.T + q, p, rtol=1e-7,
                                       atol=1e-9 * np.abs(p).max())


def test_schedule_changes_discretization_and_is_cached() -> None:
    """ω0 follows a step schedule; each rounded ω0 is discretized once."""
    sched = schedule.steps(1.25, [(100.0, 0.3)])
    gen = waves.WaveGenerator('motion', 0.1, np.ones(3), sched, 0.5, np.random.default_rng(1))
    waves.discretize.cache_clear()
    _, peak = gen.next_block(400)
    assert peak[0] == 1.25 and peak[199] == 1.25 and peak[200] == 0.3 and peak[-1] == 0.3
    info = waves.discretize.cache_info()
    assert info.misses == 2


def test_fig_4_1_schedule() -> None:
    """1.25 → 0.3 → 1.25 rad/s over 480 min."""
    sched = schedule.thesis_fig_4_1()
    assert sched(0.0) == 1.25 and sched(240 * 60.0) == 0.3 and sched(480 * 60.0) == 1.25
    assert sched(120 * 60.0) == pytest.approx(0.775)
    with pytest.raises(ValueError, match='non-decreasing'):
        schedule.table([[10.0, 1.0], [5.0, 1.0]])
    with pytest.raises(ValueError, match='rad/s'):
        schedule.constant(20.0)


@pytest.mark.parametrize(('before', 'after'), [(0.3, 1.25), (1.25, 0.3)])
def test_force_after_an_omega_step_has_the_new_sea_state_level(before: float,
                                                               after: float) -> None:
    """No transient at a step of ω0: the force right after it has the new stationary std.

    Keeping the raw state (states scale like ω0⁻⁶) gave a force ≈ 10³ × too large for several
    wave periods after 0.3 → 1.25 rad/s.
    """
    step, t_step = 0.05, 600.0  # s
    sched = schedule.steps(before, [(t_step, after)])
    gen = waves.WaveGenerator('force', DAMPING, np.ones(3), sched, step,
                              np.random.default_rng(5))
    out, _ = gen.next_block(int((t_step + 60.0) / step))
    right_after = out[int(t_step / step):]  # the 60 s after the step, 3 DOFs
    expected = np.sqrt(waves.analytic_variance('force', after, DAMPING, 1.0))
    ratio = float(right_after.std() / expected)
    assert 0.3 < ratio < 3.0


def test_rescale_state_maps_one_stationary_covariance_onto_the_other() -> None:
    """x_new = L_new L_old⁻¹ x_old turns Cov = P_old into Cov = P_new exactly."""
    old = waves.discretize('force', 0.3, DAMPING, 0.05)
    new = waves.discretize('force', 1.25, DAMPING, 0.05)
    basis = np.eye(6)
    transform = waves.rescale_state(basis, old, new).T  # column j is the image of e_j
    mapped = transform @ old.stationary_cov @ transform.T
    np.testing.assert_allclose(mapped, new.stationary_cov, rtol=1e-6,
                               atol=1e-9 * np.abs(new.stationary_cov).max())
    state = np.arange(18.0).reshape(3, 6)
    copy = state.copy()
    waves.rescale_state(state, old, new)
    np.testing.assert_array_equal(state, copy)  # pure


def test_force_impulses_are_the_integral_of_the_output() -> None:
    """Each step's impulse is ∫τ dt: matches a fine trapezoid of the output, σ included.

    1000 steps of 1 ms summed in 100-step chunks; the trapezoid at 1 ms errs by O(h²)·τ̈
    (≈ 1e-7 relative here), the tolerance is 1e-5 of the chunk impulses' scale.
    """
    sigma = np.array([85.0, 40.0, 2.2])
    gen = waves.WaveGenerator('force', DAMPING, sigma, schedule.constant(PEAK_FREQ), 0.001,
                              np.random.default_rng(3))
    start = gen.output.copy()
    out, impulses, _ = gen.next_block_with_impulses(1000)
    samples = np.vstack([start[None, :], out])
    chunks = [np.trapezoid(samples[k:k + 101], dx=0.001, axis=0) for k in range(0, 1000, 100)]
    summed = impulses.reshape(10, 100, 3).sum(axis=1)
    scale = np.abs(summed).max(axis=0)
    np.testing.assert_allclose(summed, np.array(chunks), atol=1e-5 * scale.max(), rtol=0)
    assert np.all(scale > 0)
    # the motion model has no antiderivative state: zero impulses
    motion = waves.WaveGenerator('motion', DAMPING, np.ones(3), schedule.constant(PEAK_FREQ),
                                 0.1, np.random.default_rng(3))
    assert np.all(motion.next_block_with_impulses(10)[1] == 0.0)
