"""Exploratory: the LF augmentation's motion band moved (issue 13).

    OMP_NUM_THREADS=1 python docs/scripts/lf_band_probe.py --lf-band 0 0.05 \
        --scenarios supply_closed_loop --seeds 563 564 --closed-loop --loops-only \
        --variant "y05b=lf_augmentation:0,0,0.0005"

`method_probe.py` with `augmentation.LF_MOTION_BAND` (the band of the synthetic LF motion that
`lf_augmentation` adds to a copy of the training window; (0, 0.1) rad/s in the package, the DP
control bandwidth) set to ``--lf-band LOW HIGH`` [rad/s] in this process only (nothing in the
package changes). Every variant of the run gets it; it acts only where ``lf_augmentation`` is
on. A 45–90° DP turn lasts 60–100 s, so its motion lies mostly below 0.1 rad/s: a lower band
asks the heading filter to follow turns without asking it to pass the slow wave motion just
below the wave band. Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import augmentation  # noqa: E402


def main(argv: list[str]) -> int:
    """Strip ``--lf-band LOW HIGH`` from ``argv``, set the band, run `method_probe.main`."""
    if '--lf-band' not in argv:
        raise SystemExit('give --lf-band LOW HIGH [rad/s]')
    at = argv.index('--lf-band')
    low, high = float(argv[at + 1]), float(argv[at + 2])
    setattr(augmentation, 'LF_MOTION_BAND', (low, high))  # noqa: B010 - the patch is the point
    return method_probe.main(argv[:at] + argv[at + 3:])


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
