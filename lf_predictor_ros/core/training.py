"""Model-agnostic trainer for regressor networks (thesis §2.2.2–2.2.3, §4.3, Alg. 4.1 l. 36–40).

In the spirit of karpathy/minGPT's trainer, this module knows nothing about layers. It needs a
``torch.nn.Module`` with a ``spec`` (``nu``, ``ny``, ``nfb``, ``n_outputs``, ``n_inputs_u``) whose
``forward`` maps raw regressor rows (``regressors.build_regressors`` layout) to the next LF
position, a ``free_run(x_static, fb_init)`` for the parallel mode and, when
``TrainSettings.standardize`` is on, a ``set_standardization(u, y)`` method (``NnarmaxNet`` has
all three).

Objective (thesis eq. 2.6 and 2.8 with a = 1, b = ``weight_decay``, plus our derivative term):

    J(w) = MSE + d · MSE_Δ + b · Σ w_j²   (sum over the tanh part: the linear bypass is free)
    MSE   = mean over kept samples and channels of ((ŷLF(t+1) − yT(t+1)) / s)²
    MSE_Δ = mean over kept consecutive pairs of ((Δŷ − ΔyT) / s_Δ)²,  Δx(t+1) = x(t+1) − x(t)

s is the per-channel scale of what the network predicts (``loss_scale``: the std of the kept
targets, or for a relative network the RMS of yT(t+1) − y(t)) and s_Δ the RMS of the targets' first
differences, so the loss is dimensionless, treats metres and radians alike and is comparable
between candidate networks on the same window. For a body-frame network (``spec.body_frame``) the
errors, steps and differences are taken in the body frame of the row's newest heading ψ(t) (north
and east rotated by R(ψ(t))ᵀ) before scaling, so s is per surge/sway and the loss is rotation
invariant like the network. The derivative term answers the thesis's closed-loop
failure (§5.4.2: the prediction's derivative had the wrong sign, so a PID's D-term steered with the
waves). Samples with ``mask`` False (the last ε, thesis Algorithm 4.1 line 38) contribute no error.

Modes (thesis §2.3; Narendra & Parthasarathy 1990):
- ``series_parallel``: the feedback regressors are the targets yT: a feed-forward problem.
- ``parallel``: the feedback regressors are the network's own predictions, unrolled over the
  window from yT at the first row; gradients go through the whole recursion (backpropagation
  through time for L-BFGS/Adam, dynamic backpropagation for the LM Jacobian). Train
  series-parallel first and warm-start the parallel run: from an untrained network and a short
  window LM can settle in a poor, unstable local minimum (seen with 300 samples, not with 600).

Algorithms:
- ``lm``: Levenberg–Marquardt, thesis eq. 2.7, w ← w − (JᵀJ + μI)⁻¹ Jᵀε, with the residual vector
  ε = [√(1/N)·e; √(d/N_Δ)·e_Δ; √b·w] so that ‖ε‖² = J(w); μ adapts as in MATLAB ``trainlm``
  (× ``lm_mu_dec`` after a successful step, × ``lm_mu_inc`` until a step succeeds). The Jacobian
  comes from per-row reverse-mode Jacobians (``vmap(jacrev)``) and, in parallel mode, the
  dynamic-backpropagation recursion through the feedback (see ``_prediction_jacobian``).
- ``lbfgs``: ``torch.optim.LBFGS`` with strong-Wolfe line search, one iteration per epoch.
- ``adam``: full-batch Adam, one step per epoch.

Training never modifies the network passed in: it deep-copies it, warm-starts from its weights and
returns a new state_dict. It honours ``max_epochs``, ``max_seconds`` (wall time) and a
``threading.Event``, checked between epochs and between LM damping retries. It runs torch on one
thread (``torch.set_num_threads(1)``, restored afterwards) because the predict path and the other
processes share the cores. Call ``warm_up()`` once at start-up: the first Jacobian makes torch
import ``torch._dynamo`` (≈ 2 s, holding the GIL), which must not happen in the first retraining.

It also runs with subnormal floats flushed to zero on its thread (the CPU's FTZ/DAZ modes,
``torch.set_flush_denormal``; restored afterwards). Weight decay, warm-started from one training
to the next, shrinks the weights of hidden units that the data do not use geometrically, until
they are subnormal (below 2.2e-308): then every product with them, and with the tanh of the
rows they feed, takes a slow path in the CPU. In a 2 h replay nine LM iterations in ten had
such weights, and the training took half the replay's time. A subnormal term added to a normal
number does not change it, so the estimates do not change: the same to the bit in that replay and
in the benchmark's cases (docs/BENCHMARKS.md, thirtieth session). The weights that were subnormal
come out as exact zeros.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
import copy
from dataclasses import dataclass
import math
import threading
import time
from typing import Literal, NamedTuple, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
import torch
from torch.func import functional_call, jacrev, vmap

from lf_predictor_ros.core.network import (
    LINEAR_RIDGE,
    NnarmaxNet,
    NnarmaxSpec,
    _relative_frame_torch,
    rotate_blocks_torch,
    solve_ridge,
)
from lf_predictor_ros.core.regressors import (
    as_series,
    build_regressors,
    n_static_regressors,
    rotate_blocks,
)

FloatArray = NDArray[np.float64]
Algorithm = Literal['lm', 'lbfgs', 'adam']
BASE_RIDGE = LINEAR_RIDGE  # every column's ridge but the thrust's (validated_force_ridges)
Mode = Literal['series_parallel', 'parallel']

_ALGORITHMS = ('lm', 'lbfgs', 'adam')
_MODES = ('series_parallel', 'parallel')
_SCALE_FLOOR = 1e-12  # [-] relative floor below which a target channel is not normalized


@dataclass(frozen=True)
class TrainSettings:
    """Hyper-parameters of one training run (thesis §4.3, Table A.x).

    ``weight_decay`` is b of eq. 2.8 (on the weights and biases of the tanh part, standardized
    units; the linear bypass is not penalized, see ``decay_vector``);
    ``derivative_weight`` is d of the derivative term; ``lm_mu0``/``lm_mu_inc``/``lm_mu_dec``/
    ``lm_mu_max`` drive eq. 2.7 (MATLAB ``trainlm`` defaults); ``lr`` is Adam's step size;
    ``min_grad`` stops when ‖∇J‖ falls below it; ``loss_goal`` stops when the MSE part reaches it;
    ``standardize`` re-computes the input/output standardization from the window (exactly
    function-preserving, so the warm start is kept); ``linear_init`` solves the linear bypass by
    least squares before the first epoch (``NnarmaxNet.fit_linear_bypass``);
    ``force_ridge_grid`` (linear network only; empty: off) the ridges per row on the force
    columns to choose from, per output, by the error on the newest ``validation_rows`` kept rows
    of a fit on the others (``validated_force_ridges``); ``force_prior`` > 0 the force
    columns' ridge per row towards the warm start's weights in the least-squares solve
    (``NnarmaxNet.fit_linear_bypass``; 0: ``LINEAR_RIDGE`` towards 0); ``hold_forces`` (the
    linear network solved by least squares only) keeps the force weights exactly at the warm
    start's and solves the rest given them; ``north_east_decoupled`` (the linear network
    solved by least squares only; no effect with one output) solves the north and east outputs
    each on its own DOF's columns (``NnarmaxNet.fit_linear_bypass``); ``seed`` is
    recorded for stochastic variants (mini-batches, restarts): the three full-batch algorithms
    here use no randomness, so a run is reproducible bit for bit without touching torch's global
    RNG.
    """

    algorithm: Algorithm = 'lm'
    mode: Mode = 'series_parallel'
    max_epochs: int = 100
    max_seconds: float = 10.0
    weight_decay: float = 0.0
    derivative_weight: float = 0.0
    lm_mu0: float = 1e-3
    lm_mu_inc: float = 10.0
    lm_mu_dec: float = 0.1
    lm_mu_max: float = 1e10
    lr: float = 1e-2
    min_grad: float = 1e-10
    loss_goal: float = 0.0
    standardize: bool = True
    linear_init: bool = False
    seed: int = 0
    force_ridge_grid: tuple[float, ...] = ()
    validation_rows: int = 0
    force_prior: float = 0.0
    hold_forces: bool = False
    north_east_decoupled: bool = False

    def __post_init__(self) -> None:
        """Validate; raise ValueError naming the broken rule."""
        if self.algorithm not in _ALGORITHMS:
            raise ValueError(f'TrainSettings.algorithm must be one of {_ALGORITHMS}, got '
                             f'{self.algorithm!r}')
        if self.mode not in _MODES:
            raise ValueError(f'TrainSettings.mode must be one of {_MODES}, got {self.mode!r}')
        epochs = self.max_epochs
        if isinstance(epochs, bool) or not isinstance(epochs, int) or epochs < 0:
            raise ValueError(f'TrainSettings.max_epochs must be an int ≥ 0, got {epochs!r}')
        if not self.max_seconds > 0.0:
            raise ValueError(
                f'TrainSettings.max_seconds must be > 0 s (math.inf for no limit), got '
                f'{self.max_seconds}'
            )
        for name in ('weight_decay', 'derivative_weight', 'min_grad', 'loss_goal', 'force_prior'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'TrainSettings.{name} must be a finite number ≥ 0, got {value}')
        if not (math.isfinite(self.lm_mu0) and self.lm_mu0 > 0.0):
            raise ValueError(f'TrainSettings.lm_mu0 must be > 0, got {self.lm_mu0}')
        if not (self.lm_mu_inc > 1.0 and 0.0 < self.lm_mu_dec < 1.0):
            raise ValueError(
                'TrainSettings needs lm_mu_inc > 1 and 0 < lm_mu_dec < 1 (μ grows after a failed '
                f'step, shrinks after a good one), got {self.lm_mu_inc}, {self.lm_mu_dec}'
            )
        if not self.lm_mu_max > self.lm_mu0:
            raise ValueError(
                f'TrainSettings.lm_mu_max must exceed lm_mu0, got {self.lm_mu_max} ≤ {self.lm_mu0}'
            )
        if not (math.isfinite(self.lr) and self.lr > 0.0):
            raise ValueError(f'TrainSettings.lr must be > 0, got {self.lr}')
        if any(not (math.isfinite(r) and r > 0.0) for r in self.force_ridge_grid):
            raise ValueError('TrainSettings.force_ridge_grid must hold finite ridges > 0, got '
                             f'{self.force_ridge_grid}')
        if self.force_ridge_grid and self.validation_rows < 1:
            raise ValueError('TrainSettings.force_ridge_grid needs validation_rows ≥ 1 (the '
                             f'newest rows that choose the ridge), got {self.validation_rows}')
        if self.hold_forces and self.force_ridge_grid:
            raise ValueError('TrainSettings.hold_forces and force_ridge_grid both set the force '
                             'weights: give one of them')
        if self.north_east_decoupled and (self.hold_forces or self.force_ridge_grid or
                                          self.force_prior > 0.0):
            raise ValueError('TrainSettings.north_east_decoupled solves each output on its own '
                             'columns and does not combine with hold_forces, force_ridge_grid '
                             'or force_prior: give one of them')


@dataclass(frozen=True)
class TrainResult:
    """Outcome of ``train``.

    ``state_dict``: the trained weights and standardization (load into a net of the same spec);
    ``loss``/``initial_loss``: MSE part of the objective on the masked window after/before;
    ``epochs``: completed epochs (LM: accepted or attempted weight updates); ``seconds``: wall
    time; ``converged``: stopped because a convergence criterion held; ``stopped_reason``: one of
    'max_epochs', 'max_seconds', 'stop_event', 'loss_goal', 'min_grad', 'mu_max', 'non_finite',
    'least_squares' (the linear network, solved exactly, ``epochs`` 0);
    ``loss_history``: MSE part after every epoch; ``objective``/``initial_objective``: the full
    objective J(w) (with derivative and weight-decay terms) after/before. Never
    ``objective > initial_objective``; the MSE part alone may rise when d or b > 0.
    """

    state_dict: dict[str, torch.Tensor]
    loss: float
    initial_loss: float
    epochs: int
    seconds: float
    converged: bool
    stopped_reason: str
    loss_history: tuple[float, ...] = ()
    objective: float = math.nan
    initial_objective: float = math.nan


@dataclass(frozen=True)
class _Window:
    """Training window as tensors, prepared once per run."""

    x_series: torch.Tensor  # (rows, n_reg) regressors with the targets as feedback
    fb_init: torch.Tensor  # (nfb, n_out) targets at first−nfb+1 … first (oldest first)
    target: torch.Tensor  # (rows − 1, n_out) yT(t + 1) for row t
    keep: torch.Tensor  # (rows − 1,) bool: target counts
    keep_pair: torch.Tensor  # (rows − 2,) bool: both targets of a difference count
    scale: torch.Tensor  # (n_out,) loss normalization (``loss_scale``)
    diff_scale: torch.Tensor  # (n_out,) RMS of kept target differences
    first: int
    # body-frame networks: (cos ψ(t), sin ψ(t)) of each target row's newest heading, (rows − 1,)
    body: tuple[torch.Tensor, torch.Tensor] | None = None


class _WindowPredictor(torch.nn.Module):
    """Runs a regressor network over a window, series-parallel (batch) or parallel (unrolled)."""

    def __init__(self, net: NnarmaxNet, n_static: int, nfb: int) -> None:
        """Wrap ``net``; the feedback block is the last ``nfb`` lag blocks of a regressor row."""
        super().__init__()
        self.net = net
        self.n_static = n_static
        self.nfb = nfb

    def forward(
        self, x_series: torch.Tensor, fb_init: torch.Tensor, parallel: bool
    ) -> torch.Tensor:
        """Predictions ŷLF(t + 1) for every row t of the window, shape (rows, n_out)."""
        if not parallel or self.nfb == 0:
            prediction: torch.Tensor = self.net(x_series)
            return prediction
        free_run: torch.Tensor = self.net.free_run(
            x_series[:, : self.n_static], fb_init, differentiable=torch.is_grad_enabled()
        )
        return free_run


def _channel_scale(values: FloatArray) -> FloatArray:
    """Per-channel normalization: the given spread, or 1 for a (near-)constant channel."""
    return np.where(values > _SCALE_FLOOR, values, 1.0)


def _y_series(spec: NnarmaxSpec, y: ArrayLike, n: int) -> FloatArray:
    """The measured positions as an (n, n_outputs) series (validated length)."""
    series = as_series(y, spec.n_outputs, 'y')
    if series.shape[0] != n:
        raise ValueError(f'y has {series.shape[0]} samples, the targets {n}: align them first')
    return series


def loss_frame_errors(spec: NnarmaxSpec, y_now: ArrayLike, errors: ArrayLike) -> FloatArray:
    """Errors (rows, n_out) in the frame of the loss.

    Unchanged, or for a body-frame network rotated into the body frame of each row's newest
    heading ψ(t) = ``y_now[:, 2]``.
    """
    values = np.asarray(errors, dtype=np.float64)
    if not spec.body_frame:
        return values
    heading = as_series(y_now, spec.n_outputs, 'y')[:, 2]
    return rotate_blocks(values, np.cos(heading), -np.sin(heading))


def _in_loss_frame(values: torch.Tensor, body: tuple[torch.Tensor, torch.Tensor] | None,
                   ) -> torch.Tensor:
    """``loss_frame_errors`` on tensors: the body rotation of a window's rows (or none)."""
    if body is None:
        return values
    return rotate_blocks_torch(values, body[0], -body[1])


