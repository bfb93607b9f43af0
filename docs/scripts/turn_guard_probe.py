"""Exploratory: the sanity guard's bound in turns, with or without heading lags in north/east.

    OMP_NUM_THREADS=1 python docs/scripts/turn_guard_probe.py --guard-spreads 1e9 \
        [--north-east-without-heading] --scenarios rao_supply --seeds 635 636 \
        --closed-loop --loops-only --variant "noguard="

`method_probe.py` with, in this process only (nothing in the package changes):
- ``--guard-spreads G``: `predictor.GUARD_SPREADS` set to G (shipped 6: a prediction farther
  from the newest measurement than 6 RMS of the training window's wave motion plus a floor is
  not believed and the cascade stands in for every DOF). In a RAO vessel's 45° turn the holding
  network trips it on north (the heading lags' part, `turn_part_probe.py`) and then on heading
  (the heading row lags the turn), and the cascade, which lags a turn far more, serves for
  10–15 s (seed 636: 45 % of the 20 s block at the turn's start). 1e9 switches the guard off.
- ``--north-east-without-heading``: `heading_column_probe.py`'s patch (the north/east rows fitted
  without the heading lags).
Every variant of the run gets the patches (run the default rows from another process).
Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parent))
import heading_column_probe  # noqa: E402 - the sibling script
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import network, predictor  # noqa: E402

if __name__ == '__main__':
    argv = sys.argv[1:]
    if '--guard-spreads' in argv:
        at = argv.index('--guard-spreads')
        setattr(predictor, 'GUARD_SPREADS', float(argv[at + 1]))  # noqa: B010 - the patch
        del argv[at:at + 2]
    if '--north-east-without-heading' in argv:
        argv.remove('--north-east-without-heading')
        setattr(network.NnarmaxNet, 'fit_linear_bypass',  # noqa: B010 - the patch
                heading_column_probe.no_heading_fit)
    sys.exit(method_probe.main(argv))
