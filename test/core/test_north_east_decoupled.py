"""North/east per DOF in the linear network's least-squares solve (`north_east_decoupled`)."""
from __future__ import annotations

import functools

import numpy as np
import pytest
import torch

from lf_predictor_ros.core.network import (
    NnarmaxNet,
    NnarmaxSpec,
    own_dof_columns,
    solve_per_output,
    solve_ridge,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.retraining import (
    Snapshot,
    network_spec,
    run_retraining,
    train_settings,
)
from lf_predictor_ros.core.training import TrainSettings, train
from sim_ros.simulation import load_scenario, simulate

pytestmark = pytest.mark.filterwarnings(
    'ignore:`torch.jit.script` is deprecated:DeprecationWarning')


def test_own_dof_columns_gives_north_and_east_their_own_lags_and_the_heading_all() -> None:
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=3, nfb=0, hidden_units=0,
                       relative=True)
    allowed = own_dof_columns(spec).numpy()
    # lag-major: forces u(t), u(t−1) as (N, E, ψ) pairs of three, then y(t), y(t−1), y(t−2)
    north = [0, 3, 6, 9, 12]
    east = [1, 4, 7, 10, 13]
    assert allowed.shape == (15, 3)
    assert np.flatnonzero(allowed[:, 0]).tolist() == north
    assert np.flatnonzero(allowed[:, 1]).tolist() == east
    assert allowed[:, 2].all()
    one = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=2, ny=3, nfb=0, hidden_units=0)
    assert own_dof_columns(one).numpy().all()


def test_the_per_output_solve_recovers_a_decoupled_system_and_zeroes_the_rest() -> None:
    rng = np.random.default_rng(4)
    rows, columns = 4000, 6
    x = rng.standard_normal((rows, columns))
    design = torch.tensor(np.column_stack([x, np.ones(rows)]))
    # north reads columns 0 and 3 (+ bias 0.5), east 1 and 4, the heading everything
    truth = np.zeros((columns + 1, 3))
    truth[[0, 3, 6], 0] = [1.0, -2.0, 0.5]
    truth[[1, 4, 6], 1] = [0.7, 0.3, -0.1]
    truth[:, 2] = [0.2, -0.4, 0.1, 0.3, -0.2, 0.6, 0.05]
    # the heading leaks into north and east through a column they must not read: a fit on every
    # column would take it, the per-DOF fit cannot
    leak = 0.8 * x[:, 2:3] * np.array([[1.0, 1.0, 0.0]])
    wanted = torch.tensor(design.numpy() @ truth + leak + 0.01 * rng.standard_normal((rows, 3)))
    allowed = torch.zeros((columns, 3), dtype=torch.bool)
    allowed[[0, 3], 0] = True
    allowed[[1, 4], 1] = True
    allowed[:, 2] = True
    solution = solve_per_output(design, wanted, 1e-9, allowed).numpy()
    assert np.all(solution[:-1][~allowed.numpy()] == 0.0)
    # the leak is independent of the kept columns: it only adds noise, standard error
    # 0.8 / √4000 = 0.013 per coefficient; 0.05 is four of them
    np.testing.assert_allclose(solution[[0, 3, 6], 0], [1.0, -2.0, 0.5], atol=0.05)
    np.testing.assert_allclose(solution[[1, 4, 6], 1], [0.7, 0.3, -0.1], atol=0.05)
    # the heading output is the coupled solve's (the outputs of a ridge problem are separable)
    coupled = solve_ridge(design, wanted, torch.full((columns,), 1e-9, dtype=torch.float64))
    np.testing.assert_allclose(solution[:, 2], coupled.numpy()[:, 2], rtol=0.0, atol=1e-10)


@functools.cache
def _threedof_snapshot() -> Snapshot:
    record = simulate(load_scenario('threedof_open_loop'), 3, 1500.0)
    return Snapshot(u=np.array(record.thrust), y=np.array(record.measured_pose),
                    end_index=len(record.t) - 1, segment=1)


def test_a_3dof_training_keeps_only_own_dof_weights_in_north_and_east() -> None:
    torch.set_num_threads(1)
    snapshot = _threedof_snapshot()
    params = PredictorParams(motion_gate=False, north_east_decoupled=False)
    coupled = run_retraining(params, snapshot, None, None, None)
    decoupled = run_retraining(params.replace(north_east_decoupled=True), snapshot, None, None,
                               None)
    assert coupled.state_dict is not None and decoupled.state_dict is not None
    weights = decoupled.state_dict['bypass.weight'].numpy()  # (outputs, regressors)
    allowed = own_dof_columns(network_spec(params)).numpy().T
    assert np.all(weights[~allowed] == 0.0)
    # their own columns are used (all but perhaps the y(t) − y(t) column, identically 0)
    assert np.count_nonzero(weights[:2]) >= np.count_nonzero(allowed[:2]) - 2
    np.testing.assert_allclose(weights[2], coupled.state_dict['bypass.weight'].numpy()[2],
                               rtol=0.0, atol=1e-9)
    # the coupled fit does use the other DOFs' columns in north and east
    assert np.abs(coupled.state_dict['bypass.weight'].numpy()[:2][~allowed[:2]]).max() > 1e-3


def test_a_1dof_training_is_untouched() -> None:
    torch.set_num_threads(1)
    record = simulate(load_scenario('onedof_excited'), 1, 1500.0)
    snapshot = Snapshot(u=np.array(record.thrust[:, :1]), y=np.array(record.measured_pose[:, :1]),
                        end_index=len(record.t) - 1, segment=1)
    plain = run_retraining(PredictorParams(ndof=1, north_east_decoupled=False), snapshot, None,
                           None, None)
    flagged = run_retraining(PredictorParams(ndof=1, north_east_decoupled=True), snapshot, None,
                             None, None)
    assert plain.state_dict is not None and flagged.state_dict is not None
    assert flagged.loss == plain.loss
    for name, value in plain.state_dict.items():
        assert torch.equal(flagged.state_dict[name], value), name
    # the trainer is not even asked to decouple one output
    assert not train_settings(PredictorParams(ndof=1, north_east_decoupled=True)
                              ).north_east_decoupled
    assert train_settings(PredictorParams(north_east_decoupled=True)).north_east_decoupled
    assert not train_settings(PredictorParams(north_east_decoupled=True, thrust_hold=True)
                              ).north_east_decoupled  # the hold's own solve stays coupled


@pytest.mark.parametrize('changes', [{'hold_forces': True}, {'force_prior': 0.01},
                                     {'force_ridge_grid': (1.0,), 'validation_rows': 10}])
def test_train_settings_refuse_a_second_rule_on_the_solve(changes: dict[str, object]) -> None:
    with pytest.raises(ValueError, match='north_east_decoupled solves each output on its own'):
        TrainSettings(north_east_decoupled=True, **changes)  # type: ignore[arg-type]


def test_a_3dof_tanh_network_refuses_the_option_at_training() -> None:
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=3, nfb=0, hidden_units=2,
                       relative=True)
    rng = np.random.default_rng(0)
    u, y = rng.standard_normal((200, 3)), rng.standard_normal((200, 3))
    with pytest.raises(ValueError, match='needs the linear network solved by least squares'):
        train(NnarmaxNet(spec), u, y, y, None,
              TrainSettings(north_east_decoupled=True, max_epochs=1))