def loss_scale(spec: NnarmaxSpec, y_now: ArrayLike, target_next: ArrayLike,
               keep: ArrayLike) -> FloatArray:
    """Per-channel normalization of the training loss, shape (n_outputs,).

    Absolute networks: the std of the kept targets yT(t + 1) (thesis: normalized MSE). Relative
    networks (``spec.relative``) predict ŷLF(t + 1) − y(t), so the loss is normalized by the RMS
    of yT(t + 1) − y(t), the size of what they actually predict. The absolute spread would mostly
    measure how far the vessel drifted in the window (tens of metres), make a 0.2 m error look
    like 1e-4 and let the weight penalty (eq. 2.8) dominate the fit.
    ``y_now`` (rows, n_out) is y(t) and ``target_next`` (rows, n_out) yT(t + 1) for the same rows.
    Body-frame networks: the steps in the body frame of ψ(t) (``loss_frame_errors``).
    """
    kept = np.asarray(keep, dtype=bool)
    target = as_series(target_next, spec.n_outputs, 'targets')[kept]
    if not spec.relative:
        return _channel_scale(target.std(axis=0))
    now = as_series(y_now, spec.n_outputs, 'y')[kept]
    step = loss_frame_errors(spec, now, target - now)
    return _channel_scale(np.sqrt(np.mean(step ** 2, axis=0)))


