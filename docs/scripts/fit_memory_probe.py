"""The linear fit with a memory of the data that left its window (directional forgetting).

    OMP_NUM_THREADS=1 python docs/scripts/fit_memory_probe.py --memory-time 3600 -- \
        --scenarios onedof_feedback --seeds 503 504 --duration 7200 --closed-loop \
        --loops-only --variant default --variant "mem=thrust_prior:1"

An exploratory pre-check for issue 13 (hypotheses 1 and 2; docs/BENCHMARKS.md, thirty-eighth
session), not part of the package. Everything after ``--`` is `method_probe.py`'s command line;
this script only replaces `NnarmaxNet.fit_linear_bypass` in its process. **It borrows the
``thrust_prior`` field as its switch**: a variant with ``thrust_prior: c`` > 0 fits with the
memory below, with ``c`` its forgetting constant (``thrust_prior``'s own prior is not used
here); a variant without it fits as the package does.

The memory (per network: the holding network and the motion gate's ramp-invariant twin) holds,
in raw regressor units and centred (every group of rows keeps its own mean: the bias stays
free), the information matrix C and the vector h = C m of the rows that have left the sliding
training window since the loop started: at each training, the rows of the previous window
before the first row of this one (matched by their raw regressor values; no match: the window
restarted, the memory is emptied). Then

1. the memory is forgotten in time, C, h ← λ C, λ h with λ = exp(−Δ / ``--memory-time``);
2. it is forgotten in the directions this window identifies (directional forgetting, as in
   recursive least squares with directional forgetting, Kulhavý 1987): in the standardized
   units of the fit, with C = L Lᵀ and the window's own centred information W, the
   eigen-decomposition L⁻¹ W L⁻ᵀ = V diag(σ) Vᵀ gives C ← L V diag(1 / (1 + σ / c)) Vᵀ Lᵀ:
   where the window holds at least as much information as the memory (σ ≳ c) the memory
   fades, where it holds little (the thrust's directions in station keeping, where the thrust
   is a function of the filter's own past estimates) the memory stays;
3. the fit minimizes ‖D w − y‖² + ridge + (w − m)ᵀ C (w − m) over the window's rows, the bias
   free, and the forgotten memory is kept for the next training.

The first training and every restart fit as the package does (empty memory).

The package accepts a candidate only if its loss on the window is within 2 % of the network in
service's (`retraining._judge`). A memory candidate minimizes the window's error *plus* the
memory's penalty, so on the window alone it is often worse: in the pre-check's runs most
candidates were rejected after the first twenty minutes, and the network in service aged.
``--judge-penalized`` judges a memory candidate as what it is, the optimum of the penalized
objective (where the network in service is one feasible point and cannot be better): only the
finiteness test and the causal cascade's loss (`run_retraining`) can reject it.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import math
from pathlib import Path
import sys
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

import method_probe  # noqa: E402

from lf_predictor_ros.core import retraining  # noqa: E402
from lf_predictor_ros.core.network import LINEAR_RIDGE, NnarmaxNet  # noqa: E402

RETRAIN_PERIOD = 60.0  # [s] the shipped Δ (the memory's time forgetting is per training)
_ORIGINAL = NnarmaxNet.fit_linear_bypass


class Memory:
    """The departed rows' centred information (raw units) and the last window's rows."""

    def __init__(self) -> None:
        """Empty."""
        self.info: torch.Tensor | None = None  # C (n, n)
        self.vector: torch.Tensor | None = None  # h = C m (n, n_outputs)
        self.previous: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None
        self.trainings = 0
        self.resets = 0

    def clear(self) -> None:
        """Forget everything (a restarted window, a new loop)."""
        self.info, self.vector = None, None
        self.resets += 1


MEMORIES: dict[bool, Memory] = {}
SETTINGS: dict[str, float] = {'memory_time': 3600.0, 'judge_penalized': 0.0}
LAST_FIT = {'memory': False}  # did the newest fit use the memory (inline training: its judge)
_ORIGINAL_JUDGE = retraining._judge


def judge(loss: float, objective: float, initial_objective: float,
          incumbent_loss: float | None, state: dict[str, torch.Tensor]) -> tuple[bool, str]:
    """`retraining._judge`; with ``--judge-penalized`` a memory fit skips the loss tests."""
    if SETTINGS['judge_penalized'] and LAST_FIT['memory']:
        return _ORIGINAL_JUDGE(loss, math.nan, math.nan, None, state)
    return _ORIGINAL_JUDGE(loss, objective, initial_objective, incumbent_loss, state)


def centred(design: torch.Tensor, wanted: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(Xcᵀ Xc, Xcᵀ Yc) of the regressor columns (bias column dropped), centred on the rows."""
    x = design[:, :-1]
    xc = x - x.mean(dim=0)
    yc = wanted - wanted.mean(dim=0)
    return xc.T @ xc, xc.T @ yc


def _departed(memory: Memory, x: torch.Tensor) -> int | None:
    """Rows of the previous window before this window's first row (None: no match)."""
    if memory.previous is None:
        return None
    prev_x = memory.previous[0]
    hits = torch.nonzero(torch.all(prev_x == x[0], dim=1)).flatten()
    return int(hits[0]) if hits.numel() else None


