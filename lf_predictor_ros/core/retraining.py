"""One retraining of the LF predictor: thesis Algorithm 4.1 lines 18–40 as a pure function.

    snapshot of the last samples (u, y)                       lines 3–8
      → wave peak frequency ω0 from the last γ samples      lines 19–23 (§4.2.1)
      → notch at ω0 + low-pass at ωLP, zero phase, last α   lines 24–29 (§4.2.2)
      → targets: append to the previous ones                lines 30–35 (eq. 4.4, 4.5)
      → train on the last N samples, last ε masked          lines 36–40 (§4.3)
      → validate the candidate against the network in service

`run_retraining` touches no shared state: it gets copies and returns a `RetrainResult`, so it can
run on the predictor's worker thread (or inline, for deterministic replay) and the caller decides
what to put in service. A candidate is rejected (and the network in service kept) when its weights
or loss are not finite, when training diverged (loss above its start), or when it is worse than the
network in service on the newest targets.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
import threading
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray
import torch

from lf_predictor_ros.core.augmentation import (
    augmented_copy,
    band_limited_motion,
    lf_motion,
    periodic_zero_phase,
)
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.filters import design_wave_filter, zero_phase
from lf_predictor_ros.core.frequency import FrequencyEstimate, estimate_wave_peak_freq
from lf_predictor_ros.core.lf_dynamics import (
    earth_to_body,
    thrust_improves_dead_reckoning,
)
from lf_predictor_ros.core.manoeuvre import manoeuvring, turning
from lf_predictor_ros.core.network import (
    NnarmaxNet,
    NnarmaxSpec,
    NumpyNnarmax,
    without_force_inputs,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.readonly import read_only
from lf_predictor_ros.core.regressors import build_regressors
from lf_predictor_ros.core.targets import TargetWindow, training_mask
from lf_predictor_ros.core.training import TrainSettings, evaluate_loss, train
from lf_predictor_ros.core.training_window import loss_frame_errors, loss_scale

FloatArray = NDArray[np.float64]

# A candidate must not be worse than the network in service by more than this factor on the
# newest targets (1.0 = strictly no worse; a little slack avoids freezing on numerical noise).
ACCEPT_LOSS_RATIO = 1.02
# Ridges per row (standardized units) on the thrust regressors that `thrust_ridge_validation`
# chooses from: from the trainer's own 1e-6 (thrust as free as the positions) to 1e3 (thrust
# in effect dropped).
FORCE_RIDGE_GRID = (1e-6, 1e-3, 1e-2, 1e-1, 1.0, 10.0, 1e3)
# An ω0 estimate this close (relative) to a wave-band edge is not trusted if an earlier one exists.
EDGE_MARGIN = 0.05
# ω0 moving by more than this (relative) between retrainings is a new sea state (see
# `sea_state_estimate`): the training window restarts on the newest data.
SEA_CHANGE_RATIO = 0.25


@dataclass(frozen=True)
class Snapshot:
    """Copies of the predictor's data at the retraining instant.

    ``u`` (n, n_inputs_u) forces, ``y`` (n, ndof) positions with unwrapped heading, newest last;
    ``end_index`` is the sample index (since the segment started) of the newest row.
    """

    u: FloatArray
    y: FloatArray
    end_index: int
    segment: int


@dataclass(frozen=True)
class RetrainResult:
    """What one retraining produced; ``model`` is None when the candidate was rejected."""

    segment: int
    end_index: int
    frequency: FrequencyEstimate
    targets: TargetWindow
    model: NumpyNnarmax | None
    state_dict: dict[str, torch.Tensor] | None
    loss: float
    incumbent_loss: float | None
    accepted: bool
    reason: str
    seconds: float
    epochs: int
    wave_spread: FloatArray | None = None
    baseline_loss: float | None = None
    retire_incumbent: bool = False
    thrust_used: bool = True  # False: thrust_validation found no thrust information
    # the sea's peak damping the targets' filter was designed with (`targets_peak_damping`)
    targets_peak_damping: float = math.nan
    # the targets' samples filtered with the narrow notch_zeta (`narrow_reference`; None: the
    # targets' notch is that narrow one)
    narrow_reference: FloatArray | None = None
    # the training window was restarted by a change of sea state (`sea_state_changed`)
    restarted: bool = False
    # ``sea_change_revert``: ω0 came back to its value before a recent restart, whose targets
    # were taken up again instead of restarting once more
    reverted: bool = False
    # ``thrust_hold``: the window showed no excitation and the candidate kept the thrust
    # weights of the network in service (`thrust_held`)
    thrust_held: bool = False

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Unpickled (from `core.fit_process`'s child): ``narrow_reference`` read-only again."""
        for name, value in state.items():
            object.__setattr__(self, name, value)
        read_only(self.narrow_reference)


