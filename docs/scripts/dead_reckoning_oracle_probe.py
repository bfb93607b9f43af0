"""Exploratory: rao_supply's dropout loops with the dead reckoner's model patched (an oracle).

    OMP_NUM_THREADS=1 python docs/scripts/dead_reckoning_oracle_probe.py VARIANT OUT.json SEED … \
        [--moves LOW HIGH] [--odometry FIELD=VALUE …]

VARIANT: ``true_damping`` (the fit's damping replaced by the simulator's supply vessel, 1/T =
1/87.8, 1/44.5, 1/11.6 s) or ``floorT`` (the least damping rate 1/T instead of 1/1000 s, e.g.
``floor200``); the dead reckoner's force clip is ``--odometry dead_reckoning_force_margin=K``
(the former ``marginK`` variant patched a module default the odometry no longer reads). Then
`odometry_bench run` of rao_supply on the development SEEDs, 3600 s, lf_odom's loops through
3 × 60 s dropouts with a 500 s phase spread, one worker in this process (so the patch holds);
``--moves``: the dropouts in the setpoint moves instead (`odometry_bench --dropout-moves`),
``--odometry``: passed on. Upper bounds and checks, never settings.
"""
from __future__ import annotations

import sys

import numpy as np

from lf_predictor_ros.benchmark import odometry_bench
from lf_predictor_ros.core import lf_dynamics

# 1/T of the simulator's supply vessel (sim_ros.physics.vessels: M_ii / D_ii) [1/s]
TRUE_DAMPING_RATE = np.array([1 / 87.77, 1 / 44.53, 1 / 11.56])


def patch(variant: str) -> None:
    """Patch `lf_dynamics` for ``variant`` (module docstring); ValueError for an unknown one."""
    if variant.startswith('floor'):
        lf_dynamics.MIN_DAMPING_RATE = 1.0 / float(variant[len('floor'):])
    elif variant == 'true_damping':
        original = lf_dynamics._fit_known_gain  # noqa: SLF001

        def patched(*args: object) -> tuple[np.ndarray, np.ndarray]:
            coef, std = original(*args)  # type: ignore[arg-type]
            if coef.shape[0] == 3:
                coef = coef.copy()
                coef[np.arange(3), np.arange(3)] = -TRUE_DAMPING_RATE
            return coef, std

        lf_dynamics._fit_known_gain = patched  # type: ignore[assignment]  # noqa: SLF001
    else:
        raise ValueError(f'unknown variant {variant!r}: true_damping or floorT (the force clip: '
                         '--odometry dead_reckoning_force_margin=K)')


def main(argv: list[str]) -> int:
    """Entry point."""
    if len(argv) < 3:
        print(__doc__)
        return 2
    variant, out, *rest = argv
    extra: list[str] = []
    if '--odometry' in rest:
        at = rest.index('--odometry')
        rest, extra = rest[:at], rest[at:]
    schedule = ['--dropout-spread', '500']
    if '--moves' in rest:
        at = rest.index('--moves')
        schedule = ['--dropout-moves', *rest[at + 1:at + 3]]
        rest = rest[:at] + rest[at + 3:]
    patch(variant)
    return odometry_bench.main(['run', '--scenarios', 'rao_supply', '--seeds', *rest,
                                '--duration', '3600', '--no-tracking', '--no-dead-reckoning',
                                '--dropout-loops', *schedule, '--workers', '1',
                                '--scheduler', 'none', *extra, '-o', out])


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