def _prepare_window(
    spec: NnarmaxSpec, u: ArrayLike, y: ArrayLike, targets: ArrayLike, mask: ArrayLike | None
) -> _Window:
    """Validate the arrays and build the regressors, targets and masks of one window."""
    target_series = as_series(targets, spec.n_outputs, 'targets')
    x_series, first = build_regressors(u, y, target_series, spec)
    n = target_series.shape[0]
    keep_all = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if keep_all.shape != (n,):
        raise ValueError(f'mask must have shape ({n},) like the targets, got {keep_all.shape}')
    if n - first < 3:
        raise ValueError(
            f'window too short: {n} samples leave fewer than 3 regressor rows after the first '
            f'{first}; collect more data before training'
        )
    if not (np.all(np.isfinite(x_series)) and np.all(np.isfinite(target_series))):
        raise ValueError('u, y and targets must be finite: drop or fill invalid samples first')
    target = target_series[first + 1 :]
    keep = keep_all[first + 1 :]
    keep_pair = keep[1:] & keep[:-1]
    if keep.sum() < 2:
        raise ValueError('mask keeps fewer than 2 training targets: the window is all transient')
    y_now = _y_series(spec, y, n)[first : n - 1]
    scale = loss_scale(spec, y_now, target, keep)
    diffs = loss_frame_errors(spec, y_now[1:], np.diff(target, axis=0))[keep_pair]
    diff_rms = np.sqrt(np.mean(diffs**2, axis=0)) if diffs.size else np.ones(spec.n_outputs)
    body = None
    if spec.body_frame:
        body = (torch.from_numpy(np.cos(y_now[:, 2])), torch.from_numpy(np.sin(y_now[:, 2])))
    return _Window(
        x_series=torch.from_numpy(x_series),
        fb_init=torch.from_numpy(target_series[first - spec.nfb + 1 : first + 1].copy()),
        target=torch.from_numpy(target.copy()),
        keep=torch.from_numpy(keep.copy()),
        keep_pair=torch.from_numpy(keep_pair.copy()),
        scale=torch.from_numpy(scale),
        diff_scale=torch.from_numpy(_channel_scale(diff_rms)),
        first=first,
        body=body,
    )


def _mse_residuals(prediction: torch.Tensor, window: _Window) -> torch.Tensor:
    """Normalized errors of the kept samples, scaled so that their squared sum is the MSE."""
    difference = _in_loss_frame(prediction[:-1] - window.target, window.body)
    error = (difference / window.scale)[window.keep]
    return error.reshape(-1) / math.sqrt(error.numel())


def _derivative_residuals(
    prediction: torch.Tensor, window: _Window, derivative_weight: float
) -> torch.Tensor:
    """Errors of the first differences, scaled so their squared sum is d · MSE_Δ."""
    fitted = prediction[:-1]
    error = ((fitted[1:] - fitted[:-1]) - (window.target[1:] - window.target[:-1]))
    if window.body is not None:  # in the frame of the later row, like ``diff_scale``
        error = _in_loss_frame(error, (window.body[0][1:], window.body[1][1:]))
    error = (error / window.diff_scale)[window.keep_pair]
    if error.numel() == 0:
        return error.reshape(-1)
    return error.reshape(-1) * math.sqrt(derivative_weight / error.numel())


def _data_residuals(
    prediction: torch.Tensor, window: _Window, derivative_weight: float
) -> torch.Tensor:
    """Residual vector of the data terms (MSE and, if weighted, derivative)."""
    parts = [_mse_residuals(prediction, window)]
    if derivative_weight > 0.0:
        parts.append(_derivative_residuals(prediction, window, derivative_weight))
    return torch.cat(parts)


def _mse(prediction: torch.Tensor, window: _Window) -> float:
    """The MSE part of the objective (the reported loss)."""
    return float(torch.sum(_mse_residuals(prediction.detach(), window) ** 2))


@dataclass
class _Run:
    """Mutable bookkeeping of one training run (local to ``train``)."""

    settings: TrainSettings
    stop_event: threading.Event | None
    start: float
    history: list[float]

    def stop_reason(self) -> str | None:
        """'stop_event' or 'max_seconds' when the run must end now, else None."""
        if self.stop_event is not None and self.stop_event.is_set():
            return 'stop_event'
        if time.monotonic() - self.start >= self.settings.max_seconds:
            return 'max_seconds'
        return None

    def goal_reached(self) -> bool:
        """True when the latest MSE is at or below the loss goal."""
        return bool(self.history) and self.history[-1] <= self.settings.loss_goal


_CONVERGED = ('loss_goal', 'min_grad', 'mu_max', 'least_squares')
# closure evaluations per L-BFGS iteration: 1 + up to 25 strong-Wolfe trials (torch's max_ls);
# torch's default max_eval = 1.25·max_iter would starve the line search at max_iter = 1
_LBFGS_MAX_EVAL = 26


def train(
    net: NnarmaxNet,
    u: ArrayLike,
    y: ArrayLike,
    targets: ArrayLike,
    mask: ArrayLike | None,
    settings: TrainSettings,
    *,
    stop_event: threading.Event | None = None,
) -> TrainResult:
    """Train a copy of ``net`` on one window (thesis Algorithm 4.1, lines 36–40).

    ``u`` (n, n_inputs_u) forces, ``y`` (n, n_outputs) measured positions, ``targets`` (n,
    n_outputs) LF targets yT, all on one time base with unwrapped heading; ``mask`` (n,) bool,
    False for targets that must not contribute (the last ε transient samples), None for all.
    The network predicts yT(t + 1) from row t. Returns the best weights found; ``net`` itself is
    not modified.
    """
    start = time.monotonic()
    previous_threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with subnormals_flushed():
            return _train(net, u, y, targets, mask, settings, stop_event, start)
    finally:
        torch.set_num_threads(previous_threads)


_SMALLEST_NORMAL = np.array([np.finfo(np.float64).tiny])  # [-] 2.2e-308


def flushing_subnormals() -> bool:
    """True when this thread's float arithmetic flushes subnormal results to zero (FTZ)."""
    return float(np.multiply(_SMALLEST_NORMAL, 0.5)[0]) == 0.0


@contextmanager
def subnormals_flushed() -> Iterator[None]:
    """Flush subnormal floats to zero on this thread inside the block (module docstring).

    The CPU's FTZ and DAZ modes are per thread. Left as they were when they were already on, or
    when the CPU has none (``torch.set_flush_denormal`` False: nothing changes then).
    """
    if flushing_subnormals() or not torch.set_flush_denormal(True):
        yield
        return
    try:
        yield
    finally:
        torch.set_flush_denormal(False)