# Dead-reckoning horizon of the thrust test of ``thrust_validation`` [s] (the dead-reckoning
# timeout of the odometry: the horizon over which a DP stack relies on the thrust model).
THRUST_TEST_HORIZON = 120.0


def thrust_predicts_motion(params: PredictorParams, u: FloatArray, targets: FloatArray,
                           mask: NDArray[np.bool_], wave_peak_freq: float | None = None,
                           peak_damping: float = math.nan) -> bool:
    """Does the thrust of this window predict its LF motion? (``thrust_validation``)

    `lf_dynamics.thrust_improves_dead_reckoning`: the LF model ν̇ = Fν + Gτ + Bβ(ψ) fitted on
    the older two thirds of the window's targets with the thrust must dead-reckon the newest
    third better than the same model fitted without it. ``u`` holds the predictor's force
    channels (earth frame for 3 DOF: turned back to the body with the targets' heading).
    ``wave_peak_freq``: the ω0 of the targets' filter, which the fit applies to the thrust too
    (`lf_dynamics.paired_forces`; None: the thrust as it is).
    """
    keep = np.flatnonzero(mask)
    if keep.size < 3:
        return True
    end = int(keep[-1]) + 1
    eta = targets[:end]
    forces = earth_to_body(eta, np.asarray(u[:end], dtype=np.float64), params.ndof)
    sos = None if wave_peak_freq is None else target_filter(params, wave_peak_freq,
                                                            peak_damping)
    return thrust_improves_dead_reckoning(eta, forces, params.sample_time, THRUST_TEST_HORIZON,
                                          sos)


def without_excitation(params: PredictorParams, snapshot: Snapshot,
                        incumbent: dict[str, torch.Tensor] | None) -> bool:
    """Does this retraining's window show no excitation a network could be identified from?

    True when there is a warm start (``incumbent``: the network in service, or the last one
    retired to the cascade), the predictor has seen at least a full training window N of this
    segment, and the newest N samples show no setpoint move or turn (`manoeuvre.manoeuvring`).
    In DP station keeping the thrust is then a function of the filter's own past estimates
    (closed-loop identification without excitation, thesis §5.2.3).
    """
    window = params.training_samples
    return (incumbent is not None and snapshot.end_index >= window
            and not manoeuvring(snapshot.y[-window:], params.sample_time))


def thrust_held(params: PredictorParams, snapshot: Snapshot,
                incumbent: dict[str, torch.Tensor] | None) -> bool:
    """Does this retraining keep the thrust weights of the warm start? (``thrust_hold``)

    Yes on a window `without_excitation`: refitting the thrust weights on such windows made the
    late limit cycles of onedof_feedback, while the wave part must keep adapting to the sea
    (docs/BENCHMARKS.md, thirty-eighth session). A window restarted for a new sea is judged the
    same way, although thrust weights fitted in a swell near the LF band carry part of the wave
    filter (thirty-ninth session, the regrowth probe).
    """
    return params.thrust_hold and params.nu > 0 and without_excitation(params, snapshot,
                                                                       incumbent)


def network_spec(params: PredictorParams) -> NnarmaxSpec:
    """The network shape the parameters ask for (one output and one force per DOF)."""
    return NnarmaxSpec(n_outputs=params.ndof, n_inputs_u=params.ndof, nu=params.nu,
                       ny=params.ny, nfb=params.nfb, hidden_units=params.hidden_units,
                       hidden_layers=params.hidden_layers, relative=True,
                       body_frame=params.regressor_frame == 'body',
                       ramp_invariant=params.ramp_invariant,
                       # the order matters only to a ramp-invariant network: a plain one keeps
                       # the spec (and checkpoint) it always had
                       ramp_order=params.ramp_order if params.ramp_invariant else 1)


