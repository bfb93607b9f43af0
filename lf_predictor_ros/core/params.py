"""Every tuning quantity of the adaptive LF predictor (thesis Algorithm 4.1), validated.

Unit system: every WINDOW (γ, Δ, N, ε, α, β) is given in SECONDS, so one parameter set works at
any sample rate; the ``*_samples`` properties convert them to sample counts with the sample time
(rounded to the nearest sample). The rules of Algorithm 4.1 are checked on those sample counts,
which is what the algorithm uses. Regressor orders (``nu``, ``ny``, ``nfb``) are in samples,
frequencies in rad/s.

Defaults target a 3-DOF supply-vessel DP (``ndof`` = 3: north, east and heading estimated; 1 DOF
only when asked for) at ``sample_time`` = 1 s (as the thesis likely used; a 10 Hz
sensor is resampled by the caller): a retraining every 60 s on the last 1200 s, a 20 min
frequency-estimation window (the sea state is stationary for 20 min to 3 h, thesis §3.3).
Regressors: nu = 12 forces and ny = 24 measured positions (24 s, two to three wave periods), and
nfb = 0 LF feedbacks — the NNARX special case of the NNARMAX structure. Every configuration with
LF feedback we tried (series-parallel or parallel training, nfb = 1–4) ran away in free run
outside its training window, while the feed-forward network in relative coordinates generalized;
nfb > 0 remains available. Each training first solves the network's linear bypass by least
squares (``linear_init``: the linear ARX model), then refines the whole network with a few LM
epochs; the weight penalty (0.1, tanh part only) keeps the 2 tanh units a small correction.
The tuning runs behind these numbers are in docs/BENCHMARKS.md ("Predictor tuning, round 2").
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from dataclasses import replace as dataclass_replace
import math
import numbers
from typing import Any

from lf_predictor_ros.core.field_meta import field_doc
from lf_predictor_ros.core.frequency import welch_resolution
from lf_predictor_ros.core.regressors import RAMP_ORDERS

TRAINERS = ('lm', 'lbfgs', 'adam')
TRAINING_MODES = ('series_parallel', 'parallel')
REGRESSOR_FRAMES = ('earth', 'body')
# ('off' would read as a YAML boolean in a parameter file: 'never')
SEA_CHANGE_CONFIRMS = ('never', 'turns', 'manoeuvres', 'always')
NDOF_VALUES = (1, 3)
# γ rule: the Welch bin must be at most this fraction of the wave band width, so the band holds
# at least 20 bins and the peak refinement has several bins per peak.
MAX_BIN_FRACTION_OF_BAND = 1.0 / 20.0
# N rule: training examples left after the regressor start-up and the masked transient.
MIN_TRAINING_EXAMPLES = 20
# A sea whose fitted spectral peak damping λ is at least this is broadband
# (``notch_zeta_broadband``): measured λ 0.005–0.017 on the thesis's vessels, 0.07–0.14 on the
# supply and RAO vessels' seas (tuning seeds, docs/BENCHMARKS.md eleventh session) [-].
BROADBAND_PEAK_DAMPING = 0.05
_WINDOW_FIELDS = ('estimation_window', 'retrain_period', 'training_window', 'transient_length',
                  'filter_window', 'append_length')
_INT_FIELDS = ('ndof', 'nu', 'ny', 'nfb', 'hidden_units', 'hidden_layers', 'max_epochs', 'seed',
               'motion_gate_ny', 'ramp_order')
_STR_FIELDS = ('trainer', 'training_mode', 'regressor_frame', 'sea_change_confirm')
_BOOL_FIELDS = ('linear_init', 'thrust_validation', 'thrust_ridge_validation', 'thrust_hold',
                'north_east_decoupled',
                'ramp_invariant', 'motion_gate',
                'motion_gate_validation', 'motion_gate_yaw', 'motion_gate_yaw_network_level',
                'notch_broadband_holding_only',
                'sea_change_revert', 'frequency_yaw')
_TUPLE_FIELDS = ('wave_band', 'max_output_rate', 'lf_augmentation', 'guard_floor')


_doc = field_doc  # (core.field_meta; kept short here, where every field uses it)


@dataclass(frozen=True)
class PredictorParams:
    """Parameters of Algorithm 4.1 (thesis §4.5); windows in seconds, see the module docstring.

    ``initial_wave_peak_freq`` = 0.0 means "no prior" (a ROS parameter cannot hold None); use
    :attr:`wave_peak_prior` to read it as ``float | None``.
    """

    ndof: int = field(default=3, metadata=_doc(
        'degrees of freedom estimated: 3 (north, east, yaw) or 1 (north only; east and yaw are '
        'the measurement passed through unfiltered)'))
    sample_time: float = field(default=1.0, metadata=_doc('predictor sample time h', 's'))
    nu: int = field(default=12, metadata=_doc('delayed control inputs n_u (thesis §4.4)',
                                             'samples'))
    ny: int = field(default=24, metadata=_doc('delayed measured positions n_y', 'samples'))
    nfb: int = field(default=0, metadata=_doc('delayed LF-estimate feedbacks n_fb', 'samples'))
    regressor_frame: str = field(
        default='earth', metadata=_doc(
            'frame of the regressors and of the predicted step: earth (north/east offsets from '
            'the newest position, forces rotated to north/east) or body (the same rotated into '
            'the body frame of the newest heading of each row: rotation invariant; ndof 3 only; '
            'issue 13, hypothesis 3)'))
    ramp_invariant: bool = field(
        default=False, metadata=_doc(
            'positions relative to the least-squares line (ramp_order 2: parabola) through the '
            'ny newest positions and the predicted step taken from its extrapolation: a vessel '
            'moving at constant velocity (setpoint moves, turns) is followed without lag '
            'whatever the window taught (issue 13; nfb 0 only)'))
    ramp_order: int = field(
        default=2, metadata=_doc(
            'polynomial fitted by ramp_invariant networks and the motion gate twin: 1 a line '
            '(constant velocity followed without lag), 2 a parabola (constant acceleration too; '
            'lets more wave motion through; needs ny ≥ 3)'))
    motion_gate: bool = field(
        default=True, metadata=_doc(
            'train a ramp-invariant twin of the network on the same data and blend it in, per '
            'DOF, when the vessel moves faster than it did over the training window (setpoint '
            'moves, turns; core/motion_gate.py; twice the training cost; nfb 0, '
            'ramp_invariant false)'))
    motion_gate_smoothing: float = field(
        default=5.0, metadata=_doc(
            'with motion_gate: time constant of a first-order low-pass on the twin-minus-'
            'holding difference before the gate scales it (the gated output is holding + '
            'g·LP(moving − holding)): the extra wave motion of the twin stays out of the '
            'estimate; '
            '0 = off (holding + g·(moving − holding))', 's'))
    motion_gate_time: float = field(
        default=10.0, metadata=_doc(
            "with motion_gate: time constant of the first-order low-pass on the twin's "
            'per-sample step whose square, against its median over the training window, sets '
            'the gain (shorter: the gate opens sooner after a move or a turn starts, and more '
            'often on wave groups; core/motion_gate.py)', 's'))
    motion_gate_ny: int = field(
        default=0, metadata=_doc(
            'with motion_gate: delayed positions n_y of the ramp-invariant twin (its line is '
            'fitted through them: fewer lag less in accelerations, let through more waves); '
            '0 = ny', 'samples'))
    motion_gate_dead_zone: float = field(
        default=0.6, metadata=_doc(
            'with motion_gate: dead zone a of the gain g, used as clip((g − a)/(1 − a), 0, 1): '
            'the small gains of a vessel holding position are shut (no wave motion of the twin '
            'leaks through them), a move (g → 1) is not touched; in [0, 1), 0 = off'))
    motion_gate_fade_in: float = field(
        default=0.0, metadata=_doc(
            'with motion_gate: when the gate has first seen enough of the usual motion '
            '(GATE_MIN_FILL of the training window, core/motion_gate.py) its gains rise from 0 '
            'over this time instead of at once: the end of that warm-up falls, whenever it '
            'falls, in the middle of a move as easily as in calm, and the gain stepping 0 → 1 '
            'there put the whole twin offset into one sample (rao_supply 772, 782: 1.6–2.0 m, '
            '3.1–4.1× the largest true LF step; docs/BENCHMARKS.md forty-sixth session). '
            'Off by default: on rao_supply that warm-up ends inside the setpoint move on most '
            'seeds, and 10 s cost 8 % of its open-loop north error (30 s: 23 %); '
            '0 = at once', 's'))
    motion_gate_validation: bool = field(
        default=False, metadata=_doc(
            'with motion_gate: the gate acts on a DOF only while its output was closer to the '
            'targets of the last training window than the holding network alone (checked at '
            'every new target window; shut until the first check; core/motion_gate.py)'))
    motion_gate_yaw: bool = field(
        default=True, metadata=_doc(
            'with motion_gate and 3 DOF: the gate acts on the heading too; false: north and '
            "east only, the heading is the holding network's (the twin lets more of a swell's "
            'yaw motion through in turns)'))
    motion_gate_yaw_moment_ratio: float = field(
        default=5.0, metadata=_doc(
            "with motion_gate and motion_gate_yaw: the gate's heading gain comes from the "
            "applied yaw moment instead of the twin's velocity: 1 while |N| (low-passed over "
            '2 s) exceeds this many times its level (low-passed over 600 s; no gain during '
            'motion_gate_yaw_warmup), held motion_gate_yaw_hold, then faded to 0 over 10 s (a '
            'turn is known from the moment before the heading shows it; '
            'core/yaw_moment_trigger.py); '
            '0 = off (the velocity gain, as north and east)', ''))
    motion_gate_yaw_hold: float = field(
        default=30.0, metadata=_doc(
            'with motion_gate_yaw_moment_ratio: time the heading gain stays 1 after the yaw '
            'moment was last above its ratio', 's'))
    motion_gate_yaw_warmup: float = field(
        default=300.0, metadata=_doc(
            "with motion_gate_yaw_moment_ratio: no heading gain until the yaw moment's level "
            'has seen this much time (the level is the running mean of |N| for its first '
            "600 s); a turn inside the warm-up gets the holding network's lagging heading; "
            "300 s: the motion gate's own warm-up (GATE_MIN_FILL of its window)", 's'))
    motion_gate_yaw_network_level: bool = field(
        default=False, metadata=_doc(
            "with motion_gate_yaw_moment_ratio: the trigger's level and warm-up count only the "
            "yaw moments applied while the gate's twin serves from its network (as the gate's "
            "usual velocity does): a DP loop on the cascade fallback's estimates (before the "
            'first training) applies larger moments, which would keep the level above any turn '
            "for many minutes; false: every moment from the start"))
    motion_gate_yaw_notch: float = field(
        default=0.0, metadata=_doc(
            'with motion_gate and motion_gate_yaw: width ζ of a causal notch at the estimated '
            'ω0 (depth notch_depth) on the low-passed heading difference twin − holding before '
            "the gate scales it: the swell's yaw motion the twin lets through in turns stays "
            'out of the heading, a turn (slow) passes; 0 = off', ''))
    estimation_window: float = field(
        default=1200.0, metadata=_doc('frequency-estimation window γ (eq. 4.3)', 's'))
    retrain_period: float = field(
        default=60.0, metadata=_doc('time Δ between two trainings', 's'))
    training_window: float = field(
        default=1200.0, metadata=_doc('training window N (eq. 4.2)', 's'))
    transient_length: float = field(
        default=30.0, metadata=_doc('filter transient length ε (§4.2.2)', 's'))
    filter_window: float = field(
        default=180.0, metadata=_doc('filtered window α, α ≥ Δ + 2ε (eq. 4.4)', 's'))
    append_length: float = field(
        default=120.0, metadata=_doc('appending length β, Δ + ε ≤ β < α − ε (eq. 4.5)', 's'))
    highpass_cutoff: float = field(
        default=0.2, metadata=_doc('high-pass cutoff ωHP before the PSD (§4.2.1)', 'rad/s'))
    notch_zeta: float = field(
        default=0.8, metadata=_doc('notch width: relative damping of the notch poles', ''))
    notch_zeta_broadband: float = field(
        default=1.3, metadata=_doc(
            "with > 0: the targets' notch width in a broadband sea, one whose fitted spectral "
            'peak damping λ (core/frequency.py) is at least BROADBAND_PEAK_DAMPING (a JONSWAP '
            "sea ≈ 0.1; the thesis's shaping-filter seas ≈ 0.01 keep notch_zeta); still limited "
            'by notch_lower_edge; 0 = notch_zeta in every sea', ''))
    notch_broadband_holding_only: bool = field(
        default=True, metadata=_doc(
            'with notch_zeta_broadband: the broadband width only for a training window of '
            'station keeping; a window with a setpoint move or a turn (core/manoeuvre.py) keeps '
            'notch_zeta'))
    sea_change_confirm: str = field(
        default='manoeuvres', metadata=_doc(
            'never, turns, manoeuvres or always: a change of sea state (a new ω0 from the short '
            'window that restarts the training window) must also be seen by the short window one '
            'retrain period earlier, within the same ratio; always: every time (a real change is '
            'then taken one retrain period later), turns: only when the short window shows a '
            'turn, manoeuvres: a turn or a setpoint move (ndof 3; the LF motion of a manoeuvre '
            'looks like a new, lower wave peak)'))
    sea_change_revert: bool = field(
        default=True, metadata=_doc(
            'a change of sea state whose ω0 comes back within two retrain periods (within the '
            'same ratio of the ω0 before it) was not one: the targets before that restart are '
            'taken up again instead of restarting the window once more (the LF motion of a '
            'start-up or a manoeuvre briefly looks like a lower wave peak)'))
    notch_lower_edge: float = field(
        default=0.23, metadata=_doc(
            'with notch_zeta_broadband: the broadband notch is no wider than the width whose '
            'lower -3 dB edge ω0·(√(1 + ζ²) − ζ) is this frequency, ζ ≤ (1 − r²) / (2r), r = '
            'edge / ω0 (a swell keeps its notch out of the LF band), and never narrower than '
            'notch_zeta; 0 = no limit', 'rad/s'))
    fallback_notch_zeta: float = field(
        default=0.1, metadata=_doc('notch width of the causal cascade fallback (narrower than '
                                   "the targets' notch: less phase lag in a DP loop)", ''))
    notch_depth: float = field(
        default=0.05, metadata=_doc('notch depth: gain at the notch frequency (< 1)', ''))
    lowpass_offset: float = field(
        default=0.2, metadata=_doc('low-pass cutoff above the notch, ωLP = ω0 + offset '
                                   '(thesis Fig. 4.8)', 'rad/s'))
    wave_band: tuple[float, ...] = field(
        default=(0.25, 1.4), metadata=_doc('(low, high) band searched for ω0; thesis eq. 3.9 '
                                           'is 0.3–1.3, widened so edge peaks are interior',
                                           'rad/s'))
    min_peak_ratio: float = field(
        default=5.0, metadata=_doc('peak PSD over median in-band PSD for a clear peak', ''))
    frequency_yaw: bool = field(
        default=False, metadata=_doc(
            "ndof 3: the heading's spectrum takes part in the ω0 estimate; false: north and "
            "east only (a DP heading loop's bandwidth is typically twice the position loops', "
            'so its own closed-loop motion reaches the lower end of the wave band and passes '
            "for a wave peak: in the RAO loops ω0 was 0.25–0.44 against the sea's 0.48–0.63; "
            'false holds position 9–17 % better with less wave-band thrust, development seeds, '
            'docs/BENCHMARKS.md "Twenty-third session")'))
    hidden_units: int = field(default=0, metadata=_doc(
        'neurons per hidden layer; 0: the linear network (no tanh part, the linear ARX model on '
        'the same regressors, trained by one least-squares solve; the default: a tanh part of 2 '
        'units decays to zero under the weight penalty within about nine trainings and held '
        'position no better than the linear network in 40-seed loop screens of three vessels; '
        'on the 1-DOF thesis vessel without control it is about 9 % better, docs/BENCHMARKS.md '
        '"Thirty-first session")'))
    hidden_layers: int = field(default=1, metadata=_doc('hidden layers'))
    max_epochs: int = field(default=10, metadata=_doc('epochs per training'))
    max_train_seconds: float = field(
        default=20.0, metadata=_doc('wall-clock limit of one training', 's'))
    weight_decay: float = field(
        default=0.1, metadata=_doc('weight penalty of the tanh part (MSEREG, thesis eq. 2.8); '
                                   'nothing to act on with hidden_units 0', ''))
    derivative_weight: float = field(
        default=0.0, metadata=_doc('weight of the derivative-error loss term', ''))
    trainer: str = field(default='lm', metadata=_doc('training algorithm: lm, lbfgs or adam'))
    linear_init: bool = field(
        default=True, metadata=_doc('solve the linear bypass by least squares before each '
                                     'training (the network then refines a linear ARX model)'))
    wave_augmentation: float = field(
        default=0.0, metadata=_doc('RMS of the synthetic wave-band motion in the wave-invariance '
                                   'copy of the training window, relative to the measured wave '
                                   'motion; 0 = no copy (core/augmentation.py)', ''))
    thrust_validation: bool = field(
        default=False, metadata=_doc(
            'each retraining first tests on its window whether the thrust predicts the LF '
            'motion (an LF model fitted with the thrust must dead-reckon the newest third better '
            'than one fitted without it, core/lf_dynamics.py); if not, the network is trained '
            'without the thrust regressors (their weights 0)'))
    thrust_ridge_validation: bool = field(
        default=False, metadata=_doc(
            'linear network (hidden_units 0) only: the ridge on the thrust regressors is chosen '
            'per output, at each training, from a grid (1e-6 … 1e3 per row, standardized units) '
            'by the error on the newest retrain_period of the window of a fit on the rest, then '
            'refitted on all of it: the newest data decide how much the thrust is trusted (issue '
            '13, hypothesis 1)'))
    thrust_prior: float = field(
        default=0.0, metadata=_doc(
            "the least-squares fit's ridge on the thrust regressors, per row in standardized "
            "units, pulls them towards the network in service's instead of towards 0 "
            '(NnarmaxNet.fit_linear_bypass): a window whose thrust adds nothing to the positions '
            '(a DP loop without excitation, where the thrust is a function of the estimates) '
            'leaves the thrust weights where the earlier windows put them instead of setting '
            'them freely, which closed limit cycles at 0.45-0.52 rad/s with the DP controller '
            'on onedof_feedback (docs/BENCHMARKS.md, thirty-fifth session; issue 13, '
            'hypothesis 1); 0 = off (the plain ridge towards 0)', ''))
    thrust_hold: bool = field(
        default=False, metadata=_doc(
            'linear network (hidden_units 0) only: a retraining whose window shows no '
            'excitation (a network in service, a full training window seen, no setpoint move or '
            'turn in it by core/manoeuvre.py) keeps the thrust weights exactly at the network in '
            "service's and refits only the position weights and the bias given them: in station "
            'keeping the thrust is a function of the estimates and cannot identify its weights, '
            'while the wave part keeps adapting to the sea (issue 13, hypothesis 1; '
            'docs/BENCHMARKS.md, thirty-eighth and thirty-ninth sessions)'))
    north_east_decoupled: bool = field(
        default=True, metadata=_doc(
            "the north and east estimates are each fitted on their own DOF's thrust and "
            'position lags (and the bias), the heading on every regressor; in a turn the heading '
            'lags and the yaw moment then no longer reach the north/east estimate, where they put '
            'metres of error and tripped the sanity guard (issue 13; docs/BENCHMARKS.md, '
            'forty-second and forty-third sessions; the default since the forty-third; false = '
            'every output fitted on every regressor, as before). It acts on the plain '
            'least-squares solve of the linear network with ndof 3 only: with ndof 1, a tanh '
            'part (hidden_units > 0), derivative_weight > 0, parallel training with nfb > 0, '
            'thrust_hold, thrust_prior > 0 or thrust_ridge_validation the outputs stay coupled '
            'as before'))
    regressor_clip: float = field(
        default=0.0, metadata=_doc(
            'clip every regressor the network sees (relative positions, forces) and its output '
            'step to their range in the training window, widened this many times about its '
            'centre: a turn or a move beyond what the window showed reaches the network as the '
            'largest values it was fitted on, never as an extrapolation; 0 = off, else ≥ 1 (off '
            'by default: better open loop, more wave-band thrust in the loop)', ''))
    lf_augmentation: tuple[float, ...] = field(
        default=(0.0, 0.0, 0.0), metadata=_doc(
            'RMS velocity of the synthetic LF motion (below the DP bandwidth) added to the '
            'positions and the targets of a copy of the training window, so the filter follows '
            'LF motion (setpoint moves, turns) station keeping never showed it; 0 = no copy '
            '(core/augmentation.py)', 'm/s, m/s, rad/s'))
    training_mode: str = field(
        default='series_parallel', metadata=_doc('series_parallel or parallel (BPTT)'))
    seed: int = field(default=0, metadata=_doc('seed of the network initialization'))
    initial_wave_peak_freq: float = field(
        default=0.0, metadata=_doc('prior ω0 before the first estimate; 0 = none', 'rad/s'))
    switch_blend_time: float = field(
        default=0.0, metadata=_doc('bumpless transfer: when the output changes source (cascade '
                                   'fallback ↔ network, old → new network) it moves from the '
                                   "old source's value to the new one's over this time, "
                                   'smoothly, both running; 0 = off (the output switches at '
                                   'once)', 's'))
    output_notch_zeta: float = field(
        default=0.0, metadata=_doc(
            'width (relative damping of the poles) of a causal notch at the estimated wave peak '
            'frequency ω0, depth notch_depth, on the published estimate: it removes the wave '
            'peak the learned filter lets through (in a DP loop, wave-band thrust) at a phase '
            'lag of about 2·ζ/ω0 seconds in the LF band; 0 = off (core/predictor.py)', ''))
    guard_floor: tuple[float, ...] = field(
        default=(0.5, 0.5, 0.1), metadata=_doc(
            'floor of the sanity guard (north, east, yaw): a network prediction farther from '
            'the newest measurement than 6 × the RMS wave motion of its training window plus '
            'this is not believed and the cascade fallback stands in (the heading floor lets a '
            "turn's lag pass without switching the heading's source)", 'm, m, rad'))
    max_output_rate: tuple[float, ...] = field(
        default=(0.0, 0.0, 0.0), metadata=_doc(
            'largest rate of change of the published estimate (north, east, yaw); set it above '
            'the fastest LF motion; 0 = no limit on that DOF', 'm/s, m/s, rad/s'))
    roughness_guard_time: float = field(
        default=30.0, metadata=_doc(
            "roughness guard (core/roughness.py): while the network prediction's squared second "
            "differences, averaged over this time, exceed 50× (ROUGHNESS_RATIO) the measured "
            "pose's in any DOF, the network in service is no LF filter (a limit cycle through "
            'the thrust regressors in a DP loop): it is retired and the network before it '
            'serves (a second trip: the cascade fallback) until the next accepted training; '
            '0 = off, else > sample_time', 's'))

    def __post_init__(self) -> None:
        """Coerce numbers to their field types and check every rule (raises ValueError)."""
        self._coerce_types()
        self._check_positive()
        self._check_choices()
        self._check_frequencies()
        self._check_windows()

    # ---- conversions -------------------------------------------------------------------------

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> PredictorParams:
        """Build from a mapping (YAML, ROS parameters); unknown keys raise ValueError."""
        unknown = sorted(set(values) - set(cls.field_names()))
        if unknown:
            raise ValueError(f'unknown PredictorParams key(s) {unknown}: valid keys are '
                             f'{list(cls.field_names())}')
        return cls(**dict(values))

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (wave_band as a list) that ``from_dict`` turns back into an equal object."""
        values = asdict(self)
        for name in _TUPLE_FIELDS:
            values[name] = list(getattr(self, name))
        return values

    def replace(self, **changes: Any) -> PredictorParams:
        """Copy with ``changes`` applied and every rule checked again."""
        unknown = sorted(set(changes) - set(self.field_names()))
        if unknown:
            raise ValueError(f'unknown PredictorParams key(s) {unknown}: valid keys are '
                             f'{list(self.field_names())}')
        return dataclass_replace(self, **changes)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of all parameters, in declaration order."""
        return tuple(f.name for f in fields(cls))

    # ---- derived quantities ------------------------------------------------------------------

    @property
    def trained_by_least_squares(self) -> bool:
        """One least-squares solve is the whole training (training._solved_by_least_squares).

        The linear network (hidden_units 0), no derivative term, no recursion through fed-back
        outputs (parallel training with nfb > 0).
        """
        return self.hidden_units == 0 and self.derivative_weight == 0.0 and not (
            self.training_mode == 'parallel' and self.nfb > 0)

    @property
    def decouples_north_east(self) -> bool:
        """``north_east_decoupled`` and a training it acts on (see the field's description)."""
        other_rule = self.thrust_hold or self.thrust_prior > 0.0 or self.thrust_ridge_validation
        return (self.north_east_decoupled and self.ndof == 3 and self.trained_by_least_squares
                and not other_rule)

    @property
    def estimation_samples(self) -> int:
        """γ in samples."""
        return self._samples(self.estimation_window)

    @property
    def retrain_samples(self) -> int:
        """Δ in samples."""
        return self._samples(self.retrain_period)

    @property
    def training_samples(self) -> int:
        """N in samples."""
        return self._samples(self.training_window)

    @property
    def transient_samples(self) -> int:
        """ε in samples."""
        return self._samples(self.transient_length)

    @property
    def filter_samples(self) -> int:
        """α in samples."""
        return self._samples(self.filter_window)

    @property
    def append_samples(self) -> int:
        """β in samples."""
        return self._samples(self.append_length)

    @property
    def max_lag(self) -> int:
        """Longest regressor, max(nu, ny, nfb) [samples]."""
        return max(self.nu, self.ny, self.nfb)

    @property
    def nyquist_freq(self) -> float:
        """Nyquist frequency π / h [rad/s]."""
        return math.pi / self.sample_time

    @property
    def wave_peak_prior(self) -> float | None:
        """The prior ω0 [rad/s], or None when ``initial_wave_peak_freq`` is 0."""
        return self.initial_wave_peak_freq if self.initial_wave_peak_freq > 0.0 else None

    def target_notch_zeta(self, notch_freq: float, peak_damping: float = math.nan) -> float:
        """Width ζ of the targets' notch at ω0 = ``notch_freq`` [rad/s].

        ``notch_zeta``; in a broadband sea (``notch_zeta_broadband`` on and the fitted peak
        damping ``peak_damping``, `frequency.FrequencyEstimate.peak_damping`, at least
        ``BROADBAND_PEAK_DAMPING``; NaN: unknown, not broadband) the wider
        ``notch_zeta_broadband``, but (with ``notch_lower_edge`` > 0) no wider than the width
        whose lower −3 dB edge is ``notch_lower_edge``, and never narrower than ``notch_zeta``.
        The edges of the notch (s² + ω0²)/(s² + 2ζω0 s + ω0²) lie at ω0(√(1 + ζ²) ∓ ζ); the
        lower one is at ω_e for ζ = (1 − r²)/(2r), r = ω_e/ω0.
        """
        if not (self.notch_zeta_broadband > 0.0 and peak_damping >= BROADBAND_PEAK_DAMPING):
            return self.notch_zeta
        wide = self.notch_zeta_broadband
        if self.notch_lower_edge > 0.0:
            ratio = self.notch_lower_edge / notch_freq
            wide = min(wide, (1.0 - ratio * ratio) / (2.0 * ratio))
        return max(self.notch_zeta, wide)

    def lowpass_cutoff(self, notch_freq: float) -> float:
        """ωLP = ωnotch + lowpass_offset [rad/s] (thesis Fig. 4.8)."""
        return notch_freq + self.lowpass_offset

    def _samples(self, seconds: float) -> int:
        return int(round(seconds / self.sample_time))

    # ---- validation --------------------------------------------------------------------------

    def _coerce_types(self) -> None:
        for name in _INT_FIELDS:
            value = getattr(self, name)
            if isinstance(value, bool) or not _is_integral(value):
                raise ValueError(f'{name} must be an integer, got {value!r}')
            object.__setattr__(self, name, int(value))
        for name in _BOOL_FIELDS:
            value = getattr(self, name)
            if not isinstance(value, bool):
                raise ValueError(f'{name} must be true or false, got {value!r}')
        for f in fields(self):
            if f.name in (*_INT_FIELDS, *_STR_FIELDS, *_BOOL_FIELDS, *_TUPLE_FIELDS):
                continue
            object.__setattr__(self, f.name, _finite_float(f.name, getattr(self, f.name)))
        band = self.wave_band
        if isinstance(band, (str, bytes)) or len(band) != 2:
            raise ValueError(f'wave_band must be two numbers (low, high) in rad/s, got {band!r}')
        object.__setattr__(self, 'wave_band',
                           tuple(_finite_float('wave_band', edge) for edge in band))
        for name, units in (('max_output_rate', '[north m/s, east m/s, yaw rad/s] (0 = no limit)'),
                            ('guard_floor', '[north m, east m, yaw rad]'),
                            ('lf_augmentation', '[north m/s, east m/s, yaw rad/s] (0 = off)')):
            object.__setattr__(self, name, _three_floats(name, getattr(self, name), units))

    def _check_positive(self) -> None:
        for name in ('sample_time', *_WINDOW_FIELDS, 'highpass_cutoff', 'notch_zeta',
                     'fallback_notch_zeta',
                     'lowpass_offset', 'max_train_seconds', 'motion_gate_time'):
            if not getattr(self, name) > 0.0:
                raise ValueError(f'positivity rule: {name} must be > 0, got '
                                 f'{getattr(self, name)!r}: give a positive value')
        for name in ('weight_decay', 'derivative_weight', 'initial_wave_peak_freq',
                     'wave_augmentation', 'switch_blend_time', 'motion_gate_smoothing',
                     'output_notch_zeta', 'notch_lower_edge', 'notch_zeta_broadband',
                     'motion_gate_yaw_notch', 'motion_gate_yaw_moment_ratio',
                     'motion_gate_yaw_hold', 'motion_gate_yaw_warmup',
                     'motion_gate_fade_in'):
            if getattr(self, name) < 0.0:
                raise ValueError(f'positivity rule: {name} must be ≥ 0, got '
                                 f'{getattr(self, name)!r}')
        if not (math.isfinite(self.thrust_prior) and self.thrust_prior >= 0.0):
            raise ValueError(f'positivity rule: thrust_prior must be a finite number ≥ 0 (0 = '
                             f'off), got {self.thrust_prior!r}')
        if self.thrust_prior > 0.0 and self.thrust_ridge_validation:
            raise ValueError('thrust_prior and thrust_ridge_validation both set the thrust '
                             "weights' ridge: switch one of them off")
        if any(speed < 0.0 for speed in self.lf_augmentation):
            raise ValueError(f'positivity rule: lf_augmentation must be ≥ 0 in every DOF (0 = '
                             f'off), got {list(self.lf_augmentation)!r}')
        if self.roughness_guard_time != 0.0 and not self.roughness_guard_time > self.sample_time:
            raise ValueError(f'positivity rule: roughness_guard_time must be 0 (off) or > '
                             f'sample_time {self.sample_time} s, got '
                             f'{self.roughness_guard_time!r}')
        if any(value < 0.0 for value in self.guard_floor):
            raise ValueError(f'positivity rule: guard_floor must be ≥ 0 in every DOF, got '
                             f'{list(self.guard_floor)!r}')
        if any(rate < 0.0 for rate in self.max_output_rate):
            raise ValueError(f'positivity rule: max_output_rate must be ≥ 0 in every DOF (0 = no '
                             f'limit), got {list(self.max_output_rate)!r}')
        if self.regressor_clip != 0.0 and not self.regressor_clip >= 1.0:
            raise ValueError(f'regressor_clip must be 0 (off) or ≥ 1 (the training range '
                             f'widened that many times), got {self.regressor_clip!r}')
        for name in ('nu', 'ny', 'nfb'):
            if getattr(self, name) < 0:
                raise ValueError(f'positivity rule: {name} must be ≥ 0 (number of delays), got '
                                 f'{getattr(self, name)!r}')
        if self.ny + self.nfb < 1:
            raise ValueError(f'regressor rule: ny + nfb must be ≥ 1 (the network must see a '
                             f'position, thesis §4.4), got ny = {self.ny}, nfb = {self.nfb}')
        if self.hidden_units < 0:
            raise ValueError(f'positivity rule: hidden_units must be ≥ 0 (0: the linear network, '
                             f'no tanh part), got {self.hidden_units!r}')
        if self.thrust_ridge_validation and self.hidden_units != 0:
            raise ValueError('thrust_ridge_validation needs the linear network (hidden_units 0, '
                             f'got {self.hidden_units}): set hidden_units 0 or switch it off')
        if self.thrust_hold:
            self._check_thrust_hold()
        for name in ('hidden_layers', 'max_epochs'):
            if getattr(self, name) < 1:
                raise ValueError(f'positivity rule: {name} must be ≥ 1, got '
                                 f'{getattr(self, name)!r}')
        for name in _WINDOW_FIELDS:
            if self._samples(getattr(self, name)) < 1:
                raise ValueError(f'{name} = {getattr(self, name)} s is shorter than one sample '
                                 f'(sample_time {self.sample_time} s): lengthen it')
        if not 0.0 < self.notch_depth < 1.0:
            raise ValueError(f'notch depth rule: notch_depth must lie in (0, 1) (gain at the '
                             f'notch frequency), got {self.notch_depth!r}')
        if not self.min_peak_ratio > 1.0:
            raise ValueError(f'peak ratio rule: min_peak_ratio must exceed 1 (a peak above the '
                             f'band median), got {self.min_peak_ratio!r}')

    def _check_thrust_hold(self) -> None:
        """``thrust_hold`` needs one least-squares solve and no other rule on the thrust."""
        if not self.trained_by_least_squares:
            raise ValueError('thrust_hold needs the linear network solved by least squares '
                             '(hidden_units 0, derivative_weight 0, no parallel training with '
                             'nfb > 0): change those or switch thrust_hold off')
        for other in ('thrust_validation', 'thrust_ridge_validation'):
            if getattr(self, other):
                raise ValueError(f'thrust_hold and {other} both decide the thrust weights per '
                                 'window: switch one of them off')

    def _check_choices(self) -> None:
        if self.ndof not in NDOF_VALUES:
            raise ValueError(f'ndof rule: ndof must be 1 or 3, got {self.ndof!r}')
        if self.trainer not in TRAINERS:
            raise ValueError(f'trainer rule: trainer must be one of {TRAINERS}, got '
                             f'{self.trainer!r}')
        if self.training_mode not in TRAINING_MODES:
            raise ValueError(f'training mode rule: training_mode must be one of '
                             f'{TRAINING_MODES}, got {self.training_mode!r}')
        if self.sea_change_confirm not in SEA_CHANGE_CONFIRMS:
            raise ValueError(f'sea change rule: sea_change_confirm must be one of '
                             f'{SEA_CHANGE_CONFIRMS}, got {self.sea_change_confirm!r}')
        self._check_regressor_frame()
        self._check_ramp()
        if self.max_train_seconds > self.retrain_period:
            raise ValueError(
                f'training time rule: max_train_seconds = {self.max_train_seconds} s exceeds '
                f'retrain_period Δ = {self.retrain_period} s: one training must end before the '
                'next is due; lower max_train_seconds or raise retrain_period')

    def _check_regressor_frame(self) -> None:
        if self.regressor_frame not in REGRESSOR_FRAMES:
            raise ValueError(f'regressor frame rule: regressor_frame must be one of '
                             f'{REGRESSOR_FRAMES}, got {self.regressor_frame!r}: use earth (the '
                             'default) or body')
        if self.regressor_frame == 'body' and self.ndof != 3:
            raise ValueError(f'regressor frame rule: regressor_frame body rotates north/east '
                             f'into the body frame and needs ndof 3, got ndof {self.ndof}: set '
                             'ndof 3 or regressor_frame earth')
        if self.regressor_frame == 'body' and self.training_mode == 'parallel' and self.nfb > 0:
            raise ValueError('regressor frame rule: regressor_frame body has no parallel (free '
                             'run) training with LF feedback: set training_mode '
                             'series_parallel, nfb 0 or regressor_frame earth')

    def _check_ramp(self) -> None:
        if self.motion_gate and self.ramp_invariant:
            raise ValueError('ramp rule: motion_gate blends a plain (holding) network with a '
                             'ramp-invariant twin of it: set ramp_invariant false, or '
                             'motion_gate false for a ramp-invariant network alone')
        if (self.ramp_invariant or self.motion_gate) and (self.nfb > 0 or self.ny < 2):
            raise ValueError(f'ramp rule: ramp_invariant and motion_gate fit a line through the '
                             f'measured positions and need ny ≥ 2 and nfb 0, got ny {self.ny}, '
                             f'nfb {self.nfb}: change them or set both false')
        if not 0.0 <= self.motion_gate_dead_zone < 1.0:
            raise ValueError(f'ramp rule: motion_gate_dead_zone must be in [0, 1) (0 = off), got '
                             f'{self.motion_gate_dead_zone}')
        if self.motion_gate_ny == 1 or self.motion_gate_ny < 0:
            raise ValueError(f'ramp rule: motion_gate_ny is the ny of the twin (a line needs ≥ 2 '
                             f'positions) or 0 for ny, got {self.motion_gate_ny}')
        if self.ramp_order not in RAMP_ORDERS:
            raise ValueError(f'ramp rule: ramp_order must be one of {RAMP_ORDERS} (1 line, 2 '
                             f'parabola), got {self.ramp_order}')
        ramp_ny = self.motion_gate_ny or self.ny
        if (self.ramp_invariant or self.motion_gate) and ramp_ny < self.ramp_order + 1:
            raise ValueError(f'ramp rule: ramp_order {self.ramp_order} fits a polynomial through '
                             f'the ny positions of the ramp-invariant network and needs at least '
                             f'{self.ramp_order + 1}, got {ramp_ny}: raise ny (motion_gate_ny) or '
                             'lower ramp_order')

    def _check_frequencies(self) -> None:
        low, high = self.wave_band
        nyquist = self.nyquist_freq
        if not 0.0 < low < high:
            raise ValueError(f'wave band rule: wave_band must satisfy 0 < low < high, got '
                             f'{self.wave_band!r} rad/s: order the edges')
        if not high + self.lowpass_offset < nyquist:
            raise ValueError(
                f'Nyquist rule: wave_band high {high} + lowpass_offset {self.lowpass_offset} = '
                f'{high + self.lowpass_offset:.4g} rad/s must stay below π/sample_time = '
                f'{nyquist:.4g} rad/s: sample faster or narrow the band')
        if not self.highpass_cutoff < high:
            raise ValueError(
                f'high-pass rule: highpass_cutoff ωHP = {self.highpass_cutoff} rad/s must lie '
                f'below or inside the wave band {self.wave_band!r} (thesis §4.2.1): lower it')
        prior = self.wave_peak_prior
        if prior is not None and not low <= prior <= high:
            raise ValueError(f'prior rule: initial_wave_peak_freq = {prior} rad/s lies outside '
                             f'the wave band {self.wave_band!r}: use a value inside it or 0 '
                             '(no prior)')

    def _check_windows(self) -> None:
        delta, eps = self.retrain_samples, self.transient_samples
        alpha, beta = self.filter_samples, self.append_samples
        n_train, gamma = self.training_samples, self.estimation_samples
        h = self.sample_time
        if alpha < delta + 2 * eps:
            raise ValueError(
                f'rule α ≥ Δ + 2ε (thesis eq. 4.4): filter_window α = {alpha * h:g} s is shorter '
                f'than retrain_period Δ + 2 × transient_length ε = {delta * h:g} + 2 × '
                f'{eps * h:g} s: raise filter_window to at least {(delta + 2 * eps) * h:g} s')
        if beta < delta + eps:
            raise ValueError(
                f'rule Δ + ε ≤ β (thesis eq. 4.5): append_length β = {beta * h:g} s is shorter '
                f'than retrain_period Δ + transient_length ε = {(delta + eps) * h:g} s, so the '
                'transient at the end of the old targets would stay: raise append_length')
        if beta >= alpha - eps:
            raise ValueError(
                f'rule β < α − ε (thesis eq. 4.5): append_length β = {beta * h:g} s reaches '
                f'into the start transient of the filtered window (α − ε = '
                f'{(alpha - eps) * h:g} s): lower append_length or raise filter_window')
        if n_train < alpha:
            raise ValueError(
                f'rule N ≥ α: training_window N = {n_train * h:g} s is shorter than '
                f'filter_window α = {alpha * h:g} s: raise training_window')
        needed = eps + self.max_lag + MIN_TRAINING_EXAMPLES
        if n_train < needed:
            raise ValueError(
                f'rule N ≥ ε + max regressor + {MIN_TRAINING_EXAMPLES}: training_window N has '
                f'{n_train} samples, needs {needed} (ε {eps}, regressors {self.max_lag}): raise '
                'training_window or shorten the regressors')
        resolution = welch_resolution(gamma, h)
        max_bin = MAX_BIN_FRACTION_OF_BAND * (self.wave_band[1] - self.wave_band[0])
        if resolution > max_bin:
            raise ValueError(
                f'spectral resolution rule: estimation_window γ = {gamma * h:g} s gives a Welch '
                f'bin of {resolution:.3g} rad/s, more than 1/20 of the wave band width '
                f'({max_bin:.3g} rad/s): raise estimation_window')


def _is_integral(value: Any) -> bool:
    """True for ints and for floats with an integer value (YAML may give 2.0)."""
    if isinstance(value, numbers.Integral):
        return True
    return isinstance(value, float) and math.isfinite(value) and value.is_integer()


def _three_floats(name: str, values: Any, units: str) -> tuple[float, ...]:
    """``values`` as a tuple of three finite floats, else ValueError naming the parameter."""
    if isinstance(values, (str, bytes)) or not hasattr(values, '__len__') or len(values) != 3:
        raise ValueError(f'{name} must be three numbers {units}, got {values!r}')
    return tuple(_finite_float(name, value) for value in values)


def _finite_float(name: str, value: Any) -> float:
    """``value`` as a finite float, else ValueError naming the parameter."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f'{name} must be a number, got {value!r}')
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f'{name} must be finite, got {value!r}')
    return number
