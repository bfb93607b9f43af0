"""Tests for the notch + low-pass wave filter: design, zero-phase and streaming application."""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
import pytest
from scipy import signal

from lf_predictor_ros.core.filters import (
    CausalFilter,
    continuous_wave_filter,
    design_wave_filter,
    frequency_response,
    low_pass_step,
    plan_retune,
    settling_samples,
    zero_phase,
)

WAVE_FREQS = (0.3, 0.55, 0.8, 1.05, 1.3)  # [rad/s] thesis eq. 3.9 range
SAMPLE_TIMES = (0.1, 0.5)  # [s]


def _db(x: NDArray[np.complex128]) -> NDArray[np.float64]:
    return np.asarray(20.0 * np.log10(np.abs(x)), dtype=np.float64)


@pytest.mark.parametrize('sample_time', SAMPLE_TIMES)
@pytest.mark.parametrize('wave_peak_freq', WAVE_FREQS)
def test_attenuation_at_wave_peak_at_least_20_db(
    wave_peak_freq: float, sample_time: float
) -> None:
    sos = design_wave_filter(wave_peak_freq, sample_time)
    gain = _db(frequency_response(sos, np.array([wave_peak_freq]), sample_time))[0]
    assert gain <= -20.0
    # Default depth 0.05 is -26.0 dB from the notch alone; the low-pass only adds attenuation.
    assert gain <= 20.0 * np.log10(0.05) + 1e-6


@pytest.mark.parametrize('sample_time', SAMPLE_TIMES)
@pytest.mark.parametrize('wave_peak_freq', WAVE_FREQS)
def test_low_frequency_gain_error_below_half_db(wave_peak_freq: float, sample_time: float) -> None:
    sos = design_wave_filter(wave_peak_freq, sample_time)
    omega = np.linspace(0.0, 0.05, 51)  # [rad/s]
    gain = _db(frequency_response(sos, omega, sample_time))
    assert np.max(np.abs(gain)) <= 0.5
    assert abs(gain[0]) < 1e-9  # unity DC gain


@pytest.mark.parametrize('sample_time', (0.1, 0.5, 1.0))
def test_prewarped_notch_is_exactly_at_wave_peak(sample_time: float) -> None:
    wave_peak_freq = 1.2  # [rad/s]; ω0·T = 1.2 rad at T = 1 s: strong warping without pre-warp
    sos = design_wave_filter(wave_peak_freq, sample_time, notch_depth=0.0)
    response = frequency_response(sos, np.array([wave_peak_freq, 0.97 * wave_peak_freq]),
                                  sample_time)
    assert abs(response[0]) < 1e-9
    assert abs(response[1]) > 1e-3  # a notch, not a broad zero


def test_digital_matches_continuous_design_at_low_frequency() -> None:
    b, a = continuous_wave_filter(0.6)
    omega = np.array([0.01, 0.1, 0.3])
    _, analog = signal.freqs(b, a, worN=omega)
    digital = frequency_response(design_wave_filter(0.6, 0.1), omega, 0.1)
    np.testing.assert_allclose(np.abs(digital), np.abs(analog), rtol=2e-3)


def test_notch_depth_and_width_follow_the_definition() -> None:
    # Continuous gain at ω0 is ζ_z/ζ_p = depth times the low-pass gain there.
    b, a = continuous_wave_filter(0.5, notch_zeta=0.3, notch_depth=0.1, lowpass_offset=0.2)
    _, h = signal.freqs(b, a, worN=np.array([0.5]))
    lowpass = 1.0 / np.sqrt(1.0 + (0.5 / 0.7) ** 4)  # Butterworth |h_lp(jω)|
    assert abs(h[0]) == pytest.approx(0.1 * lowpass, rel=1e-9)


