"""Exploratory: the vessel memory's learned LF model in a DP loop with the commands fed.

    OMP_NUM_THREADS=1 python docs/scripts/vessel_memory_loop_probe.py rao_supply:771 rao_swell:772

The loop is `odometry_bench`'s lf_odom loop (the predictor's pose to the PID, the D term from
lf_odom's twist, the PID's commands fed to the estimator as ``thrust_command``), so the memory
can read the controller's implied inertia (``OdometryParams.controller_inertia``). Printed at
every new vessel memory: its dead reckoner, where the thrust gain came from (``known_gain``;
'' = fitted), and the diagonals of G (≈ M⁻¹) and F (≈ −M⁻¹D) as ratios to the simulator's
true M⁻¹ and −M⁻¹D. The offline twin of this probe is `vessel_memory_fit_probe.py` (no commands,
G fitted). Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe as mp  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark import odometry_bench as ob  # noqa: E402
from lf_predictor_ros.benchmark.suite import make_setup, predictor_params  # noqa: E402
from lf_predictor_ros.core.lf_dynamics import VesselMemory  # noqa: E402
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402
from lf_predictor_ros.core.odometry_params import OdometryParams  # noqa: E402
from sim_ros.simulation import load_scenario  # noqa: E402

DURATION = 1800.0  # [s] simulated per loop


def true_rates(setup: Any, ndof: int) -> tuple[np.ndarray, np.ndarray]:
    """The simulator's diag(M⁻¹) and diag(−M⁻¹ D) of the estimated DOFs (``setup.model``)."""
    mass = np.asarray(setup.model.mass, dtype=float)[:ndof, :ndof]
    damping = np.asarray(setup.model.damping, dtype=float)[:ndof, :ndof]
    return np.diag(np.linalg.inv(mass)), np.diag(-np.linalg.inv(mass) @ damping)


def memory_line(t: float, mem: VesselMemory, true_g: np.ndarray, true_f: np.ndarray) -> str:
    """One memory: its reckoner, where its gain came from, G and F against the truth."""
    if mem.model is None:
        return f't {t:6.0f} reckoner {mem.reckoner:18s} no model: {mem.message}'
    g = np.diag(mem.model.input_gain) / true_g
    f = np.diag(mem.model.damping) / true_f
    return (f't {t:6.0f} reckoner {mem.reckoner:18s} gain from '
            f'{mem.known_gain or "fit":12s} G/true {g} F/true {f}')


def probe(sc: str, seed: int, duration: float = DURATION) -> None:
    """Run one development loop and print the memories (module docstring)."""
    np.set_printoptions(precision=3, linewidth=150)
    scenario = load_scenario(sc)
    params = predictor_params(scenario)
    true_g, true_f = true_rates(make_setup(scenario, seed, params), params.ndof)
    print(f'{sc} {seed}: true M^-1 diag {true_g}, true -M^-1 D diag {true_f}')
    seen: list[Any] = [None]

    class Probe(LfStateEstimator):
        def update(self, t: float, *args: Any, **kwargs: Any) -> Any:
            out = super().update(t, *args, **kwargs)
            mem = self.memory
            if mem is not None and mem is not seen[0]:
                seen[0] = mem
                note = mem.message.partition('; ')[2] if mem.model is not None else ''
                print(f'{memory_line(t, mem, true_g, true_f)}  {note}'.rstrip())
            return out

    ob.LfStateEstimator = Probe  # type: ignore[attr-defined]
    run = ob._odometry_loop(scenario, seed, duration, params, OdometryParams())
    print(f'loop done: aborted_at {run.aborted_at}')


def main(argv: list[str] | None = None) -> int:
    """CLI: SCENARIO:SEED … (development seeds only; `method_probe.run_cases`)."""
    return mp.run_cases(argv, (__doc__ or '').splitlines()[0], mp.DEVELOPMENT_SEEDS,
                        'only development seeds', probe)


if __name__ == '__main__':
    sys.exit(main())
