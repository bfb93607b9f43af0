"""Probe: a passive observer on the vessel memory's learned M, D and the predictor's ω0 (#13).

    python docs/scripts/memory_observer_probe.py rao_supply 3 \
        --loops memory_observer memory_observer_fit adaptive observer raw

Question: the tuned observer's loop has half the adaptive predictor's position error on the RAO
vessels, and the same observer mistuned (M ×1.3, D ×0.7, ω0 ×1.2) is as good. Is a passive
observer (Fossen & Strand 1999, `core.baselines.observer`) whose model is *learned* — M, D from
the `LfStateEstimator`'s vessel memory (`core.lf_dynamics`: M_ii = 1 / G_ii, D_ii = −F_ii M_ii),
ω0 from the predictor — a better learned filter than the network? Gains: the fixed
`baseline_tuning.RECORDING_OBSERVER` setting (vessel-independent, not tuned per vessel) on the
suite's K3/K4 rule for the learned M.

The observer is built when the first vessel memory with a model arrives (until then the loop gets
the predictor's own output) with η̂ at the predictor's LF estimate, and rebuilt with the newest M, D
at every later memory, its state kept. Loop names (any combination of the suffixes):

- ``memory_observer``: M, D as the memory gives them (with the default `controller_inertia`,
  the thrust gain read from the DP controller's gains while it can be read);
- ``_fit``: ``controller_inertia`` off (the thrust gain fitted);
- ``_true_model``: the simulator's true M, D instead (only the ω0 is learned);
- ``_true_omega``: the true ω0 instead of the predictor's;
- ``_once``: the first memory only, no rebuilds;
- ``_damping_prior``: D = M / 50 s instead of the fitted damping;
- ``_no_thrust``: the observer gets zero thrust (its bias state has to absorb the thrust);
- ``_tuned_gains``: the gains of the scenario's tuned observer (`config/baselines`) instead of
  ``RECORDING_OBSERVER``.

Other names are the suite's loops (`benchmark.estimators`). Scored like `benchmark`
(`suite.run_closed_loops`, same seed, from 481 s). Tuning and development seeds only (1–10).
Diagnostic: it replaces `suite._run_loop` in this process to add the loop.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import math
import sys
from typing import Any

import numpy as np
import torch

from lf_predictor_ros.benchmark import suite
from lf_predictor_ros.benchmark.baseline_tuning import RECORDING_OBSERVER, observer_base_gains
from lf_predictor_ros.benchmark.benchmark import FIRST_HELD_OUT_SEED
from lf_predictor_ros.benchmark.estimators import EstimatorSetup, predictor_params
from lf_predictor_ros.benchmark.recordings import run_loop
from lf_predictor_ros.core.baselines.observer import PassiveObserver
from lf_predictor_ros.core.heading import wrap_angle
from lf_predictor_ros.core.lf_dynamics import VesselMemory
from lf_predictor_ros.core.lf_state import LfStateEstimator
from lf_predictor_ros.core.odometry_params import OdometryParams
from sim_ros.simulation import load_scenario, simulate

FloatArray = np.ndarray
PREFIX = 'memory_observer'
DAMPING_PRIOR_TIME = 50.0  # [s] D = M / this with _damping_prior


class MemoryObserver:
    """The probe's estimator: `LfStateEstimator` for ω0 and memory, a `PassiveObserver` on it."""

    def __init__(self, setup: EstimatorSetup, name: str) -> None:
        """``name``: PREFIX + suffixes (module docstring)."""
        self.setup = setup
        self.ndof = setup.ndof
        self.name = name
        odometry = OdometryParams(controller_inertia=False) if '_fit' in name else None
        self.state = LfStateEstimator(setup.params, odometry, background=False)
        self.observer: PassiveObserver | None = None
        self.models: list[tuple[float, FloatArray, FloatArray]] = []  # (t, M_ii, D_ii)
        self._memory: VesselMemory | None = None
        self._omega = math.nan

    def command(self, t: float, tau: FloatArray) -> None:
        """The DP controller's command (the controller read of the vessel memory)."""
        self.state.command(t, np.asarray(tau, dtype=np.float64))

    def _model(self, memory: VesselMemory) -> tuple[FloatArray, FloatArray] | None:
        n = self.ndof
        if memory.model is None:
            return None
        gain = np.diag(memory.model.input_gain)[:n]
        if not np.all(np.isfinite(gain)) or np.any(gain <= 0.0):
            return None
        mass = 1.0 / gain
        damping = np.maximum(-np.diag(memory.model.damping)[:n], 1e-3) * mass
        if '_true_model' in self.name:
            mass = np.diag(np.asarray(self.setup.model.mass))[:n]
            damping = np.diag(np.asarray(self.setup.model.damping))[:n]
        if '_damping_prior' in self.name:
            damping = mass / DAMPING_PRIOR_TIME
        return mass, damping

    def _build(self, t: float, omega: float, mass: FloatArray, damping: FloatArray,
               pose: FloatArray, force: FloatArray, lf_pose: FloatArray) -> None:
        n = self.ndof
        full_mass = np.eye(3)
        full_mass[:n, :n] = np.diag(mass)
        k3, k4 = observer_base_gains(full_mass)
        cfg = RECORDING_OBSERVER
        if '_tuned_gains' in self.name:  # the tuned observer's entry (config/baselines)
            cfg = {**RECORDING_OBSERVER, **self.setup.baselines.get('observer', {})}
        observer = PassiveObserver(
            n, self.setup.sample_time, omega, np.diag(mass) if n == 3 else float(mass[0]),
            np.diag(damping) if n == 3 else float(damping[0]),
            k3=(float(cfg['k3_scale']) * k3)[:n], k4=(float(cfg['k4_scale']) * k4)[:n],
            relative_damping=float(cfg['relative_damping']),
            cutoff_ratio=float(cfg['cutoff_ratio']), bias_time=float(cfg['bias_time']))
        old = self.observer
        if old is not None and old._state is not None:  # noqa: SLF001 - probe: keep the state
            observer._state = old._state.copy()  # noqa: SLF001
            observer._last_t = old._last_t  # noqa: SLF001
        else:
            observer.update(t, pose, force)
            state = observer._state  # noqa: SLF001
            assert state is not None
            state[2 * n:3 * n] = lf_pose[:n]
            if n == 3:  # unwrapped near the measured heading, as the observer keeps it
                state[2 * n + 2] = float(pose[2]) + wrap_angle(float(lf_pose[2] - pose[2]))
        self.observer = observer
        self._omega = omega
        self.models.append((t, mass, damping))

    def step(self, t: float, pose: FloatArray, force: FloatArray,
             true_omega: float) -> FloatArray:
        """One grid sample (the suite's `StreamingEstimator.step` signature)."""
        lf_pose, _ = self.state.update(t, pose, force)
        memory = self.state.memory
        omega = self.state.predictor.wave_peak_freq
        if '_true_omega' in self.name:
            omega = true_omega
        rebuild = self.observer is None or '_once' not in self.name
        if memory is not None and memory is not self._memory and omega is not None and rebuild:
            self._memory = memory
            model = self._model(memory)
            if model is not None:
                self._build(t, omega, *model, np.asarray(pose), np.asarray(force),
                            np.asarray(lf_pose))
        if self.observer is None:
            return np.asarray(lf_pose, dtype=np.float64)
        if omega is not None and omega != self._omega:
            self.observer.set_wave_peak_freq(omega)
            self._omega = omega
        applied = np.zeros(3) if '_no_thrust' in self.name else force
        return np.asarray(self.observer.update(t, pose, applied), dtype=np.float64)