def _train(
    net: NnarmaxNet,
    u: ArrayLike,
    y: ArrayLike,
    targets: ArrayLike,
    mask: ArrayLike | None,
    settings: TrainSettings,
    stop_event: threading.Event | None,
    start: float,
) -> TrainResult:
    """Body of ``train`` (runs with one torch thread)."""
    spec = net.spec
    window = _prepare_window(spec, u, y, targets, mask)
    model = copy.deepcopy(net)
    if settings.standardize:
        model.set_standardization(u, y, preserve_function=True)
    solved = _solved_by_least_squares(spec, settings)
    if settings.hold_forces and not solved:
        raise ValueError('TrainSettings.hold_forces needs the linear network solved by least '
                         'squares (no tanh part, derivative_weight 0, no parallel training with '
                         'feedback): the gradient training would move the held force weights')
    if settings.north_east_decoupled and spec.n_outputs == 3 and not solved:
        raise ValueError('TrainSettings.north_east_decoupled needs the linear network solved by '
                         'least squares (no tanh part, derivative_weight 0, no parallel training '
                         'with feedback): the gradient training would couple the outputs again')
    if solved and settings.force_ridge_grid:
        design, wanted = model.linear_problem(window.x_series[:-1], window.target, window.keep)
        ridges = validated_force_ridges(design, wanted, spec.nu * spec.n_inputs_u,
                                        settings.validation_rows, settings.force_ridge_grid)
        model.set_linear_solution(solve_ridge(design, wanted, ridges))
    elif settings.linear_init or solved:
        model.fit_linear_bypass(window.x_series[:-1], window.target, window.keep,
                                force_prior=settings.force_prior,
                                hold_forces=settings.hold_forces,
                                north_east_decoupled=settings.north_east_decoupled)
    runner = _WindowPredictor(model, n_static_regressors(spec), spec.nfb)
    parallel = settings.mode == 'parallel'
    with torch.no_grad():
        initial_objective, prediction = _objective(runner, window, parallel, settings)
        initial_loss = _mse(prediction, window)
    run = _Run(settings, stop_event, start, [])
    optimizers: dict[str, Callable[[_WindowPredictor, _Window, bool, _Run], str]] = {
        'lm': _levenberg_marquardt,
        'lbfgs': _lbfgs,
        'adam': _adam,
    }
    reason = 'least_squares' if solved else 'max_epochs'
    objective, loss = initial_objective, initial_loss  # unless an optimizer moves the weights
    if settings.max_epochs > 0 and not solved:
        reason = run.stop_reason() or optimizers[settings.algorithm](runner, window, parallel, run)
        with torch.no_grad():
            objective, prediction = _objective(runner, window, parallel, settings)
            loss = _mse(prediction, window)
    state = {name: value.detach().clone() for name, value in model.state_dict().items()}
    return TrainResult(
        state_dict=state,
        loss=loss,
        initial_loss=initial_loss,
        epochs=len(run.history),
        seconds=time.monotonic() - start,
        converged=reason in _CONVERGED,
        stopped_reason=reason,
        loss_history=tuple(run.history),
        objective=float(objective),
        initial_objective=float(initial_objective),
    )


def _solved_by_least_squares(spec: NnarmaxSpec, settings: TrainSettings) -> bool:
    """True when one least-squares solve is the exact training: the linear network on the MSE.

    The linear network (no tanh part) is linear in its weights, and with neither a derivative
    term nor a recursion through fed-back outputs (parallel mode with nfb > 0) its objective is
    the plain MSE: ``fit_linear_bypass`` finds its optimum (up to ``LINEAR_RIDGE``) in one solve.
    ``weight_decay`` has nothing to act on then (it covers only the tanh part).
    """
    recursive = settings.mode == 'parallel' and spec.nfb > 0
    return spec.linear and settings.derivative_weight == 0.0 and not recursive


