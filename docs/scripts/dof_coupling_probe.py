"""Exploratory: each output DOF of the linear network on its own DOF's regressors (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/dof_coupling_probe.py --scenarios rao_supply \
        --seeds 559 560 --closed-loop --loops-only --variant "perdof=" [--yaw-coupled]

`method_probe.py` with `NnarmaxNet.fit_linear_bypass` patched in this process only (nothing in
the package changes): the least-squares solve of the linear network (the shipped default,
``hidden_units`` 0: that solve is its whole training) is done per output, on the output's own
force channel and its own position channel (all their lags) and the bias; the other weights are
0. With ``--yaw-coupled`` only north and east are fitted so; the heading keeps every column.
The motion gate's twin is fitted the same way (it is the same class). For 1 DOF nothing
changes. It is the twenty-first session's ``dof_coupling: none`` (removed in `fce8467`, screened
then on the tanh network of that time), on today's defaults: `truth_window_probe.py` found that
a sliding ARX fitted on the true LF pose extrapolates to the RAO vessels' manoeuvres far better
per DOF than coupled (docs/BENCHMARKS.md, fortieth session). Every variant of the run gets the
patch (run the default rows from another process). The package's `north_east_decoupled` (the
``--yaw-coupled`` fit as an option, since the forty-second session) is ignored: the probe sets
the coupling itself. Only the plain solve is patched: the force-prior and held-force paths raise,
and `thrust_ridge_validation` (its own solve) is left coupled. Development seeds only, as
`method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import network  # noqa: E402

# Output DOFs that keep every regressor (``--yaw-coupled``: the heading, 2); the others are fitted
# on their own DOF's columns.
COUPLED_OUTPUTS: set[int] = set()


def plain_problem(net: network.NnarmaxNet, x: torch.Tensor, target: torch.Tensor,
                  keep: torch.Tensor, force_prior: float, hold_forces: bool, probe: str
                  ) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The plain least-squares problem of a patched `fit_linear_bypass` (None: no bypass).

    Shared by the probes that replace the solve; they patch the plain solve only.
    """
    if net.bypass is None:
        return None
    if force_prior > 0.0 or hold_forces:
        raise NotImplementedError(f'the {probe} probe patches the plain solve only')
    return net.linear_problem(x, target, keep)


def per_dof_fit(self: network.NnarmaxNet, x: torch.Tensor, target: torch.Tensor,
                keep: torch.Tensor, ridge: float = network.LINEAR_RIDGE,
                force_prior: float = 0.0, hold_forces: bool = False,
                north_east_decoupled: bool = False) -> None:
    """`NnarmaxNet.fit_linear_bypass`, one ridge least-squares problem per output DOF."""
    problem = plain_problem(self, x, target, keep, force_prior, hold_forces, 'per-DOF')
    if problem is None:
        return
    design, wanted = problem
    n_regressors, n_outputs = design.shape[1] - 1, wanted.shape[1]
    dofs = network.column_channels(self.spec)
    allowed = torch.stack([dofs == dof if dof not in COUPLED_OUTPUTS else
                           torch.ones(n_regressors, dtype=torch.bool) for dof in range(n_outputs)],
                          dim=1)
    self.set_linear_solution(network.solve_per_output(design, wanted, ridge, allowed))

if __name__ == '__main__':
    setattr(network.NnarmaxNet, 'fit_linear_bypass', per_dof_fit)  # noqa: B010 - the patch
    argv = sys.argv[1:]
    if '--yaw-coupled' in argv:  # the heading keeps its coupled fit; north and east per DOF
        argv.remove('--yaw-coupled')
        COUPLED_OUTPUTS.add(2)
    sys.exit(method_probe.main(argv))