def train_settings(params: PredictorParams) -> TrainSettings:
    """Trainer settings from the predictor parameters."""
    return TrainSettings(algorithm=params.trainer,  # type: ignore[arg-type]
                         mode=params.training_mode,  # type: ignore[arg-type]
                         max_epochs=params.max_epochs, max_seconds=params.max_train_seconds,
                         weight_decay=params.weight_decay,
                         derivative_weight=params.derivative_weight,
                         linear_init=params.linear_init, seed=params.seed,
                         force_ridge_grid=FORCE_RIDGE_GRID if params.thrust_ridge_validation
                         else (), validation_rows=params.retrain_samples,
                         force_prior=params.thrust_prior,
                         north_east_decoupled=params.decouples_north_east)


def first_training_samples(params: PredictorParams) -> int:
    """Samples needed before the first training: α and half of γ (enough spectral resolution)."""
    return max(params.filter_samples + params.max_lag + 1,
               min(params.estimation_samples, 2 * params.filter_samples))


def estimate_frequency(params: PredictorParams, y: FloatArray,
                       previous: FrequencyEstimate | float | None,
                       samples: int | None = None) -> FrequencyEstimate:
    """Algorithm 4.1 lines 19–23 on the last γ samples (or the last ``samples``).

    With ``frequency_yaw`` false (ndof 3) the heading column is left out of the spectrum.
    """
    window = y[-(params.estimation_samples if samples is None else samples):]
    if params.ndof == 3 and not params.frequency_yaw:
        window = window[:, :2]
    estimate = estimate_wave_peak_freq(window, params.sample_time,
                                       highpass_cutoff=params.highpass_cutoff,
                                       wave_band=(params.wave_band[0], params.wave_band[1]),
                                       min_peak_ratio=params.min_peak_ratio, previous=previous)
    prev = previous.wave_peak_freq if isinstance(previous, FrequencyEstimate) else previous
    if not _band_interior(params, estimate.wave_peak_freq) and prev is not None:
        # A peak on the band edge is most often LF motion leaking through the high-pass (a large
        # DP excursion) or noise, not the sea: keep the previous estimate and say so.
        return replace(estimate, wave_peak_freq=float(prev), confident=False)
    return estimate


def _band_interior(params: PredictorParams, wave_peak_freq: float) -> bool:
    """True unless ω0 lies within ``EDGE_MARGIN`` of a wave-band edge."""
    low, high = params.wave_band
    return low * (1 + EDGE_MARGIN) < wave_peak_freq < high * (1 - EDGE_MARGIN)


def sea_state_estimate(params: PredictorParams, y: FloatArray,
                       previous: FrequencyEstimate | float | None) -> FrequencyEstimate:
    """ω0 for this retraining: the γ-window estimate, unless the sea has just changed.

    The γ window (20 min) resolves the peak finely but keeps the old sea's peak for up to γ
    after a change of sea state (a swell arriving, the wind turning): on the thesis Fig. 4.1 steps
    the estimate switched 600–900 s late, and every target in between was filtered at the wrong
    ω0. So ω0 is also estimated on the newest ``change_samples`` (max(α, γ/4)); when that estimate
    is confident and more than ``SEA_CHANGE_RATIO`` away from the γ-window one, it wins.

    ``sea_change_confirm`` always (or, ndof 3, manoeuvres and the short window shows a setpoint
    move or a turn, or turns and it shows a turn): it wins only if the short window ending one
    retrain period Δ earlier says the same (a change too, within ``SEA_CHANGE_RATIO`` of the
    newest). On rao_swell development seed 5 one short window held the LF motion of a +90° turn
    as a peak at 0.335 rad/s (sea: 0.48), the training window restarted on targets notched there
    and the loop left 5 m; the windows Δ before and after it reported no change
    (docs/BENCHMARKS.md "Fifteenth session"). A real change is then taken one Δ later
    (omega_steps development seed 3: the estimate recovered 477 s after the 1.25 → 0.3 rad/s step
    instead of 252 s), which is why the confirmation is asked only where a manoeuvre is in the
    window. ``manoeuvres`` (the default since the twentieth session) asks after setpoint moves
    too: with the restart no longer undone (`fresh_span`), a false restart on rao_swell
    development seed 6 took that loop out (docs/BENCHMARKS.md, twentieth session).
    """
    long = estimate_frequency(params, y, previous)
    short_len = change_samples(params)
    if len(y) < 2 * short_len:
        return long
    short = estimate_frequency(params, y, None, samples=short_len)
    if not _sea_changed_from(params, short, long):
        return long
    if _confirm_needed(params, y[-short_len:]):
        earlier_y = y[:-params.retrain_samples]
        if len(earlier_y) < 2 * short_len:
            return long
        earlier = estimate_frequency(params, earlier_y, None, samples=short_len)
        if not (_sea_changed_from(params, earlier, long) and _relative_change(
                short.wave_peak_freq, earlier.wave_peak_freq) <= SEA_CHANGE_RATIO):
            return long
    return short


