"""NNARMAX network for one-step LF-position prediction (thesis §2.2, §2.3, §4.4, §5.1).

Structure (thesis eq. 2.2, one or more hidden layers):

    x_s = (x − x_mean) / x_std                           input standardization (thesis §2.2.4)
    h_1 = tanh(W_1 x_s + b_1), …, h_L = tanh(W_L h_{L−1} + b_L)     (eq. 2.1, 2.4)
    o   = V h_L + v_0 (+ B x_s)                          linear output (+ optional linear bypass)
    ŷLF(t + 1) = y_mean + y_std · o                      output de-standardization

x is the raw regressor row of ``regressors.build_regressors`` (forces, measured positions, LF
feedback). The standardization statistics live in registered buffers, so a ``state_dict`` (and a
checkpoint) carries everything needed to reproduce a prediction. Positions and feedback share the
y statistics, so the output is in the units of y.

The linear bypass B (default on) is our addition to the thesis network: a tanh network only
interpolates (thesis §2.5), while a DP vessel slowly drifts to positions outside the training
window. The bypass starts as persistence (ŷLF(t + 1) = fb(t)), so an untrained network holds the
last LF value and training learns the correction; switch it off for the plain eq. 2.2 network.

Linear network (``hidden_units`` 0, needs the bypass): no tanh part, ŷLF(t + 1) = y_mean + y_std ·
(v_0 + B x_s), the linear ARX model (eq. 2.2 without hidden layer) on the same regressors. It is
linear in its weights, so `training.train` fits it by one least-squares solve
(``fit_linear_bypass``). The layers keep their names with zero width, so checkpoints, the numpy
predict path and every other user of the state dict stay the same.

Relative coordinates (``NnarmaxSpec.relative``, our addition): a wave filter is translation
invariant — moving the vessel 10 m moves its LF estimate 10 m — but a tanh network fed absolute
positions is not, and fails as soon as the vessel leaves the positions of its training window.
With ``relative`` the network sees y(t−i) − y(t) and fb(t−i) − y(t) and predicts
ŷLF(t + 1) − y(t); y(t) is added back to the output. Forces are unchanged.

Body frame (``NnarmaxSpec.body_frame``, 3 DOF, relative only; issue 13 hypothesis 3): the relative
row is further rotated into the body frame of the row's newest heading ψ(t) (every (north, east)
pair of every lag block by R(ψ(t))ᵀ, see ``regressors``), the network predicts the step as a
body-frame offset and R(ψ(t)) turns it back to north/east. The function is then rotation
invariant: turning the whole run (positions about any point, headings by the same angle) turns
the prediction the same way, for any weights. The standardization statistics are those of the
body-frame quantities (forces R(ψ(t))ᵀu(t), body-frame relative positions).

Heading: the network works on unwrapped heading (a continuous signal); the caller unwraps the
measured yaw before building regressors and wraps the predicted yaw to (−π, π] afterwards.

The predict path uses ``NumpyNnarmax``: an immutable numpy copy of the weights, so a prediction
costs microseconds, needs no autograd, and a retrained network is put in service by swapping one
reference (atomic in Python).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
import functools
import io
import json
import os
from pathlib import Path
import tempfile
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
import torch

from lf_predictor_ros.core.readonly import ReadOnlyArrays
from lf_predictor_ros.core.regressors import (
    RAMP_ORDERS,
    as_series,
    build_regressors,
    first_index,
    n_regressors,
    regressor_vector,
    rotate_blocks,
)

FloatArray = NDArray[np.float64]

__all__ = [
    'CHECKPOINT_FORMAT',
    'CHECKPOINT_VERSION',
    'LINEAR_RIDGE',
    'NnarmaxNet',
    'NnarmaxSpec',
    'NumpyNnarmax',
    'build_regressors',
    'load_checkpoint',
    'predict_step',
    'rotate_blocks_torch',
    'save_checkpoint',
    'solve_ridge',
]

CHECKPOINT_FORMAT = 'lf_predictor_ros.nnarmax'
CHECKPOINT_VERSION = 1
_STD_FLOOR_REL = 1e-12  # [-] a channel with std below this × max(1, |mean|) is not scaled


def _check_count(name: str, value: object, allowed: str, minimum: int) -> None:
    """Raise ValueError unless ``value`` is an int ≥ ``minimum`` (bool is not an int here)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f'NnarmaxSpec.{name} must be {allowed}, got {value!r}')


@dataclass(frozen=True)
class NnarmaxSpec:
    """Shape of an NNARMAX network (thesis §4.4, Algorithm 4.1 line 1).

    ``n_outputs``: position channels (1: surge/north only, 3: north, east, yaw);
    ``n_inputs_u``: force channels (1 or 3); ``nu``, ``ny``, ``nfb``: number of delayed forces,
    measured positions and LF feedback values; ``hidden_units`` per hidden layer (0: the linear
    network, module docstring; needs the bypass); ``hidden_layers`` ≥ 1 (the thesis uses one);
    ``linear_bypass``: add a linear input→output path (see module docstring); ``relative``:
    position regressors and the output are taken relative to the newest measured position y(t)
    (translation invariance, see module docstring);
    ``body_frame``: with ``relative`` and 3 DOF, regressors and output step in the body frame of
    the newest heading (rotation invariance, see module docstring).
    """

    n_outputs: int
    n_inputs_u: int
    nu: int
    ny: int
    nfb: int
    hidden_units: int
    hidden_layers: int = 1
    linear_bypass: bool = True
    relative: bool = False
    body_frame: bool = False
    ramp_invariant: bool = False
    ramp_order: int = 1

    def __post_init__(self) -> None:
        """Validate the spec; raise ValueError naming the broken rule."""
        for name in ('n_outputs', 'n_inputs_u'):
            value = getattr(self, name)
            if value not in (1, 3) or isinstance(value, bool):
                raise ValueError(
                    f'NnarmaxSpec.{name} must be 1 or 3 (1-DOF surge or 3-DOF north/east/yaw), '
                    f'got {value!r}'
                )
        for name in ('nu', 'ny', 'nfb'):
            _check_count(name, getattr(self, name), 'an int ≥ 0 (number of delays)', 0)
        if self.ny + self.nfb < 1:
            raise ValueError(
                'NnarmaxSpec needs ny + nfb ≥ 1: the network must see a position (measured or '
                'fed back) to predict the next one'
            )
        _check_count('hidden_units', self.hidden_units, 'an int ≥ 0', 0)
        _check_count('hidden_layers', self.hidden_layers, 'an int ≥ 1', 1)
        if not isinstance(self.relative, bool):
            raise ValueError(f'NnarmaxSpec.relative must be a bool, got {self.relative!r}')
        if self.relative and self.ny < 1:
            raise ValueError('NnarmaxSpec.relative needs ny ≥ 1: positions are taken relative '
                             'to the newest measured position y(t)')
        if not isinstance(self.linear_bypass, bool):
            raise ValueError(
                f'NnarmaxSpec.linear_bypass must be a bool, got {self.linear_bypass!r}'
            )
        if self.hidden_units == 0 and not self.linear_bypass:
            raise ValueError('NnarmaxSpec.hidden_units = 0 (no tanh part) needs linear_bypass '
                             '= True, or the network has no path from its inputs: set one')
        if not isinstance(self.body_frame, bool):
            raise ValueError(f'NnarmaxSpec.body_frame must be a bool, got {self.body_frame!r}')
        if self.body_frame and not (self.relative and self.n_outputs == 3
                                    and self.n_inputs_u == 3):
            raise ValueError('NnarmaxSpec.body_frame needs relative = True and 3 outputs and 3 '
                             'force channels (north, east, yaw): set them or body_frame False')
        if not isinstance(self.ramp_invariant, bool):
            raise ValueError(
                f'NnarmaxSpec.ramp_invariant must be a bool, got {self.ramp_invariant!r}')
        if self.ramp_invariant and not (self.relative and self.ny >= 2 and self.nfb == 0):
            raise ValueError('NnarmaxSpec.ramp_invariant needs relative = True, ny ≥ 2 (a slope '
                             'needs two positions) and nfb = 0: set them or ramp_invariant False')
        if self.ramp_order not in RAMP_ORDERS or isinstance(self.ramp_order, bool):
            raise ValueError(f'NnarmaxSpec.ramp_order must be one of {RAMP_ORDERS} (1 line, 2 '
                             f'parabola), got {self.ramp_order!r}')
        if self.ramp_invariant and self.ny < self.ramp_order + 1:
            raise ValueError(f'NnarmaxSpec.ramp_order {self.ramp_order} fits a polynomial of that '
                             f'order and needs ny ≥ {self.ramp_order + 1}, got ny {self.ny}')

    @property
    def n_regressors(self) -> int:
        """Length of one regressor row."""
        return n_regressors(self)

    @property
    def linear(self) -> bool:
        """True for the linear network (``hidden_units`` 0): linear in its weights."""
        return self.hidden_units == 0

    @property
    def first_index(self) -> int:
        """First sample index with a full regressor history, max(nu, ny, nfb) − 1."""
        return first_index(self)

    def to_dict(self) -> dict[str, int | bool]:
        """Plain dict (for checkpoints, logs); optional fields only when not at their default.

        ``body_frame`` and ``ramp_invariant`` are written only when True, ``ramp_order`` only
        when not 1: a spec without them writes the same dict (and checkpoint) as before the
        fields existed.
        """
        values: dict[str, int | bool] = dict(asdict(self))
        for name in ('body_frame', 'ramp_invariant'):
            if not values[name]:
                del values[name]
        if values['ramp_order'] == 1:
            del values['ramp_order']
        return values

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> NnarmaxSpec:
        """Inverse of ``to_dict``; unknown or missing keys raise ValueError."""
        names = {f.name for f in fields(cls)}
        unknown = set(values) - names
        if unknown:
            raise ValueError(
                f'unknown NnarmaxSpec fields {sorted(unknown)}; expected {sorted(names)}'
            )
        try:
            return cls(**dict(values))
        except TypeError as exc:
            raise ValueError(f'incomplete NnarmaxSpec {dict(values)}: {exc}') from exc