def validated_force_ridges(design: torch.Tensor, wanted: torch.Tensor, n_force: int,
                           validation_rows: int, grid: Sequence[float]) -> torch.Tensor:
    """Per column and output ridges (n_columns − 1, n_outputs) of the linear network.

    ``design``, ``wanted``: ``NnarmaxNet.linear_problem`` (kept rows, oldest first); the first
    ``n_force`` columns are the force regressors. Each ridge of ``grid`` on the force columns
    (every other column keeps ``BASE_RIDGE``) is fitted on all rows but the newest
    ``validation_rows`` (at most half) and scored per output by the mean squared error on those;
    each output takes the ridge with the least error (the smaller one on a tie).
    """
    rows, n_columns = design.shape
    holdout = min(validation_rows, rows // 2)
    fit, check = slice(0, rows - holdout), slice(rows - holdout, rows)
    errors = []
    for ridge in grid:
        ridges = torch.full((n_columns - 1,), BASE_RIDGE, dtype=design.dtype)
        ridges[:n_force] = ridge
        solution = solve_ridge(design[fit], wanted[fit], ridges)
        errors.append(torch.mean((design[check] @ solution - wanted[check]) ** 2, dim=0))
    best = torch.argmin(torch.stack(errors), dim=0)  # (n_outputs,): first minimum on a tie
    chosen = torch.full((n_columns - 1, wanted.shape[1]), BASE_RIDGE, dtype=design.dtype)
    chosen[:n_force] = torch.tensor(grid, dtype=design.dtype)[best]
    return chosen


def _objective(
    runner: _WindowPredictor, window: _Window, parallel: bool, settings: TrainSettings
) -> tuple[torch.Tensor, torch.Tensor]:
    """(J(w), prediction) with autograd through the runner's parameters."""
    prediction = runner(window.x_series, window.fb_init, parallel)
    residuals = _data_residuals(prediction, window, settings.derivative_weight)
    objective = torch.sum(residuals**2)
    if settings.weight_decay > 0.0:
        weights = torch.nn.utils.parameters_to_vector(runner.parameters())
        decay = decay_vector(runner.net, settings.weight_decay)
        objective = objective + torch.sum(decay * weights**2)
    return objective, prediction


def decay_vector(net: torch.nn.Module, weight_decay: float) -> torch.Tensor:
    """Per-parameter weight penalty b of eq. 2.8, flat in ``parameters()`` order.

    The tanh part (hidden layers, output layer) gets ``weight_decay``; the linear bypass gets
    none: it is the linear ARX model, solved by least squares at ``linear_init`` and shrinking it
    pulls the prediction toward the raw measurement y(t), not toward a smoother function.
    """
    parts = [torch.zeros(p.numel(), dtype=torch.float64) if name.startswith('bypass.')
             else torch.full((p.numel(),), weight_decay, dtype=torch.float64)
             for name, p in net.named_parameters()]
    return torch.cat(parts) if parts else torch.zeros(0, dtype=torch.float64)


@dataclass(frozen=True)
class _FlatParameters:
    """Names and shapes of a module's parameters, to move between a flat vector and a dict."""

    names: tuple[str, ...]
    shapes: tuple[torch.Size, ...]
    sizes: tuple[int, ...]

    @classmethod
    def of(cls, module: torch.nn.Module) -> _FlatParameters:
        """Layout of ``module.parameters()`` (the order of ``parameters_to_vector``)."""
        named = list(module.named_parameters())
        return cls(
            names=tuple(name for name, _ in named),
            shapes=tuple(param.shape for _, param in named),
            sizes=tuple(param.numel() for _, param in named),
        )

    def unflatten(self, flat: torch.Tensor, prefix: str = '') -> dict[str, torch.Tensor]:
        """Parameter dict for ``functional_call`` from a flat weight vector."""
        parts = flat.split(list(self.sizes))
        return {
            prefix + name: part.view(shape)
            for name, part, shape in zip(self.names, parts, self.shapes, strict=True)
        }


def _window_prediction(
    runner: _WindowPredictor, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    parallel: bool,
) -> torch.Tensor:
    """Predictions over the window with the weights ``flat`` (the runner is not modified)."""
    buffers = {'net.' + name: value for name, value in runner.net.named_buffers()}
    params = layout.unflatten(flat, prefix='net.')
    prediction: torch.Tensor = functional_call(
        runner, {**params, **buffers}, (window.x_series, window.fb_init, parallel)
    )
    return prediction


def _prediction_jacobian(
    runner: _WindowPredictor, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    parallel: bool,
) -> torch.Tensor:
    """dŷLF(t + 1)/dw for every row, shape (rows, n_out, n_weights).

    Each row's output depends on its own regressor only, so the per-row Jacobians come from a
    reverse-mode Jacobian of one row, vectorized over the rows (``vmap(jacrev)``): n_out backward
    passes of a tiny network instead of n_weights forward passes over the window. In parallel
    mode the feedback regressors are earlier outputs, and the total derivative follows the
    dynamic-backpropagation recursion (Narendra & Parthasarathy 1991, IEEE TNN 2(2)):

        S_r = ∂f/∂w|_r + Σ_k ∂f/∂fb_k|_r · S_{r−k−1},   S_r = dŷ_r/dw,

    where fb_k is feedback lag k and rows before the first see targets (S = 0).
    """
    net = runner.net
    buffers = dict(net.named_buffers())

    def one_row(weights: torch.Tensor, x_row: torch.Tensor) -> torch.Tensor:
        params = layout.unflatten(weights)
        out: torch.Tensor = functional_call(net, {**params, **buffers}, (x_row[None, :],))
        return out[0]

    if not parallel or runner.nfb == 0:
        written_out = _one_layer_jacobian(net, layout, flat, window.x_series)
        if written_out is not None:
            return written_out
        jac_w: torch.Tensor = vmap(jacrev(one_row), in_dims=(None, 0))(flat, window.x_series)
        return jac_w
    nfb, n_out = runner.nfb, window.target.shape[1]
    with torch.no_grad():
        prediction = _window_prediction(runner, layout, flat, window, parallel=True)
    history = torch.cat((window.fb_init, prediction))  # feedback values, oldest first
    rows = prediction.shape[0]
    lag_index = (nfb - 1 + torch.arange(rows))[:, None] - torch.arange(nfb)[None, :]
    x_parallel = torch.cat(
        (window.x_series[:, : runner.n_static], history[lag_index].reshape(rows, nfb * n_out)),
        dim=1,
    )
    jac_w, jac_x = vmap(jacrev(one_row, argnums=(0, 1)), in_dims=(None, 0))(flat, x_parallel)
    direct = jac_w.numpy()
    feedback_gain = jac_x[:, :, runner.n_static :].reshape(rows, n_out, nfb, n_out).numpy()
    total = np.empty_like(direct)
    for row in range(rows):
        sensitivity = direct[row].copy()
        for lag in range(min(nfb, row)):
            sensitivity += feedback_gain[row, :, lag, :] @ total[row - lag - 1]
        total[row] = sensitivity
    return torch.from_numpy(total)


_ONE_LAYER_NAMES = ('hidden.0.weight', 'hidden.0.bias', 'output.weight', 'output.bias',
                    'bypass.weight')


class _OneLayerParts(NamedTuple):
    """The forward values the written-out Jacobian of a one-tanh-layer network is made of."""

    x_s: torch.Tensor  # (rows, n_in) standardized regressors
    tanh: torch.Tensor  # (rows, hidden) tanh layer output
    g_pre: torch.Tensor  # (rows, n_out, hidden) tanh_backward(y_std_i · W2_i, tanh)
    y_std: torch.Tensor  # (n_out,)


@dataclass
class _LmScratch:
    """One training's reusable LM Jacobian arrays (what they hold is valid until the next use).

    ``columns``: the residual Jacobian array (its zero blocks stay zero, every other entry is
    written again); ``x_s``: the standardized regressors, which depend on the window and the
    network's standardization only, not on the weights.
    """

    columns: torch.Tensor | None = None
    x_s: torch.Tensor | None = None
    # the window forward's own (batched) standardized regressors and relative base
    forward_x_s: torch.Tensor | None = None
    forward_base: torch.Tensor | None = None
    # the factors of the residual Jacobian's columns (``_one_layer_factors``)
    factors: torch.Tensor | None = None


def _one_layer_parts(
    net: NnarmaxNet, layout: _FlatParameters, flat: torch.Tensor, x: torch.Tensor,
    scratch: _LmScratch | None = None,
) -> _OneLayerParts | None:
    """Forward values for ``_one_layer_jacobian``; None unless earth frame, 1 layer, bypass."""
    spec = net.spec
    if spec.body_frame or spec.hidden_layers != 1 or layout.names != _ONE_LAYER_NAMES:
        return None
    params = layout.unflatten(flat)
    w1, b1, w2 = params['hidden.0.weight'], params['hidden.0.bias'], params['output.weight']
    rows = x.shape[0]
    n_out, hidden = w2.shape
    with torch.no_grad():
        x_s = scratch.x_s if scratch is not None and scratch.x_s is not None else \
            _standardized_rows(net, x)
        if scratch is not None:
            scratch.x_s = x_s
        tanh = torch.tanh(torch.nn.functional.linear(x_s, w1, b1))
        y_std = net.y_std
        g_pre = torch.ops.aten.tanh_backward(
            (y_std[:, None] * w2)[None].expand(rows, n_out, hidden), tanh[:, None, :])
    return _OneLayerParts(x_s, tanh, g_pre, y_std)


def _one_layer_jacobian(
    net: NnarmaxNet, layout: _FlatParameters, flat: torch.Tensor, x: torch.Tensor
) -> torch.Tensor | None:
    """``vmap(jacrev(one_row))`` of an earth-frame network with one tanh layer and a bypass.

    Written out, the backward pass of the basis vector e_i through ŷ = y_mean + y_std ·
    (W2 tanh(W1 x_s + b1) + b2 + Wb x_s) gives single products only: y_std_i · x_s (Wb row i),
    y_std_i · tanh (W2 row i), y_std_i (b2), g = tanh_backward(y_std_i · W2_i, tanh) (b1) and
    g · x_s (W1); every other entry is 0. Computed as such over the whole window, each entry is
    bit for bit the autograd one (zeros +0, as its accumulating products give them): checked on
    every Jacobian of a 1800 s replay and by a test. The standardized regressors of a
    ramp-invariant network come from ``vmap`` over the rows as in ``jacrev`` (its line fit
    rounds differently over a batch). Returns None for any other network (the caller's vmap).
    """
    parts = _one_layer_parts(net, layout, flat, x)
    if parts is None:
        return None
    rows = x.shape[0]
    n_out = parts.y_std.shape[0]
    jac = torch.zeros(rows, n_out, flat.numel(), dtype=torch.float64)
    _fill_one_layer(jac.permute(2, 0, 1), parts)
    return jac


def _fill_one_layer(out: torch.Tensor, parts: _OneLayerParts,
                    residual: _ResidualMap | None = None) -> None:
    """Write the Jacobian into zeroed ``out`` (n_weights, rows, n_out), weights in flat order.

    Only the non-zero blocks are written. With ``residual`` each block is then mapped to the
    residual Jacobian's (``_ResidualMap``): a zero entry maps to +0 exactly, so the zero blocks
    need no work.
    """
    x_s, tanh, g_pre, y_std = parts
    n_in = x_s.shape[1]
    n_out, hidden = g_pre.shape[1:]
    with torch.no_grad():
        w1_end = hidden * n_in
        w1 = out[:w1_end].unflatten(0, (hidden, n_in))
        torch.mul(g_pre.permute(2, 0, 1)[:, None], x_s.T[None, :, :, None], out=w1)
        w1 += 0.0  # −0 products to +0, as autograd's accumulating products
        if residual is not None:
            residual.apply(out[:w1_end])
        b1 = out[w1_end:w1_end + hidden]
        b1.copy_(g_pre.permute(2, 0, 1))
        b1 += 0.0
        if residual is not None:
            residual.apply(b1)
        w2 = out[w1_end + hidden:w1_end + hidden + n_out * hidden].unflatten(0, (n_out, hidden))
        b2 = out[w1_end + hidden + n_out * hidden:w1_end + hidden + n_out * (hidden + 1)]
        wb = out[w1_end + hidden + n_out * (hidden + 1):].unflatten(0, (n_out, n_in))
        for i in range(n_out):
            torch.mul(tanh.T, y_std[i], out=w2[i, :, :, i])
            w2[i, :, :, i] += 0.0
            b2[i, :, i] = y_std[i]
            torch.mul(x_s.T, y_std[i], out=wb[i, :, :, i])
            wb[i, :, :, i] += 0.0
            if residual is not None:
                residual.apply(w2[i, :, :, i], i)
                residual.apply(b2[i, :, i], i)
                residual.apply(wb[i, :, :, i], i)


def _one_layer_kept(
    net: NnarmaxNet, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    derivative_weight: float, scratch: _LmScratch | None,
) -> tuple[_OneLayerParts, _ResidualMap] | None:
    """The kept rows' forward values and the MSE residual map, or None (see the callers)."""
    if derivative_weight > 0.0 or window.body is not None:
        return None
    parts = _one_layer_parts(net, layout, flat, window.x_series, scratch)
    if parts is None:
        return None
    rows, n_out = window.x_series.shape[0], parts.y_std.shape[0]
    offset = _data_residuals(torch.zeros(rows, n_out, dtype=torch.float64), window, 0.0)
    kept = window.keep.nonzero()[:, 0]
    n_keep = kept.numel()
    residual = _ResidualMap(window.target[kept], window.scale, math.sqrt(n_keep * n_out),
                            offset.view(n_keep, n_out))
    return (_OneLayerParts(parts.x_s[kept], parts.tanh[kept], parts.g_pre[kept], parts.y_std),
            residual)


def _one_layer_residual_jacobian(
    net: NnarmaxNet, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    derivative_weight: float, scratch: _LmScratch | None = None,
) -> torch.Tensor | None:
    """``_residual_jacobian(_prediction_jacobian(...))`` of a one-layer earth-frame network.

    Only the MSE residuals (derivative_weight 0): the kept rows' written-out Jacobian is built
    in the residual Jacobian's own layout (n_weights, n_residuals), and the residual map's
    element-wise steps run on it in place, so neither the whole window's Jacobian nor a
    transposing copy is made. The same numbers: see ``_one_layer_jacobian`` and
    ``_residual_columns``. None when it does not apply. With ``scratch`` (one per training)
    its arrays are reused: the returned Jacobian is then valid until the next call.
    """
    found = _one_layer_kept(net, layout, flat, window, derivative_weight, scratch)
    if found is None:
        return None
    parts, residual = found
    n_keep, n_out = residual.offset.shape
    columns = _zeroed(scratch, (flat.numel(), n_keep, n_out))
    _fill_one_layer(columns, parts, residual)
    return columns.view(flat.numel(), -1).T


def _one_layer_factors(parts: _OneLayerParts, out: torch.Tensor | None = None) -> torch.Tensor:
    """The columns every output's residual Jacobian is a scaling of, transposed: (n_c, n_keep).

    With d = 1 − tanh², output i's prediction Jacobian in row r is y_std_i · W2_ij · d_rj · x_rk
    (W1), y_std_i · W2_ij · d_rj (b1), y_std_i · tanh_rj (W2 row i), y_std_i (b2_i) and
    y_std_i · x_rk (bypass row i), zero elsewhere; the residual map scales output i by
    c_i = 1/(scale_i · √(n_keep · n_out)). So output i's non-zero columns are the shared
    factors B = [d_j x_k, d_j] scaled per hidden unit by a_ij = c_i y_std_i W2_ij and the own
    factors O = [tanh, 1, x] scaled by e_i = c_i y_std_i. Rows: B in flat (W1, b1) order, then O
    in (W2 row, b2, bypass row) order. ``out``: an array to write into.
    """
    x_s, tanh, _, _ = parts
    n_keep, n_in = x_s.shape
    hidden = tanh.shape[1]
    w1_end = hidden * n_in
    shared = w1_end + hidden
    shape = (shared + hidden + 1 + n_in, n_keep)
    if out is None or out.shape != shape:
        out = torch.empty(shape, dtype=torch.float64)
    with torch.no_grad():
        slope = 1.0 - tanh.T * tanh.T  # (hidden, n_keep)
        torch.mul(slope[:, None, :], x_s.T[None], out=out[:w1_end].unflatten(0, (hidden, n_in)))
        out[w1_end:shared] = slope
        out[shared:shared + hidden] = tanh.T
        out[shared + hidden] = 1.0
        out[shared + hidden + 1:] = x_s.T
    return out


def _one_layer_normal_equations(
    net: NnarmaxNet, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    derivative_weight: float, residuals: torch.Tensor, scratch: _LmScratch | None = None,
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """(Jᵀ J, Jᵀ r) of ``_one_layer_residual_jacobian``'s J by factors; None where it is None.

    Output i's rows of J are [B diag(â_i), e_i O] in its non-zero columns
    (``_one_layer_factors``; â_i is a_i repeated over each hidden unit's columns), so with
    G = [B O]ᵀ [B O] (one symmetric product, BLAS syrk through numpy) and P = [B O]ᵀ R
    (R: the residuals, one column per output):

        shared × shared  G_BB ∘ Σ_i â_i â_iᵀ      shared × own_i  diag(â_i) G_BO e_i
        own_i × own_i    e_i² G_OO                 own_i × own_j   0 (i ≠ j)
        Jᵀ r: shared Σ_i â_i ∘ P_B,i,  own_i e_i P_O,i.

    The same matrix in exact arithmetic, about n_out × 2 × (n_weights/n_c)² fewer multiply-adds
    than the dense ``J.T @ J``; it differs in the last bits (and in the rounding of the residual
    map's subtract-and-divide, which this skips). Exactly symmetric.
    """
    found = _one_layer_kept(net, layout, flat, window, derivative_weight, scratch)
    if found is None:
        return None
    parts, residual = found
    factors = _one_layer_factors(parts, scratch.factors if scratch is not None else None)
    if scratch is not None:
        scratch.factors = factors
    n_c, n_keep = factors.shape
    n_in = parts.x_s.shape[1]
    n_out, hidden = parts.g_pre.shape[1:]
    shared = hidden * (n_in + 1)
    block = factors.numpy()
    gram = block @ block.T  # numpy: syrk for a matrix times its own transpose
    per_output = np.ascontiguousarray(residuals.view(n_keep, n_out).numpy())
    projected = block @ per_output  # (n_c, n_out)
    w2 = layout.unflatten(flat)['output.weight'].detach().numpy()  # (n_out, hidden)
    own_scale = (parts.y_std / (residual.scale * residual.root)).numpy()  # e_i
    unit_scale = own_scale[:, None] * w2  # a_ij
    # â_i: W1 columns (j, k) then b1 columns j
    shared_scale = np.concatenate((np.repeat(unit_scale, n_in, axis=1), unit_scale), axis=1)
    n_weights = flat.numel()
    matrix = np.zeros((n_weights, n_weights))
    gradient = np.zeros(n_weights)
    # Σ_i â_i â_iᵀ by outer products: exactly symmetric, as G
    outer = sum(np.multiply.outer(scale_i, scale_i) for scale_i in shared_scale)
    matrix[:shared, :shared] = gram[:shared, :shared] * outer
    gradient[:shared] = np.sum(shared_scale.T * projected[:shared], axis=1)
    for i in range(n_out):
        own = np.concatenate((
            np.arange(shared + i * hidden, shared + (i + 1) * hidden),
            [shared + n_out * hidden + i],
            np.arange(shared + n_out * (hidden + 1) + i * n_in,
                      shared + n_out * (hidden + 1) + (i + 1) * n_in)))
        cross = gram[:shared, shared:] * (shared_scale[i][:, None] * own_scale[i])
        matrix[:shared, own] = cross
        matrix[own, :shared] = cross.T
        matrix[np.ix_(own, own)] = gram[shared:, shared:] * own_scale[i] ** 2
        gradient[own] = own_scale[i] * projected[shared:, i]
    return torch.from_numpy(matrix), torch.from_numpy(gradient)


def _damped_step(matrix: torch.Tensor, mu: float, gradient: torch.Tensor) -> torch.Tensor:
    """(matrix + μ I)⁻¹ gradient by Cholesky; LU (``linalg.solve``) if it is not positive definite.

    For μ > 0 the damped Gauss–Newton matrix Jᵀ J + diag(b) + μ I is symmetric positive
    definite, so the Cholesky factor exists unless rounding breaks it (then LU as before).
    """
    damped = matrix.clone()
    damped.diagonal().add_(mu)
    factor, info = torch.linalg.cholesky_ex(damped)
    if int(info) != 0:
        lu_step: torch.Tensor = torch.linalg.solve(damped, gradient)
        return lu_step
    step: torch.Tensor = torch.cholesky_solve(gradient[:, None], factor)[:, 0]
    return step


def _zeroed(scratch: _LmScratch | None, shape: tuple[int, int, int]) -> torch.Tensor:
    """A zero array of ``shape`` the first time; then the scratch one as it was left."""
    if scratch is not None and scratch.columns is not None and scratch.columns.shape == shape:
        return scratch.columns
    columns = torch.zeros(shape, dtype=torch.float64)
    if scratch is not None:
        scratch.columns = columns
    return columns


@dataclass(frozen=True)
class _ResidualMap:
    """The MSE residual map's element-wise steps ((v − target)/scale)/√n − offset, in place."""

    target: torch.Tensor  # (n_keep, n_out) kept targets
    scale: torch.Tensor  # (n_out,)
    root: float  # √(n_keep · n_out)
    offset: torch.Tensor  # (n_keep, n_out) the map of 0

    def apply(self, values: torch.Tensor, channel: int | None = None) -> None:
        """``values`` (..., n_keep, n_out), or (..., n_keep) of output ``channel``."""
        if channel is None:
            target, scale, offset = self.target, self.scale, self.offset
        else:
            target, scale = self.target[:, channel], self.scale[channel]
            offset = self.offset[:, channel]
        values -= target
        values /= scale
        values /= self.root
        values -= offset


def _standardized_rows(net: NnarmaxNet, x: torch.Tensor) -> torch.Tensor:
    """The standardized (relative) regressors x_s the network's first layers see, (rows, n)."""
    spec = net.spec
    x_mean, x_std = net.regressor_standardization()

    def one(rows: torch.Tensor) -> torch.Tensor:
        if spec.relative:
            rows = rows - _relative_frame_torch(spec, rows)[1]
        return (rows - x_mean) / x_std

    if spec.ramp_invariant:
        per_row: torch.Tensor = vmap(lambda row: one(row[None, :])[0])(x)
        return per_row
    return one(x)


def _residual_jacobian(
    jac_prediction: torch.Tensor, window: _Window, derivative_weight: float
) -> torch.Tensor:
    """Jacobian of the data residuals from that of the predictions (the map is affine).

    Column j is residuals(dŷ/dw_j) − residuals(0). Earth-frame windows compute all columns at
    once (``_residual_columns``), element for element as the per-column map; the result is laid
    out as ``vmap(..., out_dims=1)`` lays it out (transpose of a contiguous (n_weights,
    n_residuals)), so J^T J sees the same operands.
    """
    offset = _data_residuals(torch.zeros(jac_prediction.shape[:2], dtype=torch.float64), window,
                             derivative_weight)
    if window.body is None:
        columns = _residual_columns(jac_prediction, window, derivative_weight)
        columns -= offset[:, None]
        return columns.T.contiguous().T

    def linear_part(prediction: torch.Tensor) -> torch.Tensor:
        return _data_residuals(prediction, window, derivative_weight) - offset

    jacobian: torch.Tensor = vmap(linear_part, in_dims=2, out_dims=1)(jac_prediction)
    return jacobian


def _residual_columns(
    jac_prediction: torch.Tensor, window: _Window, derivative_weight: float
) -> torch.Tensor:
    """``_data_residuals`` of every column jac_prediction[:, :, j] (earth frame), (n_res, n_w).

    The same element-wise operations in the same order as ``_mse_residuals`` and
    ``_derivative_residuals`` (kept rows picked first, which does not change them), in place
    on the (rows, n_out, n_weights) array's layout: few new 15 MB buffers per LM epoch.
    """
    n_weights = jac_prediction.shape[2]
    fitted = jac_prediction[:-1]
    error = fitted[window.keep]
    error -= window.target[window.keep][:, :, None]
    error /= window.scale[:, None]
    mse = error.reshape(-1, n_weights)
    mse /= math.sqrt(error.shape[0] * error.shape[1])
    if not derivative_weight > 0.0:
        return mse
    step = fitted[1:] - fitted[:-1]
    step -= (window.target[1:] - window.target[:-1])[:, :, None]
    step /= window.diff_scale[:, None]
    kept = step[window.keep_pair]
    count = kept.shape[0] * kept.shape[1]
    derivative = kept.reshape(-1, n_weights)
    if count > 0:
        derivative *= math.sqrt(derivative_weight / count)
    return torch.cat((mse, derivative))


def _one_layer_prediction(
    runner: _WindowPredictor, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    parallel: bool, scratch: _LmScratch,
) -> torch.Tensor | None:
    """``_window_prediction`` (no grad) of a one-layer earth-frame network, x_s kept in scratch.

    ``NnarmaxNet.forward``'s operations in its order on the weights ``flat``; the standardized
    regressors and the relative base (weight-free) are computed once per training. None when
    it does not apply.
    """
    net = runner.net
    spec = net.spec
    if (parallel and runner.nfb > 0) or spec.body_frame or spec.hidden_layers != 1 or \
            layout.names != _ONE_LAYER_NAMES:
        return None
    if scratch.forward_x_s is None:
        x = window.x_series
        if spec.relative:
            _, shift, scratch.forward_base = _relative_frame_torch(spec, x)
            x = x - shift
        x_mean, x_std = net.regressor_standardization()
        scratch.forward_x_s = (x - x_mean) / x_std
    x_s = scratch.forward_x_s
    params = layout.unflatten(flat)
    linear = torch.nn.functional.linear
    hidden = torch.tanh(linear(x_s, params['hidden.0.weight'], params['hidden.0.bias']))
    out = linear(hidden, params['output.weight'], params['output.bias'])
    out = out + linear(x_s, params['bypass.weight'])
    prediction = net.y_mean + net.y_std * out
    return prediction if scratch.forward_base is None else scratch.forward_base + prediction


def _lm_jacobian(
    runner: _WindowPredictor, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    parallel: bool, derivative_weight: float, scratch: _LmScratch | None = None,
) -> torch.Tensor:
    """Jacobian of the data residuals w.r.t. the weights, (n_residuals, n_weights).

    ``scratch``: see ``_one_layer_residual_jacobian`` (valid until the next call then).
    """
    if not parallel or runner.nfb == 0:
        direct = _one_layer_residual_jacobian(runner.net, layout, flat, window,
                                              derivative_weight, scratch)
        if direct is not None:
            return direct
    return _residual_jacobian(_prediction_jacobian(runner, layout, flat, window, parallel),
                              window, derivative_weight)


def _lm_normal_equations(
    runner: _WindowPredictor, layout: _FlatParameters, flat: torch.Tensor, window: _Window,
    parallel: bool, derivative_weight: float, residuals: torch.Tensor, scratch: _LmScratch,
) -> tuple[torch.Tensor, torch.Tensor, bool]:
    """(Jᵀ J, Jᵀ r, by_factors): by factors for the default network, else from the dense J."""
    if not parallel or runner.nfb == 0:
        normal = _one_layer_normal_equations(runner.net, layout, flat, window,
                                             derivative_weight, residuals, scratch)
        if normal is not None:
            return normal[0], normal[1], True
    jacobian = _lm_jacobian(runner, layout, flat, window, parallel, derivative_weight, scratch)
    return jacobian.T @ jacobian, jacobian.T @ residuals, False


def _levenberg_marquardt(
    runner: _WindowPredictor, window: _Window, parallel: bool, run: _Run
) -> str:
    """Levenberg–Marquardt (thesis eq. 2.7) with trainlm-style μ adaptation."""
    settings = run.settings
    layout = _FlatParameters.of(runner.net)
    decay = decay_vector(runner.net, settings.weight_decay)

    def residual_fn(flat: torch.Tensor) -> torch.Tensor:
        prediction = _one_layer_prediction(runner, layout, flat, window, parallel, scratch)
        if prediction is None:
            prediction = _window_prediction(runner, layout, flat, window, parallel)
        return _data_residuals(prediction, window, settings.derivative_weight)

    def objective_of(flat: torch.Tensor, residuals: torch.Tensor) -> float:
        return float(torch.sum(residuals**2) + torch.sum(decay * flat**2))

    scratch = _LmScratch()  # one epoch's Jacobian is dead at the next's
    with torch.no_grad():
        weights = torch.nn.utils.parameters_to_vector(runner.net.parameters()).detach().clone()
        residuals = residual_fn(weights)
    objective = objective_of(weights, residuals)
    identity = torch.eye(weights.numel(), dtype=weights.dtype)
    mu = settings.lm_mu0
    reason = 'max_epochs'
    for _ in range(settings.max_epochs):
        stop = run.stop_reason()
        if stop is not None:
            reason = stop
            break
        jtj, jtr, by_factors = _lm_normal_equations(runner, layout, weights, window, parallel,
                                                    settings.derivative_weight, residuals,
                                                    scratch)
        gradient = jtr + decay * weights  # ½ ∇J
        if float(torch.linalg.vector_norm(2.0 * gradient)) <= settings.min_grad:
            reason = 'min_grad'
            break
        gauss_newton = jtj + torch.diag(decay)
        accepted = False
        while not accepted:
            if by_factors:
                step = _damped_step(gauss_newton, mu, gradient)
            else:
                step = torch.linalg.solve(gauss_newton + mu * identity, gradient)
            candidate = weights - step
            with torch.no_grad():
                candidate_residuals = residual_fn(candidate)
            candidate_objective = objective_of(candidate, candidate_residuals)
            if math.isfinite(candidate_objective) and candidate_objective < objective:
                weights, residuals, objective = candidate, candidate_residuals, candidate_objective
                mu = max(mu * settings.lm_mu_dec, 1e-20)
                accepted = True
            else:
                mu *= settings.lm_mu_inc
                if mu > settings.lm_mu_max:
                    break
                if run.stop_reason() is not None:
                    break
        run.history.append(float(torch.sum(_mse_residuals_from(residuals, window) ** 2)))
        if mu > settings.lm_mu_max:
            reason = 'mu_max'
            break
        if not accepted:
            reason = run.stop_reason() or reason
            break
        if run.goal_reached():
            reason = 'loss_goal'
            break
    torch.nn.utils.vector_to_parameters(weights, runner.net.parameters())
    return reason


def _mse_residuals_from(residuals: torch.Tensor, window: _Window) -> torch.Tensor:
    """The MSE block at the head of a data-residual vector."""
    n_mse = int(window.keep.sum()) * window.target.shape[1]
    return residuals[:n_mse]


def _gradient_descent(
    runner: _WindowPredictor,
    window: _Window,
    parallel: bool,
    run: _Run,
    optimizer: torch.optim.Optimizer,
) -> str:
    """Shared epoch loop of the autograd optimizers; returns with the best weights seen.

    Adam and L-BFGS do not decrease the objective monotonically, so the objective is evaluated
    after every step (one extra forward pass) and the best weights, starting with the warm
    start, are restored at the end.
    """
    settings = run.settings

    def closure() -> torch.Tensor:
        optimizer.zero_grad()
        objective, _ = _objective(runner, window, parallel, settings)
        objective.backward()
        return objective

    def evaluate() -> tuple[float, float]:
        with torch.no_grad():
            objective, prediction = _objective(runner, window, parallel, settings)
        return float(objective), _mse(prediction, window)

    best_objective, _ = evaluate()
    best_state = copy.deepcopy(runner.state_dict())
    reason = 'max_epochs'
    for _ in range(settings.max_epochs):
        stop = run.stop_reason()
        if stop is not None:
            reason = stop
            break
        optimizer.step(cast(Callable[[], float], closure))
        objective, mse = evaluate()
        if not math.isfinite(objective):
            reason = 'non_finite'
            break
        if objective < best_objective:
            best_objective = objective
            best_state = copy.deepcopy(runner.state_dict())
        run.history.append(mse)
        if _gradient_norm(runner) <= settings.min_grad:
            reason = 'min_grad'
            break
        if run.goal_reached():
            reason = 'loss_goal'
            break
    runner.load_state_dict(best_state)
    return reason


def _gradient_norm(module: torch.nn.Module) -> float:
    """Euclidean norm of the current gradients of a module's parameters."""
    grads = [param.grad.reshape(-1) for param in module.parameters() if param.grad is not None]
    return float(torch.linalg.vector_norm(torch.cat(grads))) if grads else math.inf


def _lbfgs(runner: _WindowPredictor, window: _Window, parallel: bool, run: _Run) -> str:
    """L-BFGS with strong-Wolfe line search, one iteration per epoch."""
    optimizer = torch.optim.LBFGS(
        runner.parameters(), lr=1.0, max_iter=1, max_eval=_LBFGS_MAX_EVAL, history_size=20,
        line_search_fn='strong_wolfe', tolerance_grad=0.0, tolerance_change=0.0,
    )
    return _gradient_descent(runner, window, parallel, run, optimizer)


def _adam(runner: _WindowPredictor, window: _Window, parallel: bool, run: _Run) -> str:
    """Full-batch Adam, one step per epoch."""
    optimizer = torch.optim.Adam(runner.parameters(), lr=run.settings.lr)
    return _gradient_descent(runner, window, parallel, run, optimizer)


def _as_net(
    net_or_state: NnarmaxNet | Mapping[str, torch.Tensor], spec: NnarmaxSpec
) -> NnarmaxNet:
    """The network itself, or a fresh one loaded from a state_dict."""
    if isinstance(net_or_state, NnarmaxNet):
        if net_or_state.spec != spec:
            raise ValueError(f'network spec {net_or_state.spec} differs from {spec}')
        return net_or_state
    return NnarmaxNet.from_state(spec, net_or_state)


def predict_window(
    net: NnarmaxNet, u: ArrayLike, y: ArrayLike, targets: ArrayLike, mode: Mode
) -> tuple[FloatArray, int]:
    """Predictions over a window: ``(prediction, first)``, prediction[k] = ŷLF(first + k + 1).

    ``series_parallel``: one-step predictions with the targets as feedback; ``parallel``: free run
    with the network's own predictions as feedback, started from the targets at the first row.
    The last row predicts one sample beyond the window.
    """
    if mode not in _MODES:
        raise ValueError(f'mode must be one of {_MODES}, got {mode!r}')
    spec = net.spec
    target_series = as_series(targets, spec.n_outputs, 'targets')
    x_series, first = build_regressors(u, y, target_series, spec)
    fb_init = target_series[first - spec.nfb + 1 : first + 1].copy()
    runner = _WindowPredictor(net, n_static_regressors(spec), spec.nfb)
    with torch.inference_mode():
        prediction = runner(
            torch.from_numpy(x_series), torch.from_numpy(fb_init), mode == 'parallel'
        )
    return prediction.numpy().copy(), first


def evaluate_loss(
    net_or_state: NnarmaxNet | Mapping[str, torch.Tensor],
    spec: NnarmaxSpec,
    u: ArrayLike,
    y: ArrayLike,
    targets: ArrayLike,
    mask: ArrayLike | None,
    mode: Mode,
) -> float:
    """The MSE part of the training objective of a network (or state_dict) on a window.

    The same number ``train`` reports as ``loss``, so candidates can be compared on one window.
    """
    if mode not in _MODES:
        raise ValueError(f'mode must be one of {_MODES}, got {mode!r}')
    net = _as_net(net_or_state, spec)
    window = _prepare_window(spec, u, y, targets, mask)
    runner = _WindowPredictor(net, n_static_regressors(spec), spec.nfb)
    with torch.inference_mode():
        prediction = runner(window.x_series, window.fb_init, mode == 'parallel')
    return _mse(prediction, window)


def warm_up() -> None:
    """Run one tiny training so torch's lazy imports happen now (≈ 2 s), not mid-operation.

    ``torch.func`` imports ``torch._dynamo`` (and sympy) on the first Jacobian; on a worker thread
    that import would hold the GIL and stall the real-time predict path for seconds.
    """
    spec = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=1, nfb=1, hidden_units=2)
    data = np.linspace(0.0, 1.0, 16)[:, np.newaxis] ** 2
    modes: tuple[Mode, ...] = ('series_parallel', 'parallel')
    for mode in modes:
        train(NnarmaxNet(spec), data, data, data, None, TrainSettings(mode=mode, max_epochs=1))