def _confirm_needed(params: PredictorParams, short_y: FloatArray) -> bool:
    """Must a sea change seen on ``short_y`` be confirmed (``sea_change_confirm``)?"""
    if params.sea_change_confirm == 'always':
        return True
    if params.sea_change_confirm == 'turns' and short_y.shape[1] == 3:
        return turning(short_y[:, 2], params.sample_time)
    if params.sea_change_confirm == 'manoeuvres' and short_y.shape[1] == 3:
        return manoeuvring(short_y, params.sample_time)
    return False


def _sea_changed_from(params: PredictorParams, short: FrequencyEstimate,
                      long: FrequencyEstimate) -> bool:
    """The short window's ω0 is confident, inside the band and far from the γ window's."""
    return (short.confident and _band_interior(params, short.wave_peak_freq)
            and _relative_change(short.wave_peak_freq, long.wave_peak_freq) > SEA_CHANGE_RATIO)


def change_samples(params: PredictorParams) -> int:
    """Samples of the short window that detects a change of sea state: max(α, γ/4)."""
    return max(params.filter_samples, params.estimation_samples // 4)


def sea_state_changed(previous: FrequencyEstimate | float | None,
                      current: FrequencyEstimate) -> bool:
    """True when ω0 moved by more than ``SEA_CHANGE_RATIO`` since the previous retraining."""
    prev = previous.wave_peak_freq if isinstance(previous, FrequencyEstimate) else previous
    return prev is not None and _relative_change(current.wave_peak_freq,
                                                 float(prev)) > SEA_CHANGE_RATIO


def _relative_change(value: float, reference: float) -> float:
    return abs(value - reference) / reference if reference > 0.0 else math.inf


def target_filter(params: PredictorParams, wave_peak_freq: float,
                  peak_damping: float = math.nan) -> FloatArray:
    """The targets' notch at ω0 + low-pass at ω0 + offset (Algorithm 4.1 lines 25–26), as SOS.

    The notch's width is `PredictorParams.target_notch_zeta` of ω0 and of the sea's fitted peak
    damping ``peak_damping`` (NaN: unknown, not broadband).
    """
    return design_wave_filter(wave_peak_freq, params.sample_time,
                              notch_zeta=params.target_notch_zeta(wave_peak_freq, peak_damping),
                              notch_depth=params.notch_depth,
                              lowpass_offset=params.lowpass_offset)


def targets_peak_damping(params: PredictorParams, snapshot: Snapshot,
                         frequency: FrequencyEstimate) -> float:
    """The sea's peak damping the targets' notch is designed with (`target_filter`).

    ``frequency.peak_damping``, or NaN (unknown: ``notch_zeta``) with
    ``notch_broadband_holding_only`` when `PredictorParams.target_notch_zeta` would widen the
    notch for this sea but the training window's positions show a setpoint move or a turn
    (`manoeuvre.manoeuvring` of its newest N samples). `run_retraining` then filters that
    window's targets afresh instead of appending to the previous ones (which may hold wide-notch
    targets of station keeping).
    """
    wave_peak_freq, damping = frequency.wave_peak_freq, frequency.peak_damping
    if params.notch_broadband_holding_only and \
            params.target_notch_zeta(wave_peak_freq, damping) > params.notch_zeta and \
            manoeuvring(snapshot.y[-params.training_samples:], params.sample_time):
        return math.nan
    return damping


def make_targets(params: PredictorParams, y: FloatArray, end_index: int,
                 wave_peak_freq: float, previous: TargetWindow | None,
                 peak_damping: float = math.nan) -> TargetWindow:
    """Algorithm 4.1 lines 24–35: zero-phase notch + low-pass and appending.

    The first targets (``previous`` None, or too old to append without a gap) come from filtering
    everything available up to N + ε samples, minus the last ε.
    """
    sos = target_filter(params, wave_peak_freq, peak_damping)
    eps, beta = params.transient_samples, params.append_samples
    if previous is not None:
        shift = end_index - previous.end_index
        if 0 < shift <= beta and len(previous) >= beta - shift:
            filtered = zero_phase(y[-params.filter_samples:], sos)
            return previous.append(filtered, end_index, beta, max_len=params.training_samples)
    span = min(len(y), params.training_samples + eps)
    return TargetWindow.start(zero_phase(y[-span:], sos), end_index, eps)


def narrow_reference(params: PredictorParams, y: FloatArray, count: int, wave_peak_freq: float,
                     peak_damping: float = math.nan) -> FloatArray | None:
    """The newest ``count`` samples of ``y`` filtered like the targets but with the narrow notch.

    None when the targets' notch (`target_filter` at ``peak_damping``) is the narrow
    ``notch_zeta`` one already. Otherwise ``y`` (newest last, ending at the targets' end) is
    filtered zero-phase with ``notch_zeta`` over the targets' span plus ε older samples (edge
    transient), in one pass. The odometry calibrates its covariances against this reference
    (`OdometryParams.narrow_reference`): the broadband notch's targets are smoother than the
    truth in a way that depends on the sea, so the errors measured against them do not scale to
    the errors against the truth as the narrow targets' do (issue 14).
    """
    if params.target_notch_zeta(wave_peak_freq, peak_damping) <= params.notch_zeta:
        return None
    if count < 1 or count > y.shape[0]:
        raise ValueError(f'count must lie in [1, {y.shape[0]}] samples, got {count}')
    span = min(y.shape[0], count + params.transient_samples)
    reference = zero_phase(y[-span:], target_filter(params, wave_peak_freq))[-count:]
    reference.setflags(write=False)  # handed to the odometry's worker
    return reference


def fresh_span(params: PredictorParams, snapshot: Snapshot, previous: TargetWindow) -> int:
    """Samples of ``snapshot`` to filter afresh: back to the previous targets' oldest, plus ε.

    Targets filtered afresh (a manoeuvre in a broadband sea, `targets_peak_damping`) cover the
    window the previous targets covered and the samples since, never more: after a change of
    sea state the window restarts on the newest samples (`run_retraining`), and the older ones
    hold the old sea's waves, which the new ω0's filter passes into the targets (a swell below a
    new, higher ω0 is not notched). Filtering the whole N again undid that restart at the next
    manoeuvre, and the old waves stayed in the targets for N (docs/BENCHMARKS.md, twentieth
    session). ε older samples carry the filter's start transient, which `TargetWindow.start`
    drops. At most the whole snapshot.
    """
    span = snapshot.end_index - previous.start_index + 1 + params.transient_samples
    return int(min(max(span, 1), snapshot.y.shape[0]))


def training_window(params: PredictorParams, snapshot: Snapshot,
                    targets: TargetWindow) -> tuple[FloatArray, FloatArray, FloatArray,
                                                    NDArray[np.bool_]]:
    """(u, y, targets, mask) over the samples that have targets, the last ε masked out."""
    if targets.end_index != snapshot.end_index:
        raise ValueError(f'targets end at sample {targets.end_index}, data at '
                         f'{snapshot.end_index}: make the targets from this snapshot')
    n_t = len(targets)
    u = snapshot.u[-n_t:]
    y = snapshot.y[-n_t:]
    mask = training_mask(n_t, params.transient_samples)
    return u, y, np.asarray(targets.values).reshape(n_t, -1), mask


def run_retraining(params: PredictorParams, snapshot: Snapshot,
                   incumbent: dict[str, torch.Tensor] | None,
                   previous_targets: TargetWindow | None,
                   previous_frequency: FrequencyEstimate | float | None,
                   stop_event: threading.Event | None = None,
                   before_restart: tuple[float, TargetWindow] | None = None) -> RetrainResult:
    """One full retraining (see module docstring); never modifies its arguments.

    ``before_restart`` (``sea_change_revert``): the ω0 and the targets in service before a
    restart of the window at most 2Δ ago. When this retraining's ω0 is a change from the
    previous one but not from that ω0, the restart was not a sea change: those targets are
    taken up again (appended to, or filtered afresh) instead of restarting once more.
    """
    start = time.monotonic()
    frequency = sea_state_estimate(params, snapshot.y, previous_frequency)
    damping = targets_peak_damping(params, snapshot, frequency)
    # a window flagged as a manoeuvre in a broadband sea: its targets are filtered afresh, so
    # the wide-notch targets of earlier station-keeping windows do not stay appended in it
    narrowed = math.isnan(damping) and not math.isnan(frequency.peak_damping)
    changed, reverted = sea_state_changed(previous_frequency, frequency), False
    if changed and before_restart is not None and \
            not sea_state_changed(before_restart[0], frequency):
        changed, reverted, previous_targets = False, True, before_restart[1]
    if changed:
        # a new sea: the old targets were filtered at the old ω0 and the old data shows the old
        # waves, so the training window restarts on the newest samples and grows back to N
        measured = snapshot.y[-change_samples(params):]
        targets = make_targets(params, measured, snapshot.end_index, frequency.wave_peak_freq,
                               None, damping)
    else:
        measured = snapshot.y
        if narrowed and previous_targets is not None:
            measured = snapshot.y[-fresh_span(params, snapshot, previous_targets):]
        targets = make_targets(params, measured, snapshot.end_index, frequency.wave_peak_freq,
                               None if narrowed else previous_targets, damping)
    reference = narrow_reference(params, measured, len(targets), frequency.wave_peak_freq,
                                 damping)
    u, y, t_values, mask = training_window(params, snapshot, targets)
    spread = wave_spread(y, t_values, mask)
    spec = network_spec(params)
    if incumbent is None:
        net = NnarmaxNet(spec, seed=params.seed)
    else:
        net = NnarmaxNet.from_state(spec, incumbent)
    held = thrust_held(params, snapshot, incumbent)
    settings = replace(train_settings(params), hold_forces=held)
    thrust_used = not params.thrust_validation or params.nu == 0 or \
        thrust_predicts_motion(params, u, t_values, mask, frequency.wave_peak_freq, damping)
    u_fit = u if thrust_used else np.zeros_like(u)
    result = train(net, *training_data(params, snapshot, u_fit, y, t_values, mask, spread,
                                       frequency.wave_peak_freq, damping),
                   settings, stop_event=stop_event)
    if not thrust_used:
        result = replace(result, state_dict=without_force_inputs(result.state_dict, spec))
    augmented = params.wave_augmentation > 0.0 or \
        any(v > 0.0 for v in params.lf_augmentation[:y.shape[1]])
    loss = evaluate_loss(result.state_dict, spec, u, y, t_values, mask, settings.mode) \
        if augmented else result.loss
    incumbent_loss = None
    if incumbent is not None:
        incumbent_loss = evaluate_loss(incumbent, spec, u, y, t_values, mask, settings.mode)
    baseline = cascade_loss(params, y, t_values, mask, frequency.wave_peak_freq)
    accepted, reason = _judge(loss, result.objective, result.initial_objective,
                              incumbent_loss, result.state_dict)
    if accepted and loss > baseline:
        accepted, reason = False, (f'candidate no better than the causal notch + low-pass on '
                                   f'the newest targets ({loss:.3g} > {baseline:.3g})')
    retire = not accepted and incumbent_loss is not None and incumbent_loss > baseline
    model = NumpyNnarmax.from_module(NnarmaxNet.from_state(spec, result.state_dict)) \
        if accepted else None
    if model is not None and params.regressor_clip > 0.0:
        model = model.with_range(build_regressors(u, y, t_values, spec)[0], params.regressor_clip)
    return RetrainResult(segment=snapshot.segment, end_index=snapshot.end_index,
                         frequency=frequency, targets=targets, model=model,
                         state_dict=result.state_dict if accepted else None,
                         loss=loss, incumbent_loss=incumbent_loss, accepted=accepted,
                         reason=reason, seconds=time.monotonic() - start, epochs=result.epochs,
                         wave_spread=spread, baseline_loss=baseline,
                         retire_incumbent=retire, thrust_used=thrust_used,
                         targets_peak_damping=damping, narrow_reference=reference,
                         restarted=changed, reverted=reverted, thrust_held=held)


def training_data(params: PredictorParams, snapshot: Snapshot, u: FloatArray, y: FloatArray,
                  targets: FloatArray, mask: NDArray[np.bool_], spread: FloatArray,
                  wave_peak_freq: float, peak_damping: float = math.nan,
                  ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """What the trainer fits: the window, plus its augmentation copies when enabled.

    ``params.wave_augmentation`` > 0 appends a copy (`augmentation.augmented_copy`) with synthetic
    motion over [ωLP, Nyquist] with ``wave_augmentation`` × the window's wave spread (its
    measured WF RMS) per DOF added to y, and its zero-phase target-filter output added to the
    targets. ``params.lf_augmentation`` > 0 (any DOF) appends a copy with LF motion
    (`augmentation.lf_motion`, that RMS velocity per DOF) added to y and, through the target
    filter, to the targets. The generator is seeded by the predictor seed, the segment and the
    sample index, so a replay trains on the same data.
    """
    wave = params.wave_augmentation > 0.0 and bool(np.all(np.isfinite(spread)))
    speeds = np.array(params.lf_augmentation[:y.shape[1]])
    if not wave and not np.any(speeds > 0.0):
        return u, y, targets, mask
    rng = np.random.default_rng([params.seed, snapshot.segment, snapshot.end_index])
    sos = target_filter(params, wave_peak_freq, peak_damping)
    motions = []
    if wave:
        motions.append(band_limited_motion(len(y), y.shape[1], params.sample_time,
                                           (params.lowpass_cutoff(wave_peak_freq),
                                            params.nyquist_freq),
                                           params.wave_augmentation * spread, rng))
    if np.any(speeds > 0.0):
        motions.append(lf_motion(len(y), params.sample_time, speeds, rng))
    parts = [(u, y, targets, mask)] + [
        augmented_copy(u, y, targets, mask, motion,
                       periodic_zero_phase(motion, sos, params.sample_time), params.max_lag + 1)
        for motion in motions]
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] for p in parts]), np.concatenate([p[3] for p in parts]))


