"""PredictorParams: defaults, sample counts, every rule of Algorithm 4.1 and conversions."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from lf_predictor_ros.core.params import PredictorParams

# A legal tiny configuration used to reach the "N long enough for the regressors" rule:
# h = 0.5 s, Δ = 2, ε = 2, α = 8, β = 4 samples satisfy eqs. 4.4/4.5. nfb 2 needs the motion
# gate (default on) off: the ramp rule refuses LF feedback with it.
_TINY = {'sample_time': 0.5, 'nu': 2, 'ny': 2, 'nfb': 2, 'retrain_period': 1.0,
         'transient_length': 1.0, 'filter_window': 4.0, 'append_length': 2.0,
         'max_train_seconds': 0.5, 'motion_gate': False}

# (changes, regex the message must contain): each breaks exactly one rule of the defaults
# (h = 1 s, Δ = 60 s, ε = 30 s, α = 180 s, β = 120 s, N = 600 s, γ = 1200 s).
RULE_CASES: list[tuple[str, dict[str, Any], str]] = [
    ('ndof', {'ndof': 2}, r'ndof rule.*got 2'),
    ('sample_time zero', {'sample_time': 0.0}, r'positivity rule: sample_time must be > 0'),
    ('sample_time negative', {'sample_time': -0.1}, r'sample_time must be > 0, got -0\.1'),
    ('retrain_period', {'retrain_period': 0.0}, r'retrain_period must be > 0'),
    ('transient_length', {'transient_length': -1.0}, r'transient_length must be > 0'),
    ('estimation_window', {'estimation_window': -5.0}, r'estimation_window must be > 0'),
    ('highpass_cutoff', {'highpass_cutoff': 0.0}, r'highpass_cutoff must be > 0'),
    ('notch_zeta', {'notch_zeta': 0.0}, r'notch_zeta must be > 0'),
    ('notch_lower_edge', {'notch_lower_edge': -0.1}, r'notch_lower_edge must be ≥ 0'),
    ('notch_broadband_holding_only', {'notch_broadband_holding_only': 1},
     r'notch_broadband_holding_only must be true or false'),
    ('notch_zeta_broadband', {'notch_zeta_broadband': -1.0},
     r'notch_zeta_broadband must be ≥ 0'),
    ('output_notch_zeta', {'output_notch_zeta': -0.5}, r'output_notch_zeta must be ≥ 0'),
    ('lowpass_offset', {'lowpass_offset': -0.2}, r'lowpass_offset must be > 0'),
    ('max_train_seconds', {'max_train_seconds': 0.0}, r'max_train_seconds must be > 0'),
    ('weight_decay', {'weight_decay': -1e-3}, r'weight_decay must be ≥ 0'),
    ('derivative_weight', {'derivative_weight': -0.1}, r'derivative_weight must be ≥ 0'),
    ('nu', {'nu': -1}, r'nu must be ≥ 0'),
    ('ny+nfb', {'ny': 0, 'nfb': 0}, r'regressor rule: ny \+ nfb must be ≥ 1'),
    ('hidden_units', {'hidden_units': -1}, r'hidden_units must be ≥ 0 \(0: the linear network'),
    ('hidden_layers', {'hidden_layers': 0}, r'hidden_layers must be ≥ 1'),
    ('thrust_ridge_validation', {'thrust_ridge_validation': True, 'hidden_units': 2},
     r'thrust_ridge_validation needs the linear network \(hidden_units 0, got 2\)'),
    ('thrust_prior negative', {'thrust_prior': -0.01}, r'thrust_prior must be a finite number'),
    ('thrust_prior nan', {'thrust_prior': math.nan}, r'thrust_prior must be finite'),
    ('thrust_prior with the grid', {'thrust_prior': 0.01, 'thrust_ridge_validation': True},
     r'thrust_prior and thrust_ridge_validation'),
    ('thrust_hold tanh', {'thrust_hold': True, 'hidden_units': 2},
     r'thrust_hold needs the linear network solved by least squares'),
    ('thrust_hold derivative', {'thrust_hold': True, 'derivative_weight': 0.1},
     r'thrust_hold needs the linear network'),
    ('thrust_hold with the test', {'thrust_hold': True, 'thrust_validation': True},
     r'thrust_hold and thrust_validation both decide'),
    ('thrust_hold with the grid', {'thrust_hold': True, 'thrust_ridge_validation': True},
     r'thrust_hold and thrust_ridge_validation both decide'),
    ('thrust_hold not a bool', {'thrust_hold': 1}, r'thrust_hold must be true or false'),
    ('north_east_decoupled not a bool', {'north_east_decoupled': 1},
     r'north_east_decoupled must be true or false'),
    ('max_epochs', {'max_epochs': 0}, r'max_epochs must be ≥ 1'),
    ('sub-sample window', {'transient_length': 0.2}, r'transient_length = 0\.2 s is shorter '
                                                      r'than one sample'),
    ('notch_depth 1', {'notch_depth': 1.0}, r'notch depth rule.*got 1\.0'),
    ('notch_depth 0', {'notch_depth': 0.0}, r'notch depth rule'),
    ('min_peak_ratio', {'min_peak_ratio': 1.0}, r'peak ratio rule'),
    ('trainer', {'trainer': 'sgd'}, r"trainer rule.*'sgd'"),
    ('training_mode', {'training_mode': 'teacher'}, r"training mode rule.*'teacher'"),
    ('training time', {'max_train_seconds': 61.0}, r'training time rule: max_train_seconds = '
                                                   r'61\.0 s exceeds retrain_period'),
    ('band order', {'wave_band': (1.3, 0.3)}, r'wave band rule'),
    ('band negative', {'wave_band': (-0.1, 1.3)}, r'wave band rule'),
    ('band arity', {'wave_band': (0.3,)}, r'wave_band must be two numbers'),
    ('nyquist', {'sample_time': 2.0}, r'Nyquist rule: .*1\.6 rad/s must stay below '
                                      r'π/sample_time = 1\.571'),
    ('highpass in band', {'highpass_cutoff': 1.5}, r'high-pass rule: highpass_cutoff ωHP = 1\.5'),
    ('prior outside band', {'initial_wave_peak_freq': 2.0}, r'prior rule'),
    ('prior negative', {'initial_wave_peak_freq': -0.5}, r'initial_wave_peak_freq must be ≥ 0'),
    ('eq 4.4', {'filter_window': 100.0}, r'α ≥ Δ \+ 2ε \(thesis eq\. 4\.4\): filter_window '
                                         r'α = 100 s.*at least 120 s'),
    ('eq 4.5 lower', {'append_length': 80.0}, r'Δ \+ ε ≤ β \(thesis eq\. 4\.5\): append_length '
                                              r'β = 80 s.*90 s'),
    ('eq 4.5 upper', {'append_length': 150.0}, r'β < α − ε \(thesis eq\. 4\.5\): append_length '
                                               r'β = 150 s.*α − ε = 150 s'),
    ('N ≥ α', {'training_window': 150.0}, r'rule N ≥ α: training_window N = 150 s'),
    ('N regressors', {**_TINY, 'training_window': 5.0}, r'rule N ≥ ε \+ max regressor \+ 20: '
                                                        r'training_window N has 10 samples, '
                                                        r'needs 24'),
    ('spectral resolution', {'estimation_window': 200.0}, r'spectral resolution rule: '
                                                          r'estimation_window γ = 200 s'),
    ('non-integer', {'nu': 2.5}, r'nu must be an integer'),
    ('bool as int', {'ndof': True}, r'ndof must be an integer'),
    ('nan', {'sample_time': math.nan}, r'sample_time must be finite'),
    ('string number', {'retrain_period': '60'}, r'retrain_period must be a number'),
]


@pytest.mark.parametrize(('changes', 'message'), [c[1:] for c in RULE_CASES],
                         ids=[c[0] for c in RULE_CASES])
def test_every_rule_rejects_a_violating_value(changes: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PredictorParams(**changes)
    with pytest.raises(ValueError, match=message):
        PredictorParams().replace(**changes)


def test_defaults_and_sample_counts() -> None:
    # nfb 2 (LF feedback) needs the motion gate off (ramp rule)
    params = PredictorParams(sample_time=0.5, nu=2, ny=2, nfb=2, motion_gate=False)
    assert (params.retrain_samples, params.transient_samples, params.filter_samples,
            params.append_samples, params.training_samples, params.estimation_samples) == (
                120, 60, 360, 240, 2400, 2400)
    assert params.max_lag == 2
    assert params.nyquist_freq == pytest.approx(2.0 * math.pi)
    assert PredictorParams().sample_time == 1.0
    assert PredictorParams().max_lag == 24
    assert params.lowpass_cutoff(0.3) == pytest.approx(0.5)  # thesis Fig. 4.8
    assert params.wave_peak_prior is None
    assert PredictorParams(initial_wave_peak_freq=0.6).wave_peak_prior == 0.6
    # the shipped motion gate (parabola twin, T 5 s, dead zone 0.6, the heading gated while the
    # yaw moment is 5× its level, held 30 s, after a 300 s warm-up), the guard's heading floor
    # 0.1 rad and the broadband targets' notch for station keeping (ζ 1.3, lower edge 0.23 rad/s)
    defaults = PredictorParams()
    assert (defaults.motion_gate, defaults.ramp_order, defaults.motion_gate_smoothing,
            defaults.motion_gate_dead_zone, defaults.motion_gate_yaw) == (True, 2, 5.0, 0.6, True)
    assert (defaults.motion_gate_yaw_moment_ratio, defaults.motion_gate_yaw_hold,
            defaults.motion_gate_yaw_warmup, defaults.guard_floor) == (5.0, 30.0, 300.0,
                                                                      (0.5, 0.5, 0.1))
    assert (defaults.ramp_invariant, defaults.motion_gate_ny,
            defaults.motion_gate_validation) == (False, 0, False)
    assert (defaults.notch_zeta, defaults.notch_zeta_broadband, defaults.notch_lower_edge,
            defaults.notch_broadband_holding_only) == (0.8, 1.3, 0.23, True)


def test_windows_in_seconds_are_rate_independent() -> None:
    slow = PredictorParams(sample_time=1.0)
    fast = PredictorParams(sample_time=0.1)
    assert fast.filter_samples == 10 * slow.filter_samples == 1800
    assert fast.append_samples == 10 * slow.append_samples == 1200


def test_boundaries_of_eqs_4_4_and_4_5_are_accepted() -> None:
    # β = Δ + ε exactly; α one sample above Δ + 2ε (α = Δ + 2ε leaves no β: Δ + ε ≤ β < Δ + ε).
    params = PredictorParams(sample_time=0.5, append_length=90.0, filter_window=120.5)
    assert (params.append_samples, params.filter_samples) == (180, 241)
    with pytest.raises(ValueError, match='eq. 4.5'):
        PredictorParams(sample_time=0.5, append_length=90.0, filter_window=120.0)


def test_numbers_are_coerced() -> None:
    raw: dict[str, Any] = {'nu': np.int64(3), 'ny': 2.0, 'retrain_period': 60,
                           'wave_band': [0.3, 1.3],  # as YAML / numpy would hand them over
                           'motion_gate': False}  # the default gate's parabola needs ny ≥ 3
    params = PredictorParams(**raw)
    assert isinstance(params.nu, int) and params.nu == 3
    assert isinstance(params.ny, int)
    assert isinstance(params.retrain_period, float)
    assert params.wave_band == (0.3, 1.3)


def test_dict_round_trip_and_unknown_keys() -> None:
    params = PredictorParams(ndof=3, trainer='adam', wave_band=(0.3, 1.3), seed=4)
    values = params.to_dict()
    assert values['wave_band'] == [0.3, 1.3]
    assert values['ndof'] == 3
    assert PredictorParams.from_dict(values) == params
    with pytest.raises(ValueError, match=r"unknown PredictorParams key\(s\) \['gamma'\]: valid "
                                         r"keys are \[.*'estimation_window'"):
        PredictorParams.from_dict({**values, 'gamma': 600.0})
    with pytest.raises(ValueError, match=r"\['gamma'\]"):
        params.replace(gamma=600.0)


def test_replace_revalidates_and_keeps_the_original() -> None:
    params = PredictorParams(sample_time=0.5)
    changed = params.replace(retrain_period=30.0, append_length=90.0)
    assert changed.retrain_samples == 60 and params.retrain_samples == 120
    with pytest.raises(ValueError, match='eq. 4.4'):
        params.replace(transient_length=70.0)


def test_field_metadata_documents_every_parameter() -> None:
    from dataclasses import fields
    for f in fields(PredictorParams):
        assert f.metadata['doc'], f.name
    assert {f.name: f.metadata['unit'] for f in fields(PredictorParams)}['filter_window'] == 's'


def test_linear_init_must_be_a_bool() -> None:
    assert PredictorParams().linear_init is True
    assert PredictorParams(linear_init=False).linear_init is False
    with pytest.raises(ValueError, match='linear_init must be true or false'):
        PredictorParams(linear_init=1)  # type: ignore[arg-type]


@pytest.mark.parametrize('wave_peak_freq', [0.5, 0.8, 1.2])
def test_the_broadband_notch_has_its_lower_edge_at_notch_lower_edge(
        wave_peak_freq: float) -> None:
    """|H(jω_e)|² = 1/2 for the notch (s² + ω0²)/(s² + 2ζω0 s + ω0²) with ζ of the edge rule."""
    from scipy import signal

    from lf_predictor_ros.core.filters import continuous_wave_filter

    edge = 0.27  # [rad/s]
    params = PredictorParams(notch_lower_edge=edge, notch_zeta=0.1, notch_zeta_broadband=10.0)
    zeta = params.target_notch_zeta(wave_peak_freq, peak_damping=0.1)
    b, a = continuous_wave_filter(wave_peak_freq, notch_zeta=zeta, notch_depth=0.0,
                                  lowpass_offset=None)
    _, response = signal.freqs(b, a, worN=[edge])
    assert abs(response[0]) ** 2 == pytest.approx(0.5, rel=1e-9)
    assert 0.1 < zeta < 10.0


def test_the_targets_notch_widens_only_in_a_broadband_sea() -> None:
    from lf_predictor_ros.core.params import BROADBAND_PEAK_DAMPING

    off = PredictorParams(notch_zeta=0.8, notch_zeta_broadband=0.0)
    assert off.target_notch_zeta(0.8, peak_damping=0.1) == 0.8  # broadband option off
    wide = PredictorParams(notch_zeta=0.8, notch_zeta_broadband=1.3, notch_lower_edge=0.23)
    assert PredictorParams().target_notch_zeta(0.65, peak_damping=0.1) == \
        wide.target_notch_zeta(0.65, peak_damping=0.1)  # the defaults' broadband notch
    assert wide.target_notch_zeta(0.8) == 0.8  # sea bandwidth unknown
    assert wide.target_notch_zeta(0.8, peak_damping=0.01) == 0.8  # a narrow (thesis) sea
    assert wide.target_notch_zeta(0.8, peak_damping=BROADBAND_PEAK_DAMPING) == 1.3
    r = 0.23 / 0.65
    assert wide.target_notch_zeta(0.65, peak_damping=0.1) == pytest.approx((1 - r * r) / (2 * r))
    # a swell: the edge would ask less than notch_zeta, which stays (never narrower)
    assert wide.target_notch_zeta(0.4, peak_damping=0.1) == 0.8
    assert PredictorParams(notch_zeta_broadband=1.3, notch_lower_edge=0.0).target_notch_zeta(
        0.4, peak_damping=0.1) == 1.3  # no edge: no limit


@pytest.mark.parametrize('changes', [
    {'ndof': 1}, {'hidden_units': 2}, {'derivative_weight': 0.1}, {'thrust_hold': True},
    {'thrust_prior': 0.01}, {'thrust_ridge_validation': True},
    {'nfb': 2, 'motion_gate': False, 'training_mode': 'parallel'}])
def test_north_east_decoupled_acts_only_on_the_plain_linear_solve(changes: dict[str, Any]
                                                                  ) -> None:
    assert PredictorParams(north_east_decoupled=True).decouples_north_east
    assert not PredictorParams(north_east_decoupled=False).decouples_north_east
    assert not PredictorParams(north_east_decoupled=True, **changes).decouples_north_east


def test_the_shipped_3dof_default_fits_north_and_east_per_dof() -> None:
    # the default since the forty-third session (docs/BENCHMARKS.md); 1 DOF has nothing to split
    assert PredictorParams().decouples_north_east
    assert not PredictorParams(ndof=1).decouples_north_east
