"""Exploratory: a linear network with no steady-state gain from thrust to its estimate (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/force_dc_probe.py --scenarios rao_supply \
        --seeds 635 636 --closed-loop --loops-only --variant "dc0="

`method_probe.py` with `NnarmaxNet.fit_linear_bypass` patched in this process only (nothing in
the package changes). A wave filter must return the measured position when the vessel rests
under a constant force: positions constant and the thrust constant at whatever level balances
the environment. For the network's predicted step ŷLF(t + 1) − y(t) (relative positions) that
means the lags of every thrust channel sum to zero weight, for every output. In a station-keeping
window the thrust's mean hardly moves, so the plain ridge solve leaves that sum to chance and the
bias cancels it on the window; when the mean thrust changes (a sea-state change, the wave drift
force of a new relative wave heading in a turn, a wind change) the estimate then moves by
(sum of the weights) × (change of the mean thrust) while the vessel does not.

The patch solves the same ridge least-squares problem with the thrust weights of each (thrust
channel, output) constrained to sum to zero: they are written w = N z with N an orthonormal basis
of the zero-sum vectors of the nu lags, so the ridge penalty ‖w‖² = ‖z‖² is the shipped one. In
standardized units the constraint is the same (all lags of a channel share one scale and one
mean). The motion gate's twin is fitted the same way (it is the same class); the package's
`north_east_decoupled` is ignored (every output on every column). Only the plain solve
is patched: the force-prior and held-force paths raise, and `thrust_ridge_validation` (its own
solve) is left as it is. Every variant of the run gets the patch (run the default rows from
another process). Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dof_coupling_probe import plain_problem  # noqa: E402 - the sibling script
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import network  # noqa: E402


def zero_sum_basis(lags: int) -> torch.Tensor:
    """(lags, lags − 1) orthonormal columns spanning the vectors whose entries sum to zero."""
    if lags < 2:
        return torch.zeros((lags, 0), dtype=torch.float64)
    ones = np.ones((lags, 1)) / np.sqrt(lags)
    # The left singular vectors of I − 11ᵀ/n beyond the first span the complement of the ones.
    basis, _, _ = np.linalg.svd(np.eye(lags) - ones @ ones.T)
    return torch.tensor(basis[:, :lags - 1], dtype=torch.float64)


def force_map(nu: int, force_channels: int, n_columns: int) -> torch.Tensor:
    """(n_columns, n_free) map from the free parameters to every weight of one output.

    Regressor layout (lag-major): force column ``lag · force_channels + channel`` for the first
    ``nu · force_channels`` columns, then the positions and the bias, which map to themselves.
    """
    n_force = nu * force_channels
    basis = zero_sum_basis(nu)
    n_free = force_channels * basis.shape[1] + (n_columns - n_force)
    mapping = torch.zeros((n_columns, n_free), dtype=torch.float64)
    for channel in range(force_channels):
        rows = torch.arange(nu) * force_channels + channel
        cols = torch.arange(basis.shape[1]) + channel * basis.shape[1]
        mapping[rows[:, None], cols[None, :]] = basis
    rest = torch.arange(n_columns - n_force)
    mapping[n_force + rest, force_channels * basis.shape[1] + rest] = 1.0
    return mapping


def zero_dc_fit(self: network.NnarmaxNet, x: torch.Tensor, target: torch.Tensor,
                keep: torch.Tensor, ridge: float = network.LINEAR_RIDGE,
                force_prior: float = 0.0, hold_forces: bool = False,
                north_east_decoupled: bool = False) -> None:
    """`NnarmaxNet.fit_linear_bypass` with every thrust channel's lag weights summing to zero."""
    problem = plain_problem(self, x, target, keep, force_prior, hold_forces, 'force-DC')
    if problem is None:
        return
    design, wanted = problem
    mapping = force_map(self.spec.nu, self.spec.n_inputs_u, design.shape[1]).to(design.dtype)
    reduced = design @ mapping  # the bias column stays the last one
    ridges = torch.full((reduced.shape[1] - 1,), ridge, dtype=design.dtype)
    self.set_linear_solution(mapping @ network.solve_ridge(reduced, wanted, ridges))


if __name__ == '__main__':
    setattr(network.NnarmaxNet, 'fit_linear_bypass', zero_dc_fit)  # noqa: B010 - the patch
    sys.exit(method_probe.main(sys.argv[1:]))