def cascade_loss(params: PredictorParams, y: FloatArray, targets: FloatArray,
                 mask: NDArray[np.bool_], wave_peak_freq: float) -> float:
    """The trainer's loss of the causal cascade on a window (MSE vs the targets, ``loss_scale``).

    The cascade (notch at ω0 + low-pass, the predictor's own fallback) runs over the window from
    steady state; its output at t stands for the estimate of t + h, exactly as when it is the
    predictor's fallback. Its first ε samples (start-up) and the masked targets are not scored.
    A network is only put in service when it beats this number: the learned filter must earn its
    place against the classical one on the newest data.
    """
    ndof = params.ndof
    cascade = CascadeFilter(ndof, params.sample_time, wave_peak_freq,
                            notch_zeta=params.fallback_notch_zeta, notch_depth=params.notch_depth,
                            lowpass_offset=params.lowpass_offset)
    poses = np.zeros((len(y), 3))
    poses[:, :ndof] = y
    out = np.empty_like(y)
    out[:] = cascade.update_series(poses)[:, :ndof]
    if ndof == 3:  # the cascade wraps yaw; compare on the unwrapped scale of y
        out[:, 2] = y[:, 2] + np.angle(np.exp(1j * (out[:, 2] - y[:, 2])))
    keep = mask.copy()
    keep[:params.transient_samples + 1] = False
    if keep.sum() < 2:
        return math.inf
    spec = network_spec(params)
    error = loss_frame_errors(spec, y[:-1][keep[1:]], out[:-1][keep[1:]] - targets[1:][keep[1:]])
    scale = loss_scale(spec, y[:-1], targets[1:], mask[1:])
    return float(np.mean((error / scale) ** 2))


