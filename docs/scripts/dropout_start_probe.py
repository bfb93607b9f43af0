"""Exploratory: lf_odom's loop against the observer's at each dropout start, and the error after.

    OMP_NUM_THREADS=1 python docs/scripts/dropout_start_probe.py rao_supply:885 \
        [--spread 500 | --moves -30 -5] [--oracle] [--odometry FIELD=VALUE …]

For each development case runs `odometry_bench`'s lf_odom dropout loop and the tuned observer's
loop with the dropouts of ``--spread`` or ``--moves`` (`move_dropout_probe.dropouts_of`, the
arguments of `move_dropout_probe.dropout_parser`) and prints per dropout:
the environment force each estimator dead-reckons with at the start (lf_odom: G⁻¹ B β(ψ) of its
balanced model, the fitted term in a DOF it does not balance; the observer: R(ψ)ᵀ b̂) against the
truth's M ν̇ + D ν − τ averaged over the 30 s before (the simulator's supply-vessel M and D), the
start twist against the true LF body velocity, the vessel memory's model (time constants, thrust
gain / the true 1/M_ii), and both estimators' error against their own loop's true LF pose 10, 30
and 59 s in. ``--oracle``: the simulator's damping rates in the fit and the read corrected for
them (`dead_reckoning_oracle_probe.patch('true_damping')` and ``controller_read_damping``).
``--log-damping``: every damping choice of lf_odom's vessel memory (`lf_state._damping_chosen`),
one line each: the window's heading range, the window's own rates (its fit with the read gain),
the rates and scores chosen, and the thrust gain / the true 1/M_ii (the fifty-eighth session's
traces).
Supply vessel scenarios only (rao_supply, rao_swell); development seeds only; the fifty-fifth
session's section of docs/BENCHMARKS.md.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
import dead_reckoning_oracle_probe as oracle_probe  # noqa: E402
import move_dropout_probe as mdp  # noqa: E402

from lf_predictor_ros.benchmark import odometry_bench as ob  # noqa: E402
from lf_predictor_ros.benchmark.estimators import make_estimator, predictor_params  # noqa: E402
from lf_predictor_ros.benchmark.recordings import run_loop  # noqa: E402
from lf_predictor_ros.benchmark.suite import make_setup  # noqa: E402
from lf_predictor_ros.core import lf_state  # noqa: E402
from lf_predictor_ros.core.lf_dynamics import (  # noqa: E402
    LfDynamics,
    body_velocity,
    fit_lf_dynamics,
    heading_basis,
    paired_forces,
)
from lf_predictor_ros.core.odometry import LfOdometry, OdometryEstimate  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.physics.vessels import SUPPLY_D, SUPPLY_M  # noqa: E402
from sim_ros.simulation import SimRecord, load_scenario  # noqa: E402

DURATION = mdp.DURATION  # [s] the odometry bench's loop length
FloatArray = np.ndarray


def true_environment(record: SimRecord, t0: float, span: float = 30.0
                     ) -> tuple[FloatArray, FloatArray]:
    """(M ν̇ + D ν − τ averaged over [t0 − span, t0] [N, N, N·m], the true ν at t0), body frame."""
    h = float(record.t[1] - record.t[0])
    nu = body_velocity(record.truth_lf_pose, h)
    env = np.gradient(nu, h, axis=0) @ SUPPLY_M.T + nu @ SUPPLY_D.T - record.thrust
    keep = (record.t >= t0 - span) & (record.t <= t0)
    return env[keep].mean(axis=0), nu[keep][-1]


def start_environment(model: LfDynamics, heading: float) -> FloatArray:
    """The environment a dead reckoning balances, as a body force: G⁻¹ B β(ψ) [N, N, N·m].

    A DOF whose ``dead_reckoning_force_time`` is 0 (yaw by default) keeps the window's fit.
    """
    accel = model.bias @ heading_basis(heading, 3)
    return np.asarray(accel / np.diag(model.input_gain), dtype=np.float64)


def nearest(log: dict[float, Any], t: float, before: bool = False) -> Any:
    """The entry of ``log`` nearest to ``t`` (at or before it with ``before``), within 1 s."""
    keys = [k for k in log if k <= t] if before else list(log)
    if not keys:
        return None
    k = min(keys, key=lambda q: abs(q - t))
    return log[k] if abs(k - t) <= 1.0 else None


def one(name: str, seed: int, spread: float, moves: list[float] | None,
        odometry: OdometryParams) -> None:
    """Both loops of one case, printed per dropout (``spread``, ``moves``: `mdp.dropouts_of`)."""
    scenario = load_scenario(name)
    params = predictor_params(scenario, None)
    drops = mdp.dropouts_of(scenario, params, seed, spread, moves)
    starts: dict[float, dict[str, Any]] = {}
    original = LfOdometry._balanced_model

    def traced(self: LfOdometry) -> LfDynamics | None:
        balanced = original(self)
        x, last = self._x, self._last_output  # noqa: SLF001
        if last is not None and x is not None and balanced is not None:
            memory = self.memory
            starts[float(last.stamp)] = {
                'twist': np.array(last.twist),
                'start': self._start_twist(x),  # noqa: SLF001
                'average': self._wave_averaged_twist(),  # noqa: SLF001
                'holding_std': self._holding_twist_std(),  # noqa: SLF001
                'published_std': np.sqrt(np.diag(last.twist_cov)[:3]),
                'environment': start_environment(balanced, float(x[2])),
                'model': None if memory is None else memory.model}
        return balanced

    LfOdometry._balanced_model = traced  # type: ignore[method-assign]
    log: list[OdometryEstimate] = []
    try:
        odom_run = ob._odometry_loop(scenario, seed, DURATION, params, odometry,  # noqa: SLF001
                                     drops, log)
    finally:
        LfOdometry._balanced_model = original  # type: ignore[method-assign]
    stream = make_estimator(ob.LOOP_OBSERVER, make_setup(scenario, seed, params))
    observed: dict[float, tuple[FloatArray, FloatArray, FloatArray]] = {}

    def step(t: float, pose: FloatArray, force: FloatArray, omega: float) -> FloatArray:
        estimator = stream.estimator
        if ob._in_dropout(t, drops):  # noqa: SLF001
            out = np.asarray(estimator.coast(t, force), dtype=np.float64)
        else:
            out = np.asarray(stream.step(t, pose, force, omega), dtype=np.float64)
        observed[round(t, 1)] = (out.copy(), estimator.velocity.copy(), estimator.bias.copy())
        return out

    obs_run = run_loop(scenario, seed, DURATION, params.sample_time, step)
    print(f'{name}:{seed} dropouts {drops}')
    true_gain = np.diag(np.linalg.inv(SUPPLY_M))
    for start, _ in drops:
        env_l, nu_l = true_environment(odom_run.record, start)
        env_o, nu_o = true_environment(obs_run.record, start)
        print(f' dropout at {start:.0f} s')
        info = starts[min(starts, key=lambda q: abs(q - start))] if starts else None
        if info is not None:
            print(f'   lf_odom: environment {np.round(info["environment"] / 1e3, 1)} kN, true '
                  f'{np.round(env_l / 1e3, 1)} | twist {np.round(info["twist"], 3)}, true '
                  f'{np.round(nu_l, 3)}')
            average = info['average']
            print(f'     start twist {np.round(info["start"], 4)}, wave-averaged '
                  f'{None if average is None else np.round(average, 4)}, holding std '
                  f'{np.round(info["holding_std"], 4)}, published std '
                  f'{np.round(info["published_std"], 4)}')
            model = info['model']
            if model is not None:
                print(f'     model T {np.round(-1.0 / np.diag(model.damping), 1)} s, gain / true '
                      f'{np.round(np.diag(model.input_gain) / true_gain, 2)}')
        before = nearest(observed, start - 0.5, before=True)
        if before is not None:
            eta, nu, bias = before
            c, s = np.cos(eta[2]), np.sin(eta[2])
            body_bias = np.array([c * bias[0] + s * bias[1], -s * bias[0] + c * bias[1],
                                  bias[2]])
            print(f'   observer: environment {np.round(body_bias / 1e3, 1)} kN, true '
                  f'{np.round(env_o / 1e3, 1)} | velocity {np.round(nu, 3)}, true '
                  f'{np.round(nu_o, 3)}')
        for dt in (10.0, 30.0, 59.0):
            errors = []
            for run, estimate in ((odom_run, next((o.pose for o in log
                                                   if abs(o.stamp - (start + dt)) < 0.6), None)),
                                  (obs_run, None if (o := nearest(observed, start + dt)) is None
                                   else o[0])):
                k = int(np.argmin(np.abs(run.record.t - (start + dt))))
                if estimate is None:
                    errors.append(np.full(3, np.nan))
                    continue
                error = np.array(estimate) - run.record.truth_lf_pose[k]
                error[2] = np.angle(np.exp(1j * error[2]))
                errors.append(error)
            print(f'   +{dt:.0f} s error: lf_odom {np.round(errors[0], 2)}, observer '
                  f'{np.round(errors[1], 2)}')


def log_damping_choices() -> None:
    """Wrap `lf_state._damping_chosen` to print every choice (``--log-damping``)."""
    original = lf_state._damping_chosen  # noqa: SLF001
    true_gain = np.diag(np.linalg.inv(SUPPLY_M))

    def logged(values: FloatArray, forces: FloatArray, sample_time: float, sos: Any,
               input_gain: FloatArray, natural_freq: Any, kept: Any, *args: Any,
               **kwargs: Any) -> Any:
        gain, rate, score, parts = original(values, forces, sample_time, sos, input_gain,
                                            natural_freq, kept, *args, **kwargs)
        try:
            own = -np.diag(fit_lf_dynamics(values, paired_forces(forces, sos), sample_time,
                                           input_gain=input_gain).damping)
        except ValueError:
            own = None
        heading = values[:, 2] if values.shape[1] == 3 else np.zeros(1)
        print(f'   damping choice: window {values.shape[0] * sample_time:.0f} s, heading '
              f'{heading.min():.2f}…{heading.max():.2f} rad | own rates '
              f'{None if own is None else np.round(own, 3)} | chosen '
              f'{None if rate is None else np.round(rate, 3)} 1/s, scores '
              f'{None if score is None else np.array2string(score, precision=2)} | gain / true '
              f'{np.round(gain / true_gain[:gain.shape[0]], 2)} | {"; ".join(parts)}')
        return gain, rate, score, parts

    lf_state._damping_chosen = logged  # noqa: SLF001


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    parser = mdp.dropout_parser(__doc__)
    parser.add_argument('--oracle', action='store_true',
                        help="the simulator's damping and the read corrected for it")
    parser.add_argument('--log-damping', action='store_true',
                        help="print every damping choice of lf_odom's vessel memory")
    args, cases, overrides = mdp.parse_dropout_args(parser, argv)
    if args.oracle:
        oracle_probe.patch('true_damping')
        overrides['controller_read_damping'] = True
    odometry = OdometryParams(**overrides)
    if args.log_damping:
        log_damping_choices()
    torch.set_num_threads(1)
    for name, seed in cases:
        one(name, seed, args.spread, args.moves, odometry)
    return 0


if __name__ == '__main__':
    sys.exit(main())
