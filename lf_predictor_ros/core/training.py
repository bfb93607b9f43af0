"""Model-agnostic trainer for regressor networks (thesis §2.2.2–2.2.3, §4.3, Alg. 4.1 l. 36–40).

In the spirit of karpathy/minGPT's trainer, this module knows nothing about layers. It needs a
``torch.nn.Module`` with a ``spec`` (``nu``, ``ny``, ``nfb``, ``n_outputs``, ``n_inputs_u``) whose
``forward`` maps raw regressor rows (``regressors.build_regressors`` layout) to the next LF
position, a ``free_run(x_static, fb_init)`` for the parallel mode and, when
``TrainSettings.standardize`` is on, a ``set_standardization(u, y)`` method (``NnarmaxNet`` has
all three). The window and the objective's data residuals on it are `training_window`; the
Levenberg–Marquardt Jacobian and normal equations are `lm_jacobian`; this module holds the
settings, the least-squares solve of the linear network and the optimizers' loops.

Objective (thesis eq. 2.6 and 2.8 with a = 1, b = ``weight_decay``, plus our derivative term):

    J(w) = MSE + d · MSE_Δ + b · Σ w_j²   (sum over the tanh part: the linear bypass is free)
    MSE   = mean over kept samples and channels of ((ŷLF(t+1) − yT(t+1)) / s)²
    MSE_Δ = mean over kept consecutive pairs of ((Δŷ − ΔyT) / s_Δ)²,  Δx(t+1) = x(t+1) − x(t)

s is the per-channel scale of what the network predicts (``training_window.loss_scale``: the std of
the kept targets, or for a relative network the RMS of yT(t+1) − y(t)) and s_Δ the RMS of the
targets' first differences, so the loss is dimensionless, treats metres and radians alike and is
comparable between candidate networks on the same window. For a body-frame network
(``spec.body_frame``) the errors, steps and differences are taken in the body frame of the row's
newest heading ψ(t) (north and east rotated by R(ψ(t))ᵀ) before scaling, so s is per surge/sway and
the loss is rotation invariant like the network. The derivative term answers the thesis's
closed-loop failure (§5.4.2: the prediction's derivative had the wrong sign, so a PID's D-term
steered with the waves). Samples with ``mask`` False (the last ε, thesis Algorithm 4.1 line 38)
contribute no error.

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
  dynamic-backpropagation recursion through the feedback (``lm_jacobian.prediction_jacobian``).
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
from typing import Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
import torch

from lf_predictor_ros.core.lm_jacobian import (
    FlatParameters,
    LmScratch,
    damped_step,
    lm_normal_equations,
    one_layer_prediction,
    window_prediction,
)
from lf_predictor_ros.core.network import LINEAR_RIDGE, NnarmaxNet, NnarmaxSpec, solve_ridge
from lf_predictor_ros.core.regressors import as_series, build_regressors, n_static_regressors
from lf_predictor_ros.core.training_window import (
    TrainingWindow,
    WindowPredictor,
    data_residuals,
    prepare_window,
    window_mse,
)

FloatArray = NDArray[np.float64]
Algorithm = Literal['lm', 'lbfgs', 'adam']
BASE_RIDGE = LINEAR_RIDGE  # every column's ridge but the thrust's (validated_force_ridges)
Mode = Literal['series_parallel', 'parallel']

_ALGORITHMS = ('lm', 'lbfgs', 'adam')
_MODES = ('series_parallel', 'parallel')


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
    window = prepare_window(spec, u, y, targets, mask)
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
    runner = WindowPredictor(model, n_static_regressors(spec), spec.nfb)
    parallel = settings.mode == 'parallel'
    with torch.no_grad():
        initial_objective, prediction = _objective(runner, window, parallel, settings)
        initial_loss = window_mse(prediction, window)
    run = _Run(settings, stop_event, start, [])
    optimizers: dict[str, Callable[[WindowPredictor, TrainingWindow, bool, _Run], str]] = {
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
            loss = window_mse(prediction, window)
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
    runner: WindowPredictor, window: TrainingWindow, parallel: bool, settings: TrainSettings
) -> tuple[torch.Tensor, torch.Tensor]:
    """(J(w), prediction) with autograd through the runner's parameters."""
    prediction = runner(window.x_series, window.fb_init, parallel)
    residuals = data_residuals(prediction, window, settings.derivative_weight)
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


def _levenberg_marquardt(
    runner: WindowPredictor, window: TrainingWindow, parallel: bool, run: _Run
) -> str:
    """Levenberg–Marquardt (thesis eq. 2.7) with trainlm-style μ adaptation."""
    settings = run.settings
    layout = FlatParameters.of(runner.net)
    decay = decay_vector(runner.net, settings.weight_decay)

    def residual_fn(flat: torch.Tensor) -> torch.Tensor:
        prediction = one_layer_prediction(runner, layout, flat, window, parallel, scratch)
        if prediction is None:
            prediction = window_prediction(runner, layout, flat, window, parallel)
        return data_residuals(prediction, window, settings.derivative_weight)

    def objective_of(flat: torch.Tensor, residuals: torch.Tensor) -> float:
        return float(torch.sum(residuals**2) + torch.sum(decay * flat**2))

    scratch = LmScratch()  # one epoch's Jacobian is dead at the next's
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
        jtj, jtr, by_factors = lm_normal_equations(runner, layout, weights, window, parallel,
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
                step = damped_step(gauss_newton, mu, gradient)
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


def _mse_residuals_from(residuals: torch.Tensor, window: TrainingWindow) -> torch.Tensor:
    """The MSE block at the head of a data-residual vector."""
    n_mse = int(window.keep.sum()) * window.target.shape[1]
    return residuals[:n_mse]


def _gradient_descent(
    runner: WindowPredictor,
    window: TrainingWindow,
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
        return float(objective), window_mse(prediction, window)

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


def _lbfgs(runner: WindowPredictor, window: TrainingWindow, parallel: bool, run: _Run) -> str:
    """L-BFGS with strong-Wolfe line search, one iteration per epoch."""
    optimizer = torch.optim.LBFGS(
        runner.parameters(), lr=1.0, max_iter=1, max_eval=_LBFGS_MAX_EVAL, history_size=20,
        line_search_fn='strong_wolfe', tolerance_grad=0.0, tolerance_change=0.0,
    )
    return _gradient_descent(runner, window, parallel, run, optimizer)


def _adam(runner: WindowPredictor, window: TrainingWindow, parallel: bool, run: _Run) -> str:
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
    runner = WindowPredictor(net, n_static_regressors(spec), spec.nfb)
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
    window = prepare_window(spec, u, y, targets, mask)
    runner = WindowPredictor(net, n_static_regressors(spec), spec.nfb)
    with torch.inference_mode():
        prediction = runner(window.x_series, window.fb_init, mode == 'parallel')
    return window_mse(prediction, window)


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
