"""Exploratory: the north/east outputs of the linear network without heading regressors (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/heading_column_probe.py --scenarios rao_supply \
        --seeds 635 636 --closed-loop --loops-only --variant "noheading=" [--drop-moment]

`method_probe.py` with `NnarmaxNet.fit_linear_bypass` patched in this process only (nothing in
the package changes). `turn_part_probe.py` found that in a turn the network's north/east
estimate errs by metres and that nearly all of it is what the north/east rows' weights on the
relative heading lags ψ(t − i) − ψ(t) add: in station keeping those lags carry only wave motion
(a feature the fit uses, 0.03–0.11 m RMS of the estimate), in a turn they carry tenths of a
radian. The patch solves the shipped ridge problem with the north and east outputs' weights on
the heading position columns fixed at 0 (``--drop-moment``: on the yaw-moment columns too); the
heading output keeps every column. The motion gate's twin is fitted the same way (it is the same
class). The package's `north_east_decoupled` is ignored (the probe sets the coupling itself).
Only the plain solve is patched: the force-prior and held-force paths raise, and
`thrust_ridge_validation` (its own solve) is left as it is. Every variant of the run gets the
patch (run the default rows from another process). Development seeds only, as
`method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dof_coupling_probe import plain_problem  # noqa: E402 - the sibling script
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import network  # noqa: E402

HEADING = 2  # channel of the heading (and of the yaw moment) in every lag block
DROP_MOMENT = False  # ``--drop-moment``: the north/east rows lose the yaw-moment columns too


def dropped_columns(spec: network.NnarmaxSpec, drop_moment: bool) -> torch.Tensor:
    """Regressor columns the north/east outputs do without (``network.column_channels``)."""
    heading = network.column_channels(spec) == HEADING
    if not drop_moment:  # the yaw-moment (force) columns stay
        heading[:spec.nu * spec.n_inputs_u] = False
    return torch.nonzero(heading)[:, 0]


def no_heading_fit(self: network.NnarmaxNet, x: torch.Tensor, target: torch.Tensor,
                   keep: torch.Tensor, ridge: float = network.LINEAR_RIDGE,
                   force_prior: float = 0.0, hold_forces: bool = False,
                   north_east_decoupled: bool = False) -> None:
    """`NnarmaxNet.fit_linear_bypass`, the north/east rows without the heading columns."""
    problem = plain_problem(self, x, target, keep, force_prior, hold_forces, 'heading-column')
    if problem is None:
        return
    design, wanted = problem
    n_regressors, n_outputs = design.shape[1] - 1, wanted.shape[1]
    ridges = torch.full((n_regressors,), ridge, dtype=design.dtype)
    solution = network.solve_ridge(design, wanted, ridges)
    if n_outputs == 3:  # 1 DOF: nothing to drop
        dropped = dropped_columns(self.spec, DROP_MOMENT)
        kept = torch.ones(n_regressors + 1, dtype=torch.bool)
        kept[dropped] = False
        columns = torch.nonzero(kept)[:, 0]  # the bias (last) is kept
        fitted = network.solve_ridge(design[:, columns], wanted[:, :HEADING],
                                     ridges[columns[:-1]])
        solution[:, :HEADING] = 0.0
        solution[columns, :HEADING] = fitted
    self.set_linear_solution(solution)


if __name__ == '__main__':
    setattr(network.NnarmaxNet, 'fit_linear_bypass', no_heading_fit)  # noqa: B010 - the patch
    argv = sys.argv[1:]
    if '--drop-moment' in argv:
        argv.remove('--drop-moment')
        DROP_MOMENT = True
    sys.exit(method_probe.main(argv))