def relative_spread(y: FloatArray, ny: int, body_frame: bool = False,
                    ramp_invariant: bool = False, ramp_order: int = 1) -> FloatArray:
    """RMS of y(t − i) − y(t) over i = 1 … max(1, ny − 1) and all t, per channel.

    The scale of a relative network's position regressors and of its output ŷLF(t + 1) − y(t).
    With ``body_frame`` (3 channels) each difference is first rotated by R(ψ(t))ᵀ, ψ = y[:, 2].
    With ``ramp_invariant`` the differences are those from the least-squares line through the ny
    newest positions (what such a network sees, ``_relative_regressors_numpy``; with ``ramp_order``
    2 the least-squares parabola).
    """
    if ramp_invariant and y.shape[0] > ny:
        return _detrended_spread(y, ny, body_frame, ramp_order)
    lags = range(1, min(max(1, ny - 1), y.shape[0] - 1) + 1)
    if not lags:
        return np.asarray(y.std(axis=0), dtype=np.float64)
    if body_frame:
        cos, sin = np.cos(y[:, 2]), np.sin(y[:, 2])
        squares = [np.mean(rotate_blocks(y[:-lag] - y[lag:], cos[lag:], -sin[lag:]) ** 2,
                           axis=0) for lag in lags]
        return np.asarray(np.sqrt(np.mean(squares, axis=0)), dtype=np.float64)
    squares = [np.mean((y[:-lag] - y[lag:]) ** 2, axis=0) for lag in lags]
    return np.asarray(np.sqrt(np.mean(squares, axis=0)), dtype=np.float64)


def _detrended_spread(y: FloatArray, ny: int, body_frame: bool, order: int = 1) -> FloatArray:
    """RMS of y(t − i) − (y(t) + Σₖ âₖ(t)·(−i)ᵏ), i = 1 … ny − 1, per channel.

    Order 1: y(t − i) − (y(t) − i·v̂(t)); see ``relative_spread``.
    """
    windows = np.lib.stride_tricks.sliding_window_view(y, ny, axis=0)[..., ::-1]
    block = np.swapaxes(windows, 1, 2)  # (rows, lag i newest first, channel)
    coeffs = np.einsum('ki,rio->rko', ramp_fit_weights(ny, order), block)
    fitted = block[:, :1, :] + np.einsum('ik,rko->rio', _ramp_powers(ny, order), coeffs)
    offsets = (block - fitted)[:, 1:, :]
    if body_frame:
        heading = block[:, 0, 2]
        rows = offsets.reshape(offsets.shape[0], -1)
        offsets = rotate_blocks(rows, np.cos(heading), -np.sin(heading)).reshape(offsets.shape)
    return np.asarray(np.sqrt(np.mean(offsets ** 2, axis=(0, 1))), dtype=np.float64)


def _safe_std(std: FloatArray, mean: FloatArray) -> FloatArray:
    """Standard deviation with constant channels mapped to 1 (no division by ~0)."""
    floor = _STD_FLOOR_REL * np.maximum(1.0, np.abs(mean))
    return np.where(std > floor, std, 1.0)


# [-] per row, standardized units: the ridge of the linear part's least-squares solve on every
# column but the bias (``NnarmaxNet.fit_linear_bypass``)
LINEAR_RIDGE = 1e-6


class _Linear(torch.nn.Linear):
    """torch's Linear, without its default initialization for zero-width weights.

    The layers of the linear network (``hidden_units`` 0) have no weights; torch's init would
    warn that initializing them is a no-op. ``NnarmaxNet.reset_parameters`` sets every weight
    anyway; non-empty layers keep torch's init (and its use of torch's global RNG) as before.
    """

    def reset_parameters(self) -> None:
        """The initialization of torch, unless the weight has no elements."""
        if self.weight.numel() > 0:
            super().reset_parameters()