def wave_spread(y: FloatArray, targets: FloatArray, mask: NDArray[np.bool_]) -> FloatArray:
    """RMS of measurement minus target per DOF on the kept samples: the WF motion + noise."""
    diff = (y - targets)[mask]
    if diff.size == 0:
        return np.full(y.shape[1], np.inf)
    return np.asarray(np.sqrt(np.mean(diff ** 2, axis=0)), dtype=np.float64)


def _judge(loss: float, objective: float, initial_objective: float,
           incumbent_loss: float | None, state: dict[str, torch.Tensor]) -> tuple[bool, str]:
    if not math.isfinite(loss) or not all(bool(torch.isfinite(v).all()) for v in state.values()):
        return False, 'candidate has non-finite weights or loss'
    # The full objective (MSE + derivative + weight terms) is what training minimizes; the MSE
    # part alone may legitimately rise when those terms are on.
    if math.isfinite(initial_objective) and objective > initial_objective * ACCEPT_LOSS_RATIO:
        return False, (f'training diverged (objective {objective:.3g} > start '
                       f'{initial_objective:.3g})')
    if incumbent_loss is not None and math.isfinite(incumbent_loss) and \
            loss > incumbent_loss * ACCEPT_LOSS_RATIO:
        return False, (f'candidate worse than the network in service on the newest targets '
                       f'({loss:.3g} > {incumbent_loss:.3g})')
    return True, 'accepted'