def fit_with_memory(self: NnarmaxNet, x: torch.Tensor, target: torch.Tensor, keep: torch.Tensor,
                    ridge: float = LINEAR_RIDGE, force_prior: float = 0.0,
                    hold_forces: bool = False, north_east_decoupled: bool = False) -> None:
    """`NnarmaxNet.fit_linear_bypass` with the memory (module docstring) when force_prior > 0."""
    if hold_forces:
        raise ValueError('the memory probe does not combine with thrust_hold: switch it off')
    LAST_FIT['memory'] = False
    if force_prior <= 0.0 or self.bypass is None:
        _ORIGINAL(self, x, target, keep, ridge, north_east_decoupled=north_east_decoupled)
        return
    constant = force_prior
    memory = MEMORIES.setdefault(self.spec.ramp_invariant, Memory())
    memory.trainings += 1
    mean, std = self.regressor_standardization()
    y_std = self.y_std
    # 1. the rows that left the window since the last training join the memory (raw units)
    start = _departed(memory, x)
    if start is None:
        memory.clear()
    elif start > 0:
        prev_x, prev_target, prev_keep = memory.previous  # type: ignore[misc]
        keep_d = prev_keep[:start]
        if int(keep_d.sum()) > 2:
            design_d, wanted_d = self.linear_problem(prev_x[:start], prev_target[:start], keep_d)
            raw_design = design_d.clone()
            raw_design[:, :-1] = design_d[:, :-1] * std + mean
            info_d, vector_d = centred(raw_design, wanted_d * y_std)
            memory.info = info_d if memory.info is None else memory.info + info_d
            memory.vector = vector_d if memory.vector is None else memory.vector + vector_d
    memory.previous = (x.clone(), target.clone(), keep.clone())
    design, wanted = self.linear_problem(x, target, keep)
    if memory.info is None or memory.vector is None:
        _ORIGINAL(self, x, target, keep, ridge, north_east_decoupled=north_east_decoupled)
        return
    # 2. forgetting in time, then in the directions the window identifies (standardized units)
    decay = math.exp(-RETRAIN_PERIOD / SETTINGS['memory_time'])
    info_raw, vector_raw = memory.info * decay, memory.vector * decay
    n = info_raw.shape[0]
    eye = torch.eye(n, dtype=info_raw.dtype)
    scale = torch.outer(std, std)
    info_s = info_raw * scale  # C_s = D C D (x_s = (x − mean) / std, D = diag(std))
    vector_s = (vector_raw * std[:, None]) / y_std[None, :]
    jitter = 1e-9 * max(float(torch.trace(info_s)) / n, 1e-12)
    means = torch.linalg.solve(info_s + jitter * eye, vector_s)  # the memory's own solution
    factor = torch.linalg.cholesky(info_s + jitter * eye)
    window_info, _ = centred(design, wanted)
    whitened = torch.linalg.solve_triangular(factor, window_info, upper=False)
    whitened = torch.linalg.solve_triangular(factor, whitened.T, upper=False).T
    sigma, vectors = torch.linalg.eigh((whitened + whitened.T) / 2)
    keep_share = 1.0 / (1.0 + sigma.clamp(min=0.0) / constant)
    basis = factor @ vectors
    info_kept = (basis * keep_share) @ basis.T
    # 3. the fit: window + memory prior, the bias free
    rows = design.shape[0]
    normal = design.T @ design
    normal[:-1, :-1] += info_kept
    normal += torch.diag(torch.cat((torch.full((n,), ridge, dtype=normal.dtype),
                                    normal.new_zeros(1)))) * rows
    rhs = design.T @ wanted
    rhs[:-1] += info_kept @ means
    solution = torch.linalg.lstsq(normal, rhs, driver='gelsd').solution
    self.set_linear_solution(solution)
    LAST_FIT['memory'] = True
    memory.info = info_kept / scale
    memory.vector = memory.info @ ((means * y_std[None, :]) / std[:, None])


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--memory-time', type=float, default=3600.0,
                        help='time constant of the forgetting in time [s]')
    parser.add_argument('--judge-penalized', action='store_true',
                        help='a memory candidate is not judged on the window loss alone')
    parser.add_argument('rest', nargs=argparse.REMAINDER, help='-- method_probe arguments')
    args = parser.parse_args(argv)
    rest: list[Any] = [a for a in args.rest if a != '--']
    SETTINGS['memory_time'] = args.memory_time
    SETTINGS['judge_penalized'] = float(args.judge_penalized)
    retraining._judge = judge
    NnarmaxNet.fit_linear_bypass = fit_with_memory  # type: ignore[method-assign]
    try:
        return method_probe.main(rest)
    finally:
        for twin, memory in MEMORIES.items():
            print(f'# memory ({"twin" if twin else "holding"}): {memory.trainings} trainings, '
                  f'{memory.resets} resets', file=sys.stderr)


if __name__ == '__main__':
    sys.exit(main())