@pytest.mark.parametrize(
    ('kwargs', 'rule'),
    [
        ({'wave_peak_freq': 7.0, 'sample_time': 0.5}, 'π/sample_time'),
        ({'wave_peak_freq': 0.0, 'sample_time': 0.5}, 'wave_peak_freq'),
        ({'wave_peak_freq': 0.5, 'sample_time': -0.1}, 'sample_time'),
        ({'wave_peak_freq': 0.5, 'sample_time': 0.1, 'notch_depth': 1.0}, 'notch_depth'),
        ({'wave_peak_freq': 0.5, 'sample_time': 0.1, 'notch_zeta': 0.0}, 'notch_zeta'),
        ({'wave_peak_freq': 0.5, 'sample_time': 0.1, 'lowpass_offset': -0.2}, 'lowpass_offset'),
    ],
)
def test_invalid_design_raises(kwargs: dict[str, float], rule: str) -> None:
    with pytest.raises(ValueError, match=rule):
        design_wave_filter(**kwargs)


def test_zero_phase_has_no_phase_shift_at_low_frequency() -> None:
    dt = 0.1  # [s]
    omega = 0.03  # [rad/s], LF band
    periods = 6
    t = np.arange(int(round(periods * 2.0 * np.pi / omega / dt))) * dt
    y = np.sin(omega * t)
    sos = design_wave_filter(0.5, dt)
    out = zero_phase(y, sos)
    # Phase by projection onto sin/cos over whole periods away from the edges.
    inner = slice(len(t) // 6, len(t) - len(t) // 6)
    sin_part = 2.0 * np.mean(out[inner] * np.sin(omega * t[inner]))
    cos_part = 2.0 * np.mean(out[inner] * np.cos(omega * t[inner]))
    phase = np.arctan2(cos_part, sin_part)
    # Same projection on the causal output measures a real phase lag (the test can fail).
    causal = signal.sosfilt(sos, y, zi=signal.sosfilt_zi(sos) * y[0])[0]
    causal_phase = np.arctan2(2.0 * np.mean(causal[inner] * np.cos(omega * t[inner])),
                              2.0 * np.mean(causal[inner] * np.sin(omega * t[inner])))
    assert abs(phase) < 1e-3
    assert causal_phase < -0.02
    gain = abs(frequency_response(sos, np.array([omega]), dt)[0]) ** 2
    assert np.hypot(sin_part, cos_part) == pytest.approx(gain, rel=2e-3)


def test_zero_phase_keeps_constants_shape_and_input() -> None:
    sos = design_wave_filter(0.8, 0.1)
    y = np.tile(np.array([3.0, -2.0, 0.5]), (500, 1))
    before = y.copy()
    out = zero_phase(y, sos)
    assert out.shape == y.shape
    np.testing.assert_allclose(out, y, atol=1e-9)
    np.testing.assert_array_equal(y, before)
    with pytest.raises(ValueError, match='NaN'):
        zero_phase(np.array([1.0, np.nan, 2.0]), sos)


def _drift_plus_wave(
    rng: np.random.Generator, n: int, dt: float, wave_peak_freq: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """LF: 2nd-order low-passed noise (0.05 rad/s, σ 1 m); WF: 2nd-order wave model (σ 0.7 m)."""
    lf_b, lf_a = signal.bilinear([0.05**2], [1.0, 2 * 0.7 * 0.05, 0.05**2], 1.0 / dt)
    lf = signal.lfilter(lf_b, lf_a, rng.normal(size=n + 5000))[5000:]
    wf_b, wf_a = signal.bilinear([2 * 0.1 * wave_peak_freq, 0.0],
                                 [1.0, 2 * 0.1 * wave_peak_freq, wave_peak_freq**2], 1.0 / dt)
    wave = signal.lfilter(wf_b, wf_a, rng.normal(size=n + 2000))[2000:]
    return lf / np.std(lf), 0.7 * wave / np.std(wave)


def test_zero_phase_edge_transients_smaller_than_long_odd_padding() -> None:
    # The choice documented in zero_phase: Gustafsson's initial conditions vs odd reflection
    # padded over one settling time. Seeded drift + wave series, error over the last/first 10 s.
    dt, n = 0.1, 2000
    rng = np.random.default_rng(20180601)
    ours: list[float] = []
    padded: list[float] = []
    for wave_peak_freq in (0.3, 0.8, 1.3):
        sos = design_wave_filter(wave_peak_freq, dt)
        for _ in range(10):
            lf, wave = _drift_plus_wave(rng, n, dt, wave_peak_freq)
            y = lf + wave
            alt = signal.sosfiltfilt(sos, y, padtype='odd', padlen=settling_samples(sos))
            for store, est in ((ours, zero_phase(y, sos)), (padded, alt)):
                err = est - lf
                store.append(float(np.mean(np.concatenate([err[:100], err[-100:]]) ** 2)))
    ours_rms, padded_rms = np.sqrt(np.mean(ours)), np.sqrt(np.mean(padded))
    assert ours_rms < 0.8 * padded_rms
    assert ours_rms < 0.3  # [m] edge error for σ_LF 1 m, σ_WF 0.7 m


def test_causal_filter_equals_sosfilt_with_steady_state_init() -> None:
    rng = np.random.default_rng(7)
    dt = 0.2
    sos = design_wave_filter(0.7, dt)
    y = np.cumsum(rng.normal(size=(400, 3)), axis=0) + 5.0
    zi = signal.sosfilt_zi(sos)[:, :, None] * y[0][None, None, :]
    expected, _ = signal.sosfilt(sos, y, axis=0, zi=zi)
    filt = CausalFilter(sos, 3)
    out = np.array([filt.filter(sample) for sample in y])
    np.testing.assert_allclose(out, expected, rtol=0.0, atol=1e-12)


def test_filter_values_gives_filters_numbers_bit_for_bit_through_a_retune() -> None:
    rng = np.random.default_rng(8)
    y = np.cumsum(rng.normal(size=(300, 3)), axis=0) + 5.0
    arrays, floats = (CausalFilter(design_wave_filter(0.7, 0.2), 3) for _ in range(2))
    for k, sample in enumerate(y):
        if k == 150:  # the state fitted to the I/O history the floats path remembered
            arrays.retune(design_wave_filter(0.9, 0.2))
            floats.retune(design_wave_filter(0.9, 0.2))
        values = sample.tolist()
        out = floats.filter_values(values)
        assert arrays.filter(sample).tolist() == out  # bit for bit
        assert values == sample.tolist()  # the input list is not changed
        out[0] = math.nan  # the caller's list: the filter's state keeps no reference to it
    assert math.isfinite(floats.filter_values([1.0, 2.0, 3.0])[0])
    with pytest.raises(ValueError, match='shape'):
        floats.filter_values([1.0, 2.0])


def test_a_retune_plan_gives_the_retune_of_the_coefficients_bit_for_bit() -> None:
    rng = np.random.default_rng(9)
    y = np.cumsum(rng.normal(size=(200, 3)), axis=0) + 5.0
    plain, planned = (CausalFilter(design_wave_filter(0.7, 1.0), 3) for _ in range(2))
    new = design_wave_filter(0.55, 1.0, notch_zeta=0.1)
    plan = plan_retune(new)
    for k, sample in enumerate(y):
        if k in (2, 120):  # before the I/O history is long enough (steady state) and after
            plain.retune(new)
            planned.retune(plan)
        assert planned.filter(sample).tolist() == plain.filter(sample).tolist()
    np.testing.assert_array_equal(planned.sos, new)
    assert len(plan.markov) == 2 * new.shape[0] - 1
    assert not plan.observability.flags.writeable and not plan.sos.flags.writeable
    with pytest.raises(ValueError, match='normalized'):
        plan_retune(2.0 * new)


def test_a_restart_and_a_planned_retune_compute_no_steady_state(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``sosfilt_zi`` once per set of coefficients, never at a restart or after a plan."""
    calls: list[int] = []
    zi = signal.sosfilt_zi

    def counted(sos: NDArray[np.float64]) -> NDArray[np.float64]:
        calls.append(1)
        return zi(sos)

    new = design_wave_filter(0.55, 1.0, notch_zeta=0.1)
    plan = plan_retune(new)
    monkeypatch.setattr(signal, 'sosfilt_zi', counted)
    filt = CausalFilter(design_wave_filter(0.7, 1.0), 2)
    sample = np.array([3.0, -1.0])
    first = filt.filter(sample)
    assert len(calls) == 1
    filt.reset()
    assert filt.filter(sample).tolist() == first.tolist()  # the same start, not computed again
    assert len(calls) == 1
    filt.retune(plan)  # too short a history: starts in the plan's steady state
    filt.reset()
    after_restart = filt.filter(sample)
    assert len(calls) == 1
    fresh = CausalFilter(new, 2)
    assert after_restart.tolist() == fresh.filter(sample).tolist()  # equal to a new filter
    assert len(calls) == 2  # the new filter's own
    filt.retune(new)  # unplanned: computed once more at the next start
    filt.reset()
    filt.filter(sample)
    assert len(calls) == 3
    assert not plan.steady_state.flags.writeable


def test_causal_filter_starts_without_jump_and_resets() -> None:
    filt = CausalFilter(design_wave_filter(0.5, 0.1), 2)
    outs = np.array([filt.filter(np.array([12.5, -3.0])) for _ in range(50)])
    np.testing.assert_allclose(outs, np.tile([12.5, -3.0], (50, 1)), atol=1e-10)
    filt.reset()
    assert not filt.initialized
    np.testing.assert_allclose(filt.filter(np.array([1.0, 2.0])), [1.0, 2.0], atol=1e-12)
    with pytest.raises(ValueError, match='shape'):
        filt.filter(np.zeros(3))


def test_retune_keeps_output_continuous() -> None:
    dt, n, switch = 0.1, 2000, 1000
    t = np.arange(n) * dt
    y = 5.0 * np.sin(0.05 * t) + 0.3 * np.sin(0.5 * t)
    old, new = design_wave_filter(0.5, dt), design_wave_filter(0.9, dt)
    filt = CausalFilter(old, 1)
    out = []
    for k in range(n):
        if k == switch:
            filt.retune(new)
        out.append(filt.filter(y[k : k + 1])[0])
    step = np.abs(np.diff(out))
    typical = step[switch - 100 : switch - 1].max()
    # Naive switch: keep the old section states with the new coefficients.
    zi = signal.sosfilt_zi(old) * y[0]
    _, state = signal.sosfilt(old, y[:switch], zi=zi)
    naive, _ = signal.sosfilt(new, y[switch:], zi=state)
    naive_jump = np.abs(np.diff(naive[:10])).max()
    assert step[switch - 1 : switch + 10].max() <= 1.0 * typical
    assert naive_jump > 20.0 * typical
    np.testing.assert_array_equal(filt.sos, new)


def test_settling_samples_of_a_single_pole() -> None:
    sos = np.array([[0.5, 0.0, 0.0, 1.0, -0.5, 0.0]])  # pole at z = 0.5
    assert settling_samples(sos, tolerance=1e-3) == 10  # 0.5^10 ≈ 9.8e-4


def test_low_pass_step_moves_each_entry_by_its_weight_and_keeps_the_state() -> None:
    state = np.array([1.0, -2.0, 0.5])
    out = low_pass_step(state, [3.0, 2.0, 0.5], 0.25)
    np.testing.assert_array_equal(out, [1.5, -1.0, 0.5])  # 1 + 0.25·2, −2 + 0.25·4, unchanged
    np.testing.assert_array_equal(low_pass_step(state, [3.0, 2.0, 0.5], [0.0, 1.0, 0.5]),
                                  [1.0, 2.0, 0.5])  # weight 0 keeps, 1 takes the value
    np.testing.assert_array_equal(state, [1.0, -2.0, 0.5])  # the input is not modified
    with pytest.raises(ValueError):
        low_pass_step(state, [1.0, 2.0], 0.5)  # entries must match