PROBES: dict[str, MemoryObserver] = {}
_SUITE_RUN_LOOP = suite._run_loop  # noqa: SLF001


def _run_loop(name: str, scenario: Any, seed: int, duration: float | None,
              setup: EstimatorSetup, ideal: Any, recorded: Any = None) -> Any:
    if not name.startswith(PREFIX):
        return _SUITE_RUN_LOOP(name, scenario, seed, duration, setup, ideal, recorded)
    probe = MemoryObserver(setup, name)
    PROBES[name] = probe
    run = run_loop(scenario, seed, duration, setup.sample_time, probe.step,
                   command=probe.command)
    info = {'nonfinite_estimates': run.nonfinite_estimates, 'aborted_at': run.aborted_at}
    return suite._LoopOutcome(run.record, run.aborted_at is not None, info,  # noqa: SLF001
                              run.estimate_t, run.estimates)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('scenario')
    parser.add_argument('seeds', nargs='+', type=int)
    parser.add_argument('--loops', nargs='+',
                        default=[PREFIX, 'adaptive', 'observer', 'oracle_kf', 'raw'])
    parser.add_argument('--duration', type=float, default=1800.0, help='simulated s')
    args = parser.parse_args(argv)
    if any(not 1 <= s < FIRST_HELD_OUT_SEED for s in args.seeds):
        parser.error('tuning and development seeds only (1-10); held-out seeds: `benchmark`')
    torch.set_num_threads(1)
    suite._run_loop = _run_loop  # noqa: SLF001
    scenario = load_scenario(args.scenario)
    names = list(dict.fromkeys([*args.loops, 'raw']))
    for seed in args.seeds:
        setup = suite.make_setup(scenario, seed, predictor_params(scenario))
        ideal = simulate(scenario, seed=seed, duration=args.duration, controller=True,
                         feedback='truth_lf')
        # the grid's k-th sample is the mean over ((k) h, (k + 1) h]: 481 s with the defaults
        start = (suite.scored_start(setup.params, 10 ** 9) + 1) * setup.sample_time
        PROBES.clear()
        results, _ = suite.run_closed_loops(scenario, seed, args.duration, setup, names, ideal,
                                            start)
        raw = list(results['raw']['thrust_wave_band_power'].values())
        for name, entry in results.items():
            power = list(entry['thrust_wave_band_power'].values())
            share = ' / '.join(f'{100 * p / r:.2f}' for p, r in zip(power, raw, strict=True))
            heading = entry.get('heading_rmse', math.nan)
            print(f"loop {args.scenario} {seed} {name:34s} position "
                  f"{entry['position_rmse']:.4f} m heading {heading:.5f} rad max "
                  f"{entry['max_excursion']:.2f} m thrust WF % raw {share} stable "
                  f"{entry['stability']['stable']}", flush=True)
        model = setup.model
        print(f'  true M {np.diag(model.mass)[:setup.ndof]} D '
              f'{np.diag(model.damping)[:setup.ndof]}')
        for name, probe in PROBES.items():
            for t, mass, damping in probe.models[:2] + probe.models[-1:]:
                print(f'  {name} t={t:.0f} s M {mass} D {damping} ({len(probe.models)} models)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
