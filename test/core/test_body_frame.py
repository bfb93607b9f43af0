"""Body-frame regressors (``PredictorParams.regressor_frame``, issue 13 hypothesis 3).

'earth' (the default) must stay the code before the field existed: the stored run
``data/earth_frame_run.npz`` (3 DOF, 400 s at h = 1 s, turns of +90° and −135° across ±π,
body-frame wave motion; small Algorithm 4.1 windows, 15 trainings) was recorded with commit
7b27a2a, before ``regressor_frame`` existed, by the inline predictor (one torch thread). The
comparison allows `EARTH_TOLERANCE`: the run was bit-identical on the machine that stored it and
on CI, but on another CPU (an AMD EPYC with AVX-512, the fourteenth session) the outputs differ
in the last bits from the first ω0 estimate on (row 80: the FFT and the kernels round
differently) and the trainings grow that to 5.4e-9 m; a change of the earth-frame computation
(another regressor, filter or loss) moves the output by orders of magnitude more.

'body' makes the learned filter rotation invariant: a body-frame network computes the same
function at every heading, so turning a whole input run (positions about the origin, every
heading by the same angle, body-frame forces unchanged) turns its prediction the same way, for
any weights; training on the turned window gives the same network. An earth-frame network does
not have that property.
"""
from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
import pytest
import torch