def solve_ridge(design: torch.Tensor, wanted: torch.Tensor, ridges: torch.Tensor,
                prior: torch.Tensor | None = None) -> torch.Tensor:
    """argmin_w ‖design w − wanted‖² + rows · Σ_j ridges_j (w_j − prior_j)², the last column free.

    ``design`` (rows, n_columns) with the bias column last, ``wanted`` (rows, n_outputs),
    ``ridges`` (n_columns − 1,) or (n_columns − 1, n_outputs): one penalty per column, or per
    column and output (a separate problem per output); ``prior`` (n_columns − 1, n_outputs):
    the weights each penalty pulls towards (None: 0). lstsq (minimum norm) rather than solve:
    in relative mode the y(t) − y(t) column is identically 0, so without a ridge the normal
    matrix is singular.
    """
    rows, n_columns = design.shape
    normal = design.T @ design
    rhs = design.T @ wanted
    per_output = ridges.reshape(n_columns - 1, -1)
    if prior is not None:
        pull = per_output * prior * rows  # (n_columns − 1, n_outputs), broadcast per output
        rhs = rhs + torch.cat((pull, pull.new_zeros(1, pull.shape[1])))
    if per_output.shape[1] == 1:
        solution: torch.Tensor = torch.linalg.lstsq(normal + _penalty(per_output[:, 0], rows),
                                                    rhs, driver='gelsd').solution
        return solution
    columns = [torch.linalg.lstsq(normal + _penalty(per_output[:, i], rows), rhs[:, i:i + 1],
                                  driver='gelsd').solution for i in range(wanted.shape[1])]
    return torch.cat(columns, dim=1)


def column_channels(spec: NnarmaxSpec) -> torch.Tensor:
    """Per regressor column, the channel (DOF) it carries, (n_regressors,) long.

    Lag-major layout (``regressors`` module docstring): force column j carries channel
    j mod n_inputs_u; after the nu · n_inputs_u force columns, position (and feedback) column j
    carries (j − nu · n_inputs_u) mod n_outputs.
    """
    n_force = spec.nu * spec.n_inputs_u
    return torch.tensor([j % spec.n_inputs_u if j < n_force else (j - n_force) % spec.n_outputs
                         for j in range(spec.n_regressors)], dtype=torch.long)


def own_dof_columns(spec: NnarmaxSpec) -> torch.Tensor:
    """Columns each output is solved on with ``north_east_decoupled`` (n_regressors, n_outputs).

    North and east: their own DOF's force and position (and feedback) columns, every lag
    (``column_channels``); the heading (and a 1-DOF output): every column.
    """
    channel = column_channels(spec)
    allowed = torch.ones((spec.n_regressors, spec.n_outputs), dtype=torch.bool)
    if spec.n_outputs == 3:
        for dof in (0, 1):
            allowed[:, dof] = channel == dof
    return allowed


def solve_per_output(design: torch.Tensor, wanted: torch.Tensor, ridge: float,
                     allowed: torch.Tensor) -> torch.Tensor:
    """`solve_ridge` for each output alone on its ``allowed`` columns and the bias (last column).

    ``allowed`` (n_columns − 1, n_outputs) bool; the weights of the other columns are 0. Returns
    (n_columns, n_outputs).
    """
    n_regressors = design.shape[1] - 1
    solution = torch.zeros((n_regressors + 1, wanted.shape[1]), dtype=design.dtype)
    bias = torch.tensor([n_regressors])
    for output in range(wanted.shape[1]):
        columns = torch.cat((torch.nonzero(allowed[:, output])[:, 0], bias))
        ridges = torch.full((columns.numel() - 1,), ridge, dtype=design.dtype)
        fitted = solve_ridge(design[:, columns], wanted[:, output:output + 1], ridges)
        solution[columns, output] = fitted[:, 0]
    return solution


def solve_with_fixed_rows(design: torch.Tensor, wanted: torch.Tensor, ridges: torch.Tensor,
                          fixed: torch.Tensor) -> torch.Tensor:
    """`solve_ridge` with the first ``len(fixed)`` rows of the solution fixed at ``fixed``.

    Their columns' part of ``wanted`` is taken off and the remaining columns (bias last) are
    solved on what is left: an exact constrained least-squares solution, not a limit of ever
    larger ridges. ``fixed`` (n_fixed, n_outputs); returns (n_columns, n_outputs).
    """
    n_fixed = fixed.shape[0]
    rest = solve_ridge(design[:, n_fixed:], wanted - design[:, :n_fixed] @ fixed,
                       ridges[n_fixed:])
    return torch.cat((fixed, rest))


def _penalty(ridges: torch.Tensor, rows: int) -> torch.Tensor:
    """The penalty matrix rows · diag(ridges, 0): the bias (last column) is not penalized."""
    return torch.diag(torch.cat((ridges, ridges.new_zeros(1)))) * rows


