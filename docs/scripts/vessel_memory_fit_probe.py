"""Exploratory: the vessel memory's learned LF model over a fair recording, against the truth.

    OMP_NUM_THREADS=1 python docs/scripts/vessel_memory_fit_probe.py rao_supply:771

`LfStateEstimator` (shipped defaults, no worker thread) streamed over `method_probe.fair_case`
(scheduled events delayed as `method_probe.py` delays them), printing at every new vessel memory
its dead reckoner (without a model: the memory's message, why) and, once a model is fitted,
the diagonals of G (≈ M⁻¹) and F (≈ −M⁻¹D),
next to the simulator's true M⁻¹ and −M⁻¹D. No ``thrust_command`` is fed (an offline
recording), so the controller's gains cannot be read and G is fitted. The forty-sixth session
used it to ask whether a learned model could carry an observer through the manoeuvres
(docs/BENCHMARKS.md). Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe as mp  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD  # noqa: E402
from lf_predictor_ros.benchmark.suite import predictor_params  # noqa: E402
from lf_predictor_ros.core.lf_state import LfStateEstimator  # noqa: E402


def probe(sc: str, seed: int) -> None:
    """Stream one development case and print the memories (module docstring)."""
    np.set_printoptions(precision=4, linewidth=150)
    scenario, base, setup, rec = mp.fair_case(sc, seed, 1800.0, SCHEDULE_SPREAD)
    d = rec.data()
    t, y, u = d['t'], d['y'], d['u']
    est = LfStateEstimator(predictor_params(scenario), background=False)
    M = np.asarray(setup.model.mass, dtype=float)
    D = np.asarray(setup.model.damping, dtype=float)
    n = est.ndof
    Minv = np.linalg.inv(M[:n, :n])
    print('true M^-1 diag', np.diag(Minv), 'true -M^-1 D diag', np.diag(-Minv @ D[:n, :n]))
    last = None
    for k in range(len(t)):
        est.update(t[k], y[k], u[k])
        mem = est.memory
        if mem is not None and mem is not last:
            last = mem
            if mem.model is not None:
                print(f't {t[k]:6.0f} reckoner {mem.reckoner:18s} G diag '
                      f'{np.diag(mem.model.input_gain)} F diag {np.diag(mem.model.damping)}')
            else:
                print(f't {t[k]:6.0f} reckoner {mem.reckoner} no model: {mem.message}')


def main(argv: list[str] | None = None) -> int:
    """CLI: SCENARIO:SEED … (development seeds only; `method_probe.run_cases`)."""
    return mp.run_cases(argv, (__doc__ or '').splitlines()[0], mp.DEVELOPMENT_SEEDS,
                        'only development seeds', probe)


if __name__ == '__main__':
    sys.exit(main())