from lf_predictor_ros.core.filters import zero_phase
from lf_predictor_ros.core.network import (
    NnarmaxNet,
    NnarmaxSpec,
    NumpyNnarmax,
    relative_spread,
    rotate_blocks_torch,
    save_checkpoint,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor
from lf_predictor_ros.core.regressors import build_regressors, rotate_blocks
from lf_predictor_ros.core.retraining import (
    network_spec,
    target_filter,
    train_settings,
)
from lf_predictor_ros.core.training import predict_window, train
from lf_predictor_ros.core.training_window import loss_frame_errors, loss_scale

pytestmark = pytest.mark.filterwarnings(
    'ignore:`torch.jit.script` is deprecated:DeprecationWarning'
)

FloatArray = NDArray[np.float64]
REFERENCE = Path(__file__).parent / 'data' / 'earth_frame_run.npz'
TURN = 0.7  # [rad] a generic angle: north and east mix, no channel is swapped
EARTH_TOLERANCE = 1e-6  # [m, m, rad] the stored run on another CPU (5.4e-9 m measured)


def reference() -> tuple[PredictorParams, FloatArray, FloatArray, FloatArray, FloatArray]:
    """(params, t, pose, force, output) of the stored earth-frame run.

    The run predates ``frequency_yaw`` (its ω0 spectrum had the heading in), so that is pinned
    here; left to the default, the quarter-turn test below would also see the N + E spectrum
    summed in another order, a rounding difference that 15 LM trainings amplify to 2e-5 m. It
    also predates ``guard_floor`` (the sanity guard's floor was [0.5 m, 0.5 m, 0.02 rad]).
    """
    data = np.load(REFERENCE)
    params = PredictorParams.from_dict(ast.literal_eval(str(data['params']))).replace(
        frequency_yaw=True, guard_floor=(0.5, 0.5, 0.02))
    return params, data['t'], data['pose'], data['force'], data['output']


def turned_pose(pose: FloatArray, angle: float) -> FloatArray:
    """Poses (n, 3) turned by ``angle`` about the origin; heading + angle, wrapped."""
    out = np.array(pose, dtype=np.float64)
    out[:, :2] = rotate_blocks(pose, math.cos(angle), math.sin(angle))[:, :2]
    out[:, 2] = np.angle(np.exp(1j * (pose[:, 2] + angle)))
    return out


def pose_difference(a: FloatArray, b: FloatArray) -> FloatArray:
    """Largest |a − b| per DOF, heading difference wrapped."""
    diff = np.asarray(a - b, dtype=np.float64)
    diff[:, 2] = np.angle(np.exp(1j * diff[:, 2]))
    result: FloatArray = np.max(np.abs(diff), axis=0)
    return result


def run(params: PredictorParams, t: FloatArray, pose: FloatArray,
        force: FloatArray) -> FloatArray:
    """Outputs of an inline predictor over the whole run."""
    predictor = AdaptivePredictor(params, background=False)
    return np.array([predictor.update(float(t[i]), pose[i], force[i]) for i in range(len(t))])


def earth_series(pose: FloatArray, force: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(u, y) as the predictor builds them: heading unwrapped, forces turned to north/east."""
    y = np.array(pose, dtype=np.float64)
    y[:, 2] = np.unwrap(pose[:, 2])
    u = rotate_blocks(force, np.cos(pose[:, 2]), np.sin(pose[:, 2]))
    return u, y


# ---- parameter -----------------------------------------------------------------------------

def test_regressor_frame_defaults_to_earth_and_is_validated() -> None:
    assert PredictorParams().regressor_frame == 'earth'
    assert network_spec(PredictorParams()).body_frame is False
    assert network_spec(PredictorParams(regressor_frame='body')).body_frame is True
    with pytest.raises(ValueError, match="regressor_frame must be one of \\('earth', 'body'\\), "
                                         "got 'ned': use earth"):
        PredictorParams(regressor_frame='ned')
    with pytest.raises(ValueError, match='needs ndof 3, got ndof 1: set ndof 3 or '
                                         'regressor_frame earth'):
        PredictorParams(ndof=1, regressor_frame='body')
    with pytest.raises(ValueError, match='set training_mode series_parallel, nfb 0 or '
                                         'regressor_frame earth'):
        PredictorParams(regressor_frame='body', training_mode='parallel', nfb=2)
    PredictorParams(regressor_frame='body', training_mode='parallel', nfb=0)  # no recursion
    assert PredictorParams.from_dict({'regressor_frame': 'body'}).to_dict()[
        'regressor_frame'] == 'body'


def test_spec_body_frame_needs_relative_three_dof_and_is_absent_from_earth_dicts() -> None:
    with pytest.raises(ValueError, match='body_frame needs relative = True and 3 outputs'):
        NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=1, ny=2, nfb=0, hidden_units=2,
                    body_frame=True)
    with pytest.raises(ValueError, match='body_frame needs relative = True and 3 outputs'):
        NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=2, nfb=0, hidden_units=2,
                    relative=True, body_frame=True)
    earth = network_spec(PredictorParams())
    body = network_spec(PredictorParams(regressor_frame='body'))
    assert 'body_frame' not in earth.to_dict()  # earth checkpoints are written as before
    assert body.to_dict()['body_frame'] is True
    assert NnarmaxSpec.from_dict(body.to_dict()) == body
    assert NnarmaxSpec.from_dict(earth.to_dict()) == earth


# ---- earth: the code before the field -----------------------------------------------------

@pytest.mark.parametrize('explicit', [False, True])
def test_earth_frame_run_matches_the_stored_run(explicit: bool) -> None:
    params, t, pose, force, stored = reference()
    # the stored run predates the motion gate, which blends a second network in, and the
    # broadband targets' notch, which widens the targets' notch in a broadband sea: both must
    # stay off here whatever their defaults (the gate's smoothing, dead zone, yaw and
    # ramp_order, the notch's lower edge and holding-only act only with them or with
    # ramp_invariant, off; the gated output is tested in test_motion_gate.py)
    params = params.replace(motion_gate=False, notch_zeta_broadband=0.0)
    if explicit:
        params = params.replace(regressor_frame='earth')
    out = run(params, t, pose, force)
    np.testing.assert_allclose(out, stored, rtol=0.0, atol=EARTH_TOLERANCE)


# ---- the rotation --------------------------------------------------------------------------

def test_rotate_blocks_numbers_and_torch_twin() -> None:
    # heading east (ψ = 90°): 1 m north is 1 m to port (sway −1 m); a force along +x (surge)
    # in a row whose newest heading is east is a force towards the east
    row = np.array([1.0, 0.0, 0.3, 2.0, 5.0, -0.1])
    body = rotate_blocks(row, math.cos(math.pi / 2), -math.sin(math.pi / 2))
    np.testing.assert_allclose(body, [0.0, -1.0, 0.3, 5.0, -2.0, -0.1], atol=1e-15)
    earth = rotate_blocks(np.array([1.0, 0.0, 7.0]), math.cos(math.pi / 2),
                          math.sin(math.pi / 2))
    np.testing.assert_allclose(earth, [0.0, 1.0, 7.0], atol=1e-15)
    rng = np.random.default_rng(4)
    rows, angles = rng.normal(size=(5, 9)), rng.uniform(-4.0, 4.0, size=5)
    kept = rows.copy()
    turned = rotate_blocks(rows, np.cos(angles), np.sin(angles))
    np.testing.assert_array_equal(rows, kept)  # a new array: the input is not changed
    twin = rotate_blocks_torch(torch.from_numpy(rows), torch.from_numpy(np.cos(angles)),
                               torch.from_numpy(np.sin(angles))).numpy()
    np.testing.assert_array_equal(twin, turned)
    back = rotate_blocks(turned, np.cos(angles), -np.sin(angles))
    np.testing.assert_allclose(back, rows, atol=1e-14)
    with pytest.raises(ValueError, match='needs rows of 3-channel blocks'):
        rotate_blocks(np.zeros(4), 1.0, 0.0)


def _random_weights(spec: NnarmaxSpec, u: FloatArray, y: FloatArray) -> NnarmaxNet:
    """Standardization from (u, y), every weight random: no symmetry left in the weights."""
    net = NnarmaxNet(spec, seed=3)
    net.set_standardization(u, y, preserve_function=False)
    generator = torch.Generator().manual_seed(5)
    with torch.no_grad():
        for param in net.parameters():
            param.copy_(0.3 * torch.randn(param.shape, generator=generator, dtype=param.dtype))
    return net


def _turn_rows(x: FloatArray, spec: NnarmaxSpec, angle: float) -> FloatArray:
    """Regressor rows of the turned run: every block's (north, east) turned, headings + angle."""
    turned = rotate_blocks(x, math.cos(angle), math.sin(angle))
    heading_columns = np.arange(spec.nu * 3 + 2, x.shape[1], 3)
    turned[:, heading_columns] += angle
    return turned


def test_body_network_is_rotation_equivariant_for_any_weights_earth_is_not() -> None:
    body_spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=3, ny=4, nfb=2, hidden_units=3,
                            relative=True, body_frame=True)
    earth_spec = dataclasses.replace(body_spec, body_frame=False)
    _, _, pose, force, _ = reference()
    u, y = earth_series(pose[200:260], force[200:260])
    x, _ = build_regressors(u, y, y + 0.05, body_spec)
    x_turned = _turn_rows(x, body_spec, TURN)
    offsets = {}
    for spec in (body_spec, earth_spec):
        net = _random_weights(spec, u, y)
        with torch.no_grad():
            out = net(torch.from_numpy(x)).numpy()
            out_turned = net(torch.from_numpy(x_turned)).numpy()
        numpy_net = NumpyNnarmax.from_module(net)
        np.testing.assert_allclose(numpy_net.forward(x), out, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(numpy_net.forward(x[7]), out[7], rtol=0.0, atol=1e-12)
        offsets[spec.body_frame] = pose_difference(out_turned, turned_pose(out, TURN))
    assert np.all(offsets[True] < 1e-12)  # [m, m, rad]
    assert offsets[False][0] > 0.01 and offsets[False][1] > 0.01  # [m]


def _window(angle: float) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """(u, y, targets, mask) of samples 100…299 of the stored run, turned by ``angle``."""
    params, _, pose, force, _ = reference()
    u, y = earth_series(turned_pose(pose, angle)[100:300], force[100:300])
    targets = zero_phase(y, target_filter(params, 0.8))
    mask = np.ones(len(y), dtype=bool)
    mask[-params.transient_samples:] = False
    return u, y, targets, mask


@pytest.mark.parametrize('frame', ['earth', 'body'])
def test_training_on_a_turned_window_gives_the_turned_network_only_in_body_frame(
        frame: str) -> None:
    params = reference()[0].replace(regressor_frame=frame)
    # no wall-time limit: under load (seen with a benchmark on both cores) max_seconds stopped
    # the two trainings at different epochs, and the comparison is of the whole LM path
    spec = network_spec(params)
    settings = dataclasses.replace(train_settings(params), max_seconds=math.inf)
    outputs = []
    for angle in (0.0, TURN):
        u, y, targets, mask = _window(angle)
        result = train(NnarmaxNet(spec, seed=params.seed), u, y, targets, mask, settings)
        prediction, first = predict_window(NnarmaxNet.from_state(spec, result.state_dict), u, y,
                                           targets, 'series_parallel')
        outputs.append((prediction, result.loss))
    (plain, loss), (turned, turned_loss) = outputs
    offset = pose_difference(turned, turned_pose(plain, TURN))
    if frame == 'body':
        assert np.all(offset < 1e-7)  # [m, m, rad]: rounding through the LM epochs
        assert turned_loss == pytest.approx(loss, rel=1e-9)
    else:
        assert offset[0] > 1e-4 and offset[1] > 1e-4  # [m]
        assert turned_loss != pytest.approx(loss, rel=1e-6)


def test_a_trained_body_network_predicts_the_same_at_every_heading() -> None:
    """Weights fitted on the window as it is, applied to the turned window without retraining."""
    errors = {}
    for frame in ('earth', 'body'):
        params = reference()[0].replace(regressor_frame=frame)
        spec = network_spec(params)
        u, y, targets, mask = _window(0.0)
        state = train(NnarmaxNet(spec, seed=params.seed), u, y, targets, mask,
                      train_settings(params)).state_dict
        net = NnarmaxNet.from_state(spec, state)
        plain, _ = predict_window(net, u, y, targets, 'series_parallel')
        u_t, y_t, targets_t, _ = _window(TURN)
        turned, _ = predict_window(net, u_t, y_t, targets_t, 'series_parallel')
        errors[frame] = pose_difference(turned, turned_pose(plain, TURN))
    assert np.all(errors['body'] < 1e-9)
    assert errors['earth'][0] > 0.01 and errors['earth'][1] > 0.01  # [m]


def test_a_whole_predictor_run_turned_by_90_degrees_is_turned_output_in_body_frame() -> None:
    """End to end: ω0, targets, trainings, guard, fallback and the predictor's own unwrapping.

    A quarter turn maps north/east onto each other, so the per-DOF parts (ω0 spectrum
    normalization, loss scales, guard) match and only the network can break the symmetry; the
    earth network does through its tanh part.
    """
    params, t, pose, force, stored = reference()
    turned = turned_pose(pose, math.pi / 2)
    offsets = {}
    for frame in ('earth', 'body'):
        frame_params = params.replace(regressor_frame=frame)
        plain = stored if frame == 'earth' else run(frame_params, t, pose, force)
        offsets[frame] = pose_difference(run(frame_params, t, turned, force),
                                         turned_pose(plain, math.pi / 2))
    # measured: body 1.0e-6 / 3.7e-7 m / 1.6e-8 rad (rounding, amplified by 15 LM trainings),
    # earth 6.6e-5 / 3.6e-5 m / 3.2e-6 rad (its tanh part's initial weights are not turned)
    assert np.all(offsets['body'] < 1e-5)  # [m, m, rad]
    assert np.max(offsets['earth'][:2]) > 2e-5  # [m]


# ---- the body frame's pieces ---------------------------------------------------------------

def test_body_statistics_and_loss_are_those_of_body_frame_quantities() -> None:
    # a vessel heading east (ψ = 90°) drifting north at 0.1 m/s moves to port: in the body
    # frame all of the motion is sway (−0.1 m per sample), none is surge
    n = 30
    y = np.zeros((n, 3))
    y[:, 0] = 0.1 * np.arange(n)
    y[:, 2] = math.pi / 2
    np.testing.assert_allclose(relative_spread(y, 3, body_frame=True),
                               [0.0, math.sqrt((0.1 ** 2 + 0.2 ** 2) / 2), 0.0], atol=1e-15)
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=1, ny=3, nfb=0, hidden_units=2,
                       relative=True, body_frame=True)
    net = NnarmaxNet(spec)
    force = np.tile([2.0e4, 0.0, 0.0], (n, 1))  # earth forces: 20 kN north = −20 kN sway
    force[::2, 0] = 4.0e4
    net.set_standardization(force, y, preserve_function=False)
    np.testing.assert_allclose(net.u_mean.numpy(), [0.0, -3.0e4, 0.0], atol=1e-9)
    np.testing.assert_allclose(net.u_std.numpy(), [1.0, 1.0e4, 1.0], atol=1e-9)
    step = np.tile([0.0, 0.2, 0.0], (n, 1))
    np.testing.assert_allclose(loss_frame_errors(spec, y, step)[0], [0.2, 0.0, 0.0],
                               atol=1e-15)  # 0.2 m east, heading east: 0.2 m of surge
    np.testing.assert_allclose(loss_scale(spec, y, y + step, np.ones(n, dtype=bool)),
                               [0.2, 1.0, 1.0], atol=1e-15)  # no sway, no yaw: unscaled


def test_body_checkpoint_round_trip_and_earth_checkpoint_refused(tmp_path: Path) -> None:
    params, t, pose, force, _ = reference()
    body = params.replace(regressor_frame='body')
    predictor = AdaptivePredictor(body, background=False)
    for i in range(200):
        predictor.update(float(t[i]), pose[i], force[i])
    path = str(tmp_path / 'body.pt')
    predictor.save(path)
    copy = AdaptivePredictor(body, background=False)
    copy.load(path)
    assert copy.model is not None and copy.model.spec.body_frame
    earth = AdaptivePredictor(params, background=False)
    with pytest.raises(ValueError, match='change the predictor parameters or retrain'):
        earth.load(path)
    earth_path = str(tmp_path / 'earth.pt')
    spec = network_spec(params)
    save_checkpoint(earth_path, spec, NnarmaxNet(spec).state_dict())
    with pytest.raises(ValueError, match='change the predictor parameters or retrain'):
        copy.load(earth_path)


def test_body_free_run_with_feedback_is_refused() -> None:
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=1, ny=2, nfb=1, hidden_units=2,
                       relative=True, body_frame=True)
    net = NnarmaxNet(spec)
    with pytest.raises(ValueError, match='train a body_frame network with LF feedback '
                                         'series-parallel'):
        net.free_run(torch.zeros(4, 9), torch.zeros(1, 3))