class NnarmaxNet(torch.nn.Module):
    """NNARMAX network: raw regressor rows (rows, n_regressors) → ŷLF(t + 1) (rows, n_outputs)."""

    u_mean: torch.Tensor
    u_std: torch.Tensor
    y_mean: torch.Tensor
    y_std: torch.Tensor

    def __init__(self, spec: NnarmaxSpec, *, seed: int = 0) -> None:
        """Create the layers in float64 and initialize them reproducibly from ``seed``."""
        super().__init__()
        self.spec = spec
        widths = [spec.n_regressors] + [spec.hidden_units] * spec.hidden_layers
        self.hidden = torch.nn.ModuleList(
            _Linear(widths[i], widths[i + 1], dtype=torch.float64)
            for i in range(spec.hidden_layers)
        )
        self.output = _Linear(spec.hidden_units, spec.n_outputs, dtype=torch.float64)
        self.bypass: torch.nn.Linear | None = (
            torch.nn.Linear(spec.n_regressors, spec.n_outputs, bias=False, dtype=torch.float64)
            if spec.linear_bypass
            else None
        )
        f64 = torch.float64
        self.register_buffer('u_mean', torch.zeros(spec.n_inputs_u, dtype=f64))
        self.register_buffer('u_std', torch.ones(spec.n_inputs_u, dtype=f64))
        self.register_buffer('y_mean', torch.zeros(spec.n_outputs, dtype=f64))
        self.register_buffer('y_std', torch.ones(spec.n_outputs, dtype=f64))
        self.reset_parameters(seed)

    def reset_parameters(self, seed: int) -> None:
        """Seeded initialization: hidden layers U(±1/√fan_in), output 0, bypass = persistence.

        With a zero output layer the untrained network is exactly the bypass, i.e. it predicts
        ŷLF(t + 1) = fb(t) (or y(t) when nfb = 0); without a bypass it predicts the window mean.
        """
        generator = torch.Generator().manual_seed(seed)
        with torch.no_grad():
            for layer in self.hidden_layers():
                bound = 1.0 / float(np.sqrt(layer.in_features))
                layer.weight.copy_(_uniform(layer.weight.shape, bound, generator))
                layer.bias.copy_(_uniform(layer.bias.shape, bound, generator))
            self.output.weight.zero_()
            self.output.bias.zero_()
            if self.bypass is not None:
                self.bypass.weight.copy_(_persistence_matrix(self.spec))

    def hidden_layers(self) -> list[torch.nn.Linear]:
        """The tanh layers, input side first."""
        return [cast(torch.nn.Linear, layer) for layer in self.hidden]

    def regressor_standardization(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(mean, std) of every regressor column, expanded from the u and y statistics."""
        spec = self.spec
        mean = torch.cat(
            (self.u_mean.repeat(spec.nu), self.y_mean.repeat(spec.ny + spec.nfb))
        )
        std = torch.cat((self.u_std.repeat(spec.nu), self.y_std.repeat(spec.ny + spec.nfb)))
        return mean, std

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Predict ŷLF(t + 1) for raw regressor rows ``x`` of shape (rows, n_regressors)."""
        if self.spec.relative:
            ref, shift, base = _relative_frame_torch(self.spec, x)
            relative = x - shift
            if self.spec.body_frame:
                cos, sin = torch.cos(ref[:, 2]), torch.sin(ref[:, 2])
                body = self._forward_absolute(rotate_blocks_torch(relative, cos, -sin))
                return base + rotate_blocks_torch(body, cos, sin)
            return base + self._forward_absolute(relative)
        return self._forward_absolute(x)

    def _forward_absolute(self, x: torch.Tensor) -> torch.Tensor:
        x_mean, x_std = self.regressor_standardization()
        x_s = (x - x_mean) / x_std
        hidden = x_s
        for layer in self.hidden_layers():
            hidden = torch.tanh(layer(hidden))
        out: torch.Tensor = self.output(hidden)
        if self.bypass is not None:
            out = out + self.bypass(x_s)
        return self.y_mean + self.y_std * out

    def fit_linear_bypass(self, x: torch.Tensor, target: torch.Tensor, keep: torch.Tensor,
                          ridge: float = LINEAR_RIDGE, force_prior: float = 0.0,
                          hold_forces: bool = False, north_east_decoupled: bool = False) -> None:
        """Solve the linear bypass and output bias by ridge least squares, in place.

        ``x`` (rows, n_regressors) raw regressor rows, ``target`` (rows, n_outputs) the values
        ŷLF(t + 1) should take, ``keep`` (rows,) bool rows that count. The tanh part is held
        fixed and the bypass B and bias v0 minimize ‖ŷLF − target‖² + ridge·rows·‖B‖² in
        standardized units, i.e. the linear ARX model (eq. 2.2 without hidden layer) on the
        residual of the tanh part. A linear least-squares problem has one global optimum, found
        in one solve; gradient-based training then starts from it (series-parallel only: the
        feedback columns must hold the targets). No-op without a bypass.

        ``force_prior`` > 0: the force columns' ridge is ``force_prior`` per row towards their
        current weights (the warm start's, in the current standardization) instead of
        ``ridge`` towards 0. A window whose forces add nothing to the positions (a DP loop
        without excitation: the thrust is a function of the filter's own past estimates) then
        leaves those weights where earlier windows put them, instead of setting them freely
        (``PredictorParams.thrust_prior``).

        ``hold_forces``: the force columns' weights stay exactly at their current values (the
        warm start's) and the other columns and the bias are the least-squares solution given
        them (``force_prior`` has nothing to act on then; ``PredictorParams.thrust_hold``).

        ``north_east_decoupled`` (3 outputs; no effect with 1): the north and east outputs are
        each solved on their own DOF's force and position columns and the bias, their other
        weights 0; the heading output on every column (``own_dof_columns``,
        ``PredictorParams.north_east_decoupled``). Not with ``force_prior`` or ``hold_forces``.
        """
        if self.bypass is None:
            return
        design, wanted = self.linear_problem(x, target, keep)
        if north_east_decoupled and wanted.shape[1] == 3:
            if force_prior > 0.0 or hold_forces:
                raise ValueError('north_east_decoupled solves every output on its own columns: '
                                 'it does not combine with force_prior or hold_forces')
            self.set_linear_solution(solve_per_output(design, wanted, ridge,
                                                      own_dof_columns(self.spec)))
            return
        ridges = torch.full((design.shape[1] - 1,), ridge, dtype=design.dtype)
        n_force = self.spec.nu * self.spec.n_inputs_u
        if hold_forces:
            with torch.no_grad():
                held = self.bypass.weight.T[:n_force].clone()
            self.set_linear_solution(solve_with_fixed_rows(design, wanted, ridges, held))
            return
        prior = None
        if force_prior > 0.0:
            ridges[:n_force] = force_prior
            with torch.no_grad():
                prior = torch.zeros((design.shape[1] - 1, wanted.shape[1]), dtype=design.dtype)
                prior[:n_force] = self.bypass.weight.T[:n_force]
        self.set_linear_solution(solve_ridge(design, wanted, ridges, prior))

    def linear_problem(self, x: torch.Tensor, target: torch.Tensor, keep: torch.Tensor
                       ) -> tuple[torch.Tensor, torch.Tensor]:
        """The least-squares problem (design, wanted) of ``fit_linear_bypass``.

        design: the kept rows' standardized regressors with a ones column (the bias) last;
        wanted: what the bypass must add to the tanh part's output there (rows, n_outputs), in
        the network's frame (relative, body) and units.
        """
        with torch.no_grad():
            step = target
            if self.spec.relative:
                ref, shift, base = _relative_frame_torch(self.spec, x)
                x = x - shift
                step = target - base
                if self.spec.body_frame:
                    cos, sin = torch.cos(ref[:, 2]), torch.sin(ref[:, 2])
                    x = rotate_blocks_torch(x, cos, -sin)
                    step = rotate_blocks_torch(step, cos, -sin)
            x_mean, x_std = self.regressor_standardization()
            x_s = ((x - x_mean) / x_std)[keep]
            hidden = x_s
            for layer in self.hidden_layers():
                hidden = torch.tanh(layer(hidden))
            wanted = (step[keep] - self.y_mean) / self.y_std
            residual = wanted - (hidden @ self.output.weight.T)
            design = torch.cat((x_s, torch.ones(x_s.shape[0], 1, dtype=x_s.dtype)), dim=1)
        return design, residual

    def set_linear_solution(self, solution: torch.Tensor) -> None:
        """Put a solution of ``linear_problem`` in the bypass and the output bias.

        ``solution`` (n_regressors + 1, n_outputs): the bypass rows, then the bias row.
        """
        if self.bypass is None:
            raise ValueError('the network has no linear bypass to set: build it with '
                             'linear_bypass = True')
        with torch.no_grad():
            self.bypass.weight.copy_(solution[:-1].T)
            self.output.bias.copy_(solution[-1])

    def free_run(
        self, x_static: torch.Tensor, fb_init: torch.Tensor, *, differentiable: bool = True
    ) -> torch.Tensor:
        """Parallel (recurrent) run: the feedback regressors are the network's own predictions.

        ``x_static`` (rows, n_static): the force and measured-position columns of the regressor
        rows (everything but the feedback block); ``fb_init`` (nfb, n_outputs): the feedback
        values before the first row, oldest first. Returns ŷLF(t + 1) for every row, equal to
        calling ``forward`` row by row with the feedback block replaced by earlier outputs, but
        the feedback-free part of the first layer is computed once for the whole window and the
        recursion runs in standardized units (the feedback shares the y statistics, so the
        standardized feedback is the raw output o itself). With ``differentiable`` the recursion
        is built from torch ops (BPTT, forward-mode AD); without it, it runs in numpy on detached
        weights, about 3× faster, for evaluations that need no gradient.
        """
        spec = self.spec
        if spec.nfb == 0:
            return self.forward(x_static)
        if spec.body_frame:
            raise ValueError('NnarmaxNet.free_run has no body-frame recursion: train a '
                             'body_frame network with LF feedback series-parallel')
        n_static = x_static.shape[1]
        ref_s: torch.Tensor | None = None
        if spec.relative:
            offset = _position_offset(spec)
            ref = x_static[:, offset:offset + spec.n_outputs]
            x_static = x_static - _relative_shift(spec, ref)[:, :n_static]
            ref_s = ref / self.y_std  # y_mean is 0 in relative mode
        x_mean, x_std = self.regressor_standardization()
        x_s = (x_static - x_mean[:n_static]) / x_std[:n_static]
        layers = self.hidden_layers()
        first = layers[0]
        hidden_pre = x_s @ first.weight[:, :n_static].T + first.bias
        out_static = self.output.bias.expand(x_s.shape[0], spec.n_outputs)
        if self.bypass is not None:
            out_static = out_static + x_s @ self.bypass.weight[:, :n_static].T
        recursion = _Recursion(
            hidden_fb=first.weight[:, n_static:],
            bypass_fb=None if self.bypass is None else self.bypass.weight[:, n_static:],
            output_weight=self.output.weight,
            deeper=tuple((layer.weight, layer.bias) for layer in layers[1:]),
        )
        fb_standardized = (fb_init - self.y_mean) / self.y_std
        if differentiable:
            outputs = recursion.run_torch(hidden_pre, out_static, fb_standardized, ref_s)
        else:
            outputs = torch.from_numpy(
                recursion.run_numpy(hidden_pre, out_static, fb_standardized, ref_s)
            )
        return self.y_mean + self.y_std * outputs

    def set_standardization(
        self, u: ArrayLike, y: ArrayLike, *, preserve_function: bool = True
    ) -> None:
        """Set the standardization buffers from training data (thesis §2.2.4).

        ``u`` (n, n_inputs_u) forces and ``y`` (n, n_outputs) positions (unwrapped heading).
        With ``preserve_function`` the weights are transformed exactly so the network computes the
        same function as before (a warm start stays a warm start when the window's mean and spread
        move); without it only the buffers change.
        """
        u_series = as_series(u, self.spec.n_inputs_u, 'u')
        y_series = as_series(y, self.spec.n_outputs, 'y')
        if u_series.shape[0] < 2 or y_series.shape[0] < 2:
            raise ValueError('set_standardization needs at least 2 samples of u and y')
        if not (np.all(np.isfinite(u_series)) and np.all(np.isfinite(y_series))):
            raise ValueError(
                'set_standardization got NaN/inf in u or y: drop invalid samples first'
            )
        if self.spec.body_frame:  # the network sees forces R(ψ(t))ᵀu(t)
            u_series = rotate_blocks(u_series, np.cos(y_series[:, 2]), -np.sin(y_series[:, 2]))
        u_mean = u_series.mean(axis=0)
        y_mean = y_series.mean(axis=0)
        u_std = _safe_std(u_series.std(axis=0), u_mean)
        y_std = _safe_std(y_series.std(axis=0), y_mean)
        if self.spec.relative:
            # Relative positions y(t−i) − y(t) are centred on 0 and their size is the motion
            # within the regressor span (wave motion + a few seconds of drift), not the window's
            # spread: over a 10-min window a drifting vessel spreads tens of metres, which would
            # squeeze every relative regressor and output into a sliver of the tanh range.
            y_mean = np.zeros_like(y_mean)
            y_std = _safe_std(relative_spread(y_series, self.spec.ny, self.spec.body_frame,
                                              self.spec.ramp_invariant, self.spec.ramp_order),
                              y_mean)
        new = {
            'u_mean': torch.from_numpy(u_mean),
            'u_std': torch.from_numpy(u_std),
            'y_mean': torch.from_numpy(y_mean),
            'y_std': torch.from_numpy(y_std),
        }
        with torch.no_grad():
            if preserve_function:
                self._reparameterize(new)
            for name, value in new.items():
                getattr(self, name).copy_(value)

    def _reparameterize(self, new: Mapping[str, torch.Tensor]) -> None:
        """Transform the weights so the function is unchanged under new statistics ``new``.

        x_s,old = a ⊙ x_s,new + c with a = std_new/std_old, c = (mean_new − mean_old)/std_old, and
        o_new = k ⊙ o_old + (y_mean_old − y_mean_new)/y_std_new with k = y_std_old/y_std_new.
        """
        spec = self.spec
        old_mean, old_std = self.regressor_standardization()
        lag_blocks = spec.ny + spec.nfb
        new_mean = torch.cat((new['u_mean'].repeat(spec.nu), new['y_mean'].repeat(lag_blocks)))
        new_std = torch.cat((new['u_std'].repeat(spec.nu), new['y_std'].repeat(lag_blocks)))
        scale_in = new_std / old_std
        shift_in = (new_mean - old_mean) / old_std
        first = self.hidden_layers()[0]
        first.bias.add_(first.weight @ shift_in)
        first.weight.mul_(scale_in)
        k = self.y_std / new['y_std']
        out_bias = self.output.bias.clone()
        if self.bypass is not None:
            out_bias += self.bypass.weight @ shift_in
            self.bypass.weight.mul_(scale_in).mul_(k[:, None])
        self.output.weight.mul_(k[:, None])
        self.output.bias.copy_(k * out_bias + (self.y_mean - new['y_mean']) / new['y_std'])

    @classmethod
    def from_state(cls, spec: NnarmaxSpec, state: Mapping[str, torch.Tensor]) -> NnarmaxNet:
        """Build a network from a spec and a state_dict (strict; ValueError on a mismatch)."""
        net = cls(spec)
        try:
            net.load_state_dict(dict(state), strict=True)
        except (RuntimeError, KeyError) as exc:
            raise ValueError(
                f'state_dict does not fit NnarmaxSpec {spec.to_dict()}: {exc}'.splitlines()[0]
            ) from exc
        return net


@dataclass(frozen=True)
class _Recursion:
    """Feedback-dependent part of one NNARMAX step, in standardized units (see ``free_run``)."""

    hidden_fb: torch.Tensor  # (H, nfb·n_out) first-layer weights of the feedback block
    bypass_fb: torch.Tensor | None  # (n_out, nfb·n_out) bypass weights of the feedback block
    output_weight: torch.Tensor  # (n_out, H)
    deeper: tuple[tuple[torch.Tensor, torch.Tensor], ...]  # (weight, bias) of layers 2…L

    def run_torch(
        self, hidden_pre: torch.Tensor, out_static: torch.Tensor, fb_init: torch.Tensor,
        ref: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Standardized outputs o for every row, differentiable.

        With ``ref`` (rows, n_out) — relative mode — the feedback enters relative to the row's
        reference and the reference is added back to the output.
        """
        feedback = list(fb_init.unbind(0))  # oldest first
        outputs = []
        for row, (hidden_row, out_row) in enumerate(
                zip(hidden_pre.unbind(0), out_static.unbind(0), strict=True)):
            fb_vector = torch.cat(feedback[::-1]) if len(feedback) > 1 else feedback[0]
            if ref is not None:
                fb_vector = fb_vector - ref[row].repeat(len(feedback))
            hidden = torch.tanh(hidden_row + self.hidden_fb @ fb_vector)
            for weight, bias in self.deeper:
                hidden = torch.tanh(weight @ hidden + bias)
            out = out_row + self.output_weight @ hidden
            if self.bypass_fb is not None:
                out = out + self.bypass_fb @ fb_vector
            if ref is not None:
                out = out + ref[row]
            outputs.append(out)
            feedback = feedback[1:] + [out]
        return torch.stack(outputs)

    def run_numpy(
        self, hidden_pre: torch.Tensor, out_static: torch.Tensor, fb_init: torch.Tensor,
        ref: torch.Tensor | None = None,
    ) -> FloatArray:
        """Standardized outputs o for every row, in numpy on detached values (no gradient)."""
        refs = None if ref is None else _detached(ref)
        hidden_rows = _detached(hidden_pre)
        out_rows = _detached(out_static)
        hidden_fb = _detached(self.hidden_fb)
        bypass_fb = None if self.bypass_fb is None else _detached(self.bypass_fb)
        output_weight = _detached(self.output_weight)
        deeper = [(_detached(weight), _detached(bias)) for weight, bias in self.deeper]
        feedback = list(_detached(fb_init))
        outputs = np.empty_like(out_rows)
        with np.errstate(over='ignore', invalid='ignore'):  # a diverging trial step: inf
            for row in range(out_rows.shape[0]):
                fb_vector = np.concatenate(feedback[::-1]) if len(feedback) > 1 else feedback[0]
                if refs is not None:
                    fb_vector = fb_vector - np.tile(refs[row], len(feedback))
                hidden = np.tanh(hidden_rows[row] + hidden_fb @ fb_vector)
                for weight, bias in deeper:
                    hidden = np.tanh(weight @ hidden + bias)
                out = out_rows[row] + output_weight @ hidden
                if bypass_fb is not None:
                    out = out + bypass_fb @ fb_vector
                if refs is not None:
                    out = out + refs[row]
                outputs[row] = out
                feedback = feedback[1:] + [out]
        return outputs


def without_force_inputs(state: Mapping[str, torch.Tensor], spec: NnarmaxSpec,
                         ) -> dict[str, torch.Tensor]:
    """A copy of a network state whose force regressors have no effect at all.

    The weights of the first hidden layer and of the linear bypass on the ``nu · n_inputs_u``
    force columns are set to 0 and the force standardization to (0, 1): the network then gives
    the same output for any thrust (used after training on zeroed forces, whose weights got no
    gradient and would otherwise keep their random initial values).
    """
    columns = spec.nu * spec.n_inputs_u
    new = {name: value.clone() for name, value in state.items()}
    for name in ('hidden.0.weight', 'bypass.weight'):
        if name in new:
            new[name][:, :columns] = 0.0
    new['u_mean'] = torch.zeros_like(new['u_mean'])
    new['u_std'] = torch.ones_like(new['u_std'])
    return new


def _detached(tensor: torch.Tensor) -> FloatArray:
    """float64 numpy view of a tensor without gradient tracking."""
    array: FloatArray = tensor.detach().cpu().numpy()
    return array


def _uniform(shape: torch.Size, bound: float, generator: torch.Generator) -> torch.Tensor:
    """U(−bound, bound) samples in float64 from an explicit generator."""
    return (torch.rand(shape, generator=generator, dtype=torch.float64) * 2.0 - 1.0) * bound


def _persistence_matrix(spec: NnarmaxSpec) -> torch.Tensor:
    """Bypass weights (standardized units) that output the newest feedback (or measured) value."""
    matrix = torch.zeros(spec.n_outputs, spec.n_regressors, dtype=torch.float64)
    block_start = spec.nu * spec.n_inputs_u
    if spec.nfb > 0:
        block_start += spec.ny * spec.n_outputs
    for channel in range(spec.n_outputs):
        matrix[channel, block_start + channel] = 1.0
    return matrix


def _position_offset(spec: NnarmaxSpec) -> int:
    """Column of y(t) (the newest measured position) in a regressor row."""
    return spec.nu * spec.n_inputs_u


def _relative_shift(spec: NnarmaxSpec, ref: torch.Tensor) -> torch.Tensor:
    """Per-row shift that makes the position and feedback blocks relative to ``ref`` = y(t)."""
    zeros = torch.zeros(ref.shape[0], spec.nu * spec.n_inputs_u, dtype=ref.dtype)
    return torch.cat((zeros, ref.repeat(1, spec.ny + spec.nfb)), dim=1)


def ramp_slope_weights(ny: int) -> FloatArray:
    """C with v̂ = Σᵢ cᵢ y(t − i), i = 0 … ny − 1: the least-squares slope per sample.

    The line a + v̂·(−i) fitted to the ny newest positions; Σ cᵢ = 0 (translation invariant) and
    Σ cᵢ·(−i) = 1 (a ramp's slope is returned exactly).
    """
    if ny < 2:
        raise ValueError(f'a slope needs ny ≥ 2 positions, got ny = {ny}')
    lags = np.arange(ny, dtype=np.float64)
    centred = lags - lags.mean()
    weights: FloatArray = -centred / float(np.sum(centred ** 2))
    return weights


@functools.lru_cache(maxsize=16)
def ramp_fit_weights(ny: int, order: int = 1) -> FloatArray:
    """W (order, ny) with âₖ = Σᵢ Wₖᵢ y(t − i): the least-squares polynomial's coefficients.

    The polynomial a₀ + Σₖ aₖ·(−i)ᵏ, k = 1 … order, fitted to the ny newest positions
    (i = 0 … ny − 1, newest first); row k − 1 returns aₖ (per sample^k). Order 1 is
    ``ramp_slope_weights``. Every row sums to 0 (translation invariance) and a polynomial of at
    most that order is returned exactly. Cached: the array is read-only.
    """
    if order == 1:
        weights = ramp_slope_weights(ny)[None, :]
    elif ny < order + 1:
        raise ValueError(f'a polynomial of order {order} needs ny ≥ {order + 1} positions, '
                         f'got ny = {ny}')
    else:
        vandermonde = _ramp_powers(ny, order, constant=True)
        weights = np.asarray(np.linalg.pinv(vandermonde)[1:], dtype=np.float64)
    weights.setflags(write=False)
    return weights


@functools.lru_cache(maxsize=32)
def _ramp_powers(ny: int, order: int, constant: bool = False) -> FloatArray:
    """(ny, order) matrix of (−i)ᵏ, i = 0 … ny − 1, k = 1 … order (k from 0 with constant)."""
    lags = -np.arange(ny, dtype=np.float64)
    powers = np.arange(0 if constant else 1, order + 1)
    matrix = np.asarray(lags[:, None] ** powers[None, :], dtype=np.float64)
    matrix.setflags(write=False)
    return matrix


def _relative_frame_torch(spec: NnarmaxSpec, x: torch.Tensor,
                          ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(ref, shift, base) of raw regressor rows ``x``: see ``_relative_regressors_numpy``."""
    offset = _position_offset(spec)
    n_out = spec.n_outputs
    ref = x[:, offset:offset + n_out]
    if not spec.ramp_invariant:
        return ref, _relative_shift(spec, ref), ref
    block = x[:, offset:offset + spec.ny * n_out].reshape(x.shape[0], spec.ny, n_out)
    weights = torch.tensor(ramp_fit_weights(spec.ny, spec.ramp_order))
    coeffs = torch.einsum('ki,rio->rko', weights, block)
    powers = torch.tensor(_ramp_powers(spec.ny, spec.ramp_order))
    line = ref[:, None, :] + torch.einsum('ik,rko->rio', powers, coeffs)
    zeros = torch.zeros(x.shape[0], spec.nu * spec.n_inputs_u, dtype=x.dtype)
    return ref, torch.cat((zeros, line.reshape(x.shape[0], -1)), dim=1), ref + coeffs.sum(dim=1)


def _relative_regressors_numpy(spec: NnarmaxSpec, x: FloatArray,
                               ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(ref, x − shift, base) of raw regressor rows ``x`` (rows, n_regressors) or one row.

    ref = y(t), the newest measured position. The network sees ``x − shift`` and its output is
    added to ``base``. Plain relative: shift = ref on every position and feedback block, base =
    ref (translation invariance). ``ramp_invariant``: shift = the least-squares line through the
    ny newest positions (ref − i·v̂ on lag block i, ``ramp_slope_weights``) and base = ref + v̂,
    so a vessel moving at constant velocity is followed without lag for any weights (a ramp
    leaves only the forces and the constant bias in front of the network). The shift of the
    force blocks is 0, so they are passed as they are; the position blocks are shifted block by
    block (the same numbers as subtracting a whole shift row, without building it).
    """
    offset = _position_offset(spec)
    n_out = spec.n_outputs
    ref = x[..., offset:offset + n_out]
    positions = x[..., offset:].reshape(x.shape[:-1] + (-1, n_out))  # ny (+ nfb) blocks
    if spec.ramp_invariant:  # nfb = 0 (params rule): the blocks are the ny positions
        coeffs = np.einsum('ki,...io->...ko', ramp_fit_weights(spec.ny, spec.ramp_order),
                           positions)
        line = ref[..., None, :] + np.einsum('ik,...ko->...io',
                                             _ramp_powers(spec.ny, spec.ramp_order), coeffs)
        shifted, base = positions - line, ref + coeffs.sum(axis=-2)
    else:
        shifted, base = positions - ref[..., None, :], ref
    relative = np.concatenate((x[..., :offset], shifted.reshape(x.shape[:-1] + (-1,))), axis=-1)
    return ref, relative, base


def rotate_blocks_torch(values: torch.Tensor, cos: torch.Tensor,
                        sin: torch.Tensor) -> torch.Tensor:
    """``regressors.rotate_blocks`` in torch (differentiable, vmap-safe): rows (rows, 3·k)."""
    blocks = values.reshape(values.shape[0], -1, 3)
    c, s = cos[:, None], sin[:, None]
    north, east = blocks[..., 0], blocks[..., 1]
    rotated = torch.stack((c * north - s * east, s * north + c * east, blocks[..., 2]), dim=-1)
    return rotated.reshape(values.shape)


def _frozen(array: torch.Tensor) -> FloatArray:
    """Detached float64 numpy copy marked read-only."""
    copy = np.array(array.detach().cpu().numpy(), dtype=np.float64, copy=True)
    copy.setflags(write=False)
    return copy


@dataclass(frozen=True, eq=False)
class NumpyNnarmax(ReadOnlyArrays):
    """Immutable numpy copy of an ``NnarmaxNet`` for the real-time predict path.

    Computes exactly ``NnarmaxNet.forward`` (float64) without torch. Arrays are read-only; a new
    network is published by replacing the reference to the whole object.
    """

    spec: NnarmaxSpec
    x_mean: FloatArray
    x_std: FloatArray
    hidden_weights: tuple[FloatArray, ...]
    hidden_biases: tuple[FloatArray, ...]
    output_weight: FloatArray
    output_bias: FloatArray
    bypass_weight: FloatArray | None
    y_mean: FloatArray
    y_std: FloatArray
    # (low, high) of every regressor as the network sees it (network frame: relative, rotated)
    # over its training window; the predict path clips to it. None: no clip (``with_range``).
    regressor_range: tuple[FloatArray, FloatArray] | None = None
    # (low, high) of the network's own output (the predicted step of a relative network, before
    # the base and the rotation) over the same window; the predict path clips to it too.
    output_range: tuple[FloatArray, FloatArray] | None = None

    @classmethod
    def from_module(cls, net: NnarmaxNet) -> NumpyNnarmax:
        """Copy the weights and standardization of ``net`` (the module is not modified)."""
        x_mean, x_std = net.regressor_standardization()
        return cls(
            spec=net.spec,
            x_mean=_frozen(x_mean),
            x_std=_frozen(x_std),
            hidden_weights=tuple(_frozen(layer.weight) for layer in net.hidden_layers()),
            hidden_biases=tuple(_frozen(layer.bias) for layer in net.hidden_layers()),
            output_weight=_frozen(net.output.weight),
            output_bias=_frozen(net.output.bias),
            bypass_weight=None if net.bypass is None else _frozen(net.bypass.weight),
            y_mean=_frozen(net.y_mean),
            y_std=_frozen(net.y_std),
        )

    def with_range(self, x: FloatArray, widen: float = 1.0) -> NumpyNnarmax:
        """A copy of this network that clips every regressor to its range over the raw rows ``x``.

        ``x`` (rows, n_regressors): the training window's regressor rows; ``widen`` ≥ 1: each
        range (regressors and output) widened that many times about its centre, so a wave a
        little larger than the window's largest is still filtered. The range is taken in
        the network frame (after the relative shift and the body-frame rotation), so a turn or a
        move, whose relative positions and forces lie far outside a station-keeping window's,
        reaches the network as the largest values it was fitted on: the learned filter does not
        extrapolate its fit (a cross-DOF coefficient fitted on 0.01 rad of wave yaw, applied to
        0.8 rad of turn, moved the north estimate 6 m; docs/BENCHMARKS.md "Fifteenth
        session"). Every row of ``x`` itself is predicted exactly as without the clip.
        """
        if not widen >= 1.0:
            raise ValueError(f'with_range: widen must be ≥ 1 (1 = the window range), got {widen}')
        raw = np.asarray(x, dtype=np.float64)
        if raw.ndim != 2 or raw.shape[0] == 0 or raw.shape[1] != self.spec.n_regressors or \
                not np.all(np.isfinite(raw)):
            raise ValueError(f'with_range needs finite regressor rows (rows ≥ 1, '
                             f'{self.spec.n_regressors}), got shape {raw.shape}; NaN/inf rows '
                             'must be dropped first')
        rows = network_frame_regressors(self.spec, raw)
        outputs = replace(self, regressor_range=None, output_range=None)._forward_absolute(rows)
        return replace(self, regressor_range=_column_range(rows, widen),
                       output_range=_column_range(outputs, widen))

    def range_meta(self) -> dict[str, list[list[float]]]:
        """The clip ranges as checkpoint meta entries (``with_saved_ranges``); {} without."""
        if self.regressor_range is None or self.output_range is None:
            return {}
        return {'regressor_range': [a.tolist() for a in self.regressor_range],
                'output_range': [a.tolist() for a in self.output_range]}

    def with_saved_ranges(self, meta: Mapping[str, Any]) -> NumpyNnarmax:
        """A copy with the clip ranges a checkpoint's meta carries (``range_meta``).

        A checkpoint without them, or with ranges that do not fit the network, gives the network
        unclipped (as a predictor without regressor_clip saved it).
        """
        ranges = []
        for key, width in (('regressor_range', self.spec.n_regressors),
                           ('output_range', self.spec.n_outputs)):
            try:
                low, high = (np.array(v, dtype=np.float64) for v in meta[key])
            except (KeyError, TypeError, ValueError):
                return self
            if low.shape != (width,) or high.shape != (width,) or \
                    not (np.all(np.isfinite(low)) and np.all(low <= high)):
                return self
            low.setflags(write=False)
            high.setflags(write=False)
            ranges.append((low, high))
        return replace(self, regressor_range=ranges[0], output_range=ranges[1])

    def forward(self, x: FloatArray) -> FloatArray:
        """ŷLF(t + 1) for regressor rows (rows, n_regressors) or one row (n_regressors,)."""
        if not self.spec.relative:
            return self._forward_absolute(x)
        rows, base, turn = _network_frame(self.spec, x)
        out = self._forward_absolute(rows)
        if turn is not None:
            out = rotate_blocks(out, *turn)
        result: FloatArray = base + out
        return result

    def _forward_absolute(self, x: FloatArray) -> FloatArray:
        # the clips as np.minimum(np.maximum(·)): np.clip's numbers (low ≤ high, NaN kept) at
        # half its cost on the predict path
        if self.regressor_range is not None:
            x = np.minimum(np.maximum(x, self.regressor_range[0]), self.regressor_range[1])
        x_s = (x - self.x_mean) / self.x_std
        hidden = x_s
        for weight, bias in zip(self.hidden_weights, self.hidden_biases, strict=True):
            hidden = np.tanh(hidden @ weight.T + bias)
        out = hidden @ self.output_weight.T + self.output_bias
        if self.bypass_weight is not None:
            out = out + x_s @ self.bypass_weight.T
        result: FloatArray = self.y_mean + self.y_std * out
        if self.output_range is not None:
            result = np.minimum(np.maximum(result, self.output_range[0]), self.output_range[1])
        return result


def _column_range(rows: FloatArray, widen: float) -> tuple[FloatArray, FloatArray]:
    """Read-only (low, high) of every column of ``rows``: (min, max) widened about the centre."""
    low, high = np.array(rows.min(axis=0)), np.array(rows.max(axis=0))
    if widen != 1.0:
        centre, half = 0.5 * (low + high), 0.5 * widen * (high - low)
        low, high = centre - half, centre + half
    low.setflags(write=False)
    high.setflags(write=False)
    return low, high


def network_frame_regressors(spec: NnarmaxSpec, x: FloatArray) -> FloatArray:
    """The regressor rows as the network's layers see them (before the standardization).

    Relative networks: the rows shifted by ``_relative_regressors_numpy``, body-frame ones
    then rotated by the row's newest heading; absolute networks: ``x`` itself.
    """
    return _network_frame(spec, x)[0] if spec.relative else x


def _network_frame(spec: NnarmaxSpec, x: FloatArray,
                   ) -> tuple[FloatArray, FloatArray, tuple[FloatArray, FloatArray] | None]:
    """(rows, base, turn) of a relative network's raw rows ``x``.

    ``rows``: what its layers see; its output is rotated by ``turn`` = (cos ψ, sin ψ) of the
    row's newest heading (body frame; None in the earth frame) and added to ``base``.
    """
    ref, relative, base = _relative_regressors_numpy(spec, x)
    if not spec.body_frame:
        return relative, base, None
    cos, sin = np.cos(ref[..., 2]), np.sin(ref[..., 2])
    return rotate_blocks(relative, cos, -sin), base, (cos, sin)


def predict_step(
    net: NumpyNnarmax | NnarmaxNet,
    u_hist: FloatArray,
    y_hist: FloatArray,
    fb_hist: FloatArray,
) -> FloatArray:
    """One-step prediction ŷLF(t + 1), shape (n_outputs,) (thesis Algorithm 4.1 lines 14–17).

    Histories are time series, oldest first and newest (time t) last, with at least nu, ny, nfb
    rows: ``u_hist`` forces, ``y_hist`` measured positions (unwrapped heading), ``fb_hist`` the
    previous LF predictions. Use a ``NumpyNnarmax`` for the real-time path (tens of µs); a
    ``NnarmaxNet`` is accepted and evaluated under ``torch.inference_mode``.
    """
    x = regressor_vector(u_hist, y_hist, fb_hist, net.spec)
    if isinstance(net, NumpyNnarmax):
        return net.forward(x)
    with torch.inference_mode():
        prediction: FloatArray = net(torch.from_numpy(x)[None, :])[0].numpy().copy()
    return prediction


def save_checkpoint(
    path: str | os.PathLike[str],
    spec: NnarmaxSpec,
    state: Mapping[str, torch.Tensor],
    meta: Mapping[str, Any] | None = None,
) -> None:
    """Write spec, state_dict and JSON metadata to ``path`` atomically (temp file + rename).

    The state must fit the spec (checked by loading it into a fresh network) and ``meta`` must be
    JSON-serializable (e.g. training loss, ω0, time stamps).
    """
    NnarmaxNet.from_state(spec, state)
    try:
        meta_json = json.dumps(dict(meta or {}))
    except (TypeError, ValueError) as exc:
        raise ValueError(f'checkpoint meta must be JSON-serializable: {exc}') from exc
    payload = {
        'format': CHECKPOINT_FORMAT,
        'version': CHECKPOINT_VERSION,
        'spec': spec.to_dict(),
        'state': {name: value.detach().cpu().clone() for name, value in state.items()},
        'meta_json': meta_json,
    }
    target = Path(path)
    handle, tmp_name = tempfile.mkstemp(prefix=f'.{target.name}.', dir=target.parent or '.')
    try:
        with os.fdopen(handle, 'wb') as stream:
            torch.save(payload, stream)
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


def load_checkpoint(
    path: str | os.PathLike[str], expected_spec: NnarmaxSpec | None = None
) -> tuple[NnarmaxSpec, dict[str, torch.Tensor], dict[str, Any]]:
    """Read a checkpoint written by ``save_checkpoint``: ``(spec, state_dict, meta)``.

    Raises ValueError for a corrupt or foreign file, a different format version, a state that does
    not fit its spec, or a spec different from ``expected_spec`` (when given). A missing file
    raises FileNotFoundError.
    """
    raw = Path(path).read_bytes()
    try:
        payload = torch.load(io.BytesIO(raw), map_location='cpu', weights_only=True)
    except Exception as exc:  # torch raises many types for a damaged zip/pickle
        raise ValueError(
            f'checkpoint {path} is corrupt or not a torch file ({type(exc).__name__}); delete '
            'it and train again'
        ) from exc
    if not isinstance(payload, dict) or payload.get('format') != CHECKPOINT_FORMAT:
        raise ValueError(
            f'{path} is not an NNARMAX checkpoint (format tag {CHECKPOINT_FORMAT!r} missing)'
        )
    version = payload.get('version')
    if version != CHECKPOINT_VERSION:
        raise ValueError(
            f'checkpoint {path} has format version {version!r}, this software reads version '
            f'{CHECKPOINT_VERSION}: retrain the network or convert the file'
        )
    try:
        spec = NnarmaxSpec.from_dict(payload['spec'])
        state = {str(name): value for name, value in payload['state'].items()}
        meta = json.loads(payload['meta_json'])
    except (KeyError, TypeError, AttributeError, json.JSONDecodeError) as exc:
        raise ValueError(
            f'checkpoint {path} is corrupt: missing or damaged field ({exc})'
        ) from exc
    if expected_spec is not None and spec != expected_spec:
        raise ValueError(
            f'checkpoint {path} holds a network {spec.to_dict()}, but {expected_spec.to_dict()} '
            'was expected: change the predictor parameters or retrain'
        )
    if not isinstance(meta, dict):
        raise ValueError(f'checkpoint {path} is corrupt: meta is not a JSON object')
    NnarmaxNet.from_state(spec, state)
    return spec, state, meta
