"""Exploratory: the LF augmentation's copy used for some outputs only (the others without it).

    OMP_NUM_THREADS=1 python docs/scripts/row_copy_probe.py --copy-rows 0 1 \
        --scenarios rao_supply --seeds 611 612 --closed-loop --loops-only \
        --variant default --variant "ne=lf_augmentation:0,0,0.00025"

`method_probe.py` with one change in this process (nothing in the package changes): a
retraining whose training data carry an augmentation copy (`retraining.training_data` returned
more rows than the window) solves the linear network twice: on the window alone (as without the
copy), then on the window and the copy with the first solve's standardization (so that the two
solutions' rows act on the same standardized regressors). The outputs named by ``--copy-rows``
(0 north, 1 east, 2 heading) take the second solve's row, the others the first's. Why: with the
heading copy (`lf_augmentation: [0, 0, 0.00025]`) rao_supply's estimate error in a turn falls
in north and east as much as in the heading (seed 581, RMS over the turn's blocks 1081–1200 s:
north 0.78 → 0.44 m, east 0.44 → 0.37 m, heading 0.034 → 0.020 rad), while
the cost on vessels that do not turn is in the heading row (docs/BENCHMARKS.md, forty-first
session). Linear network solved by least squares only; otherwise the retraining is left as it
is. Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
import sys
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from held_copy_probe import ORIGINAL_TRAIN, remember_plain, solve_plain_first  # noqa: E402 - sibling
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core import retraining  # noqa: E402
from lf_predictor_ros.core.network import NnarmaxNet  # noqa: E402

ROW_KEYS = ('bypass.weight', 'output.weight', 'output.bias')  # one row per output
COPY_ROWS: tuple[int, ...] = (0, 1)


def _train(net: NnarmaxNet, u: Any, y: Any, targets: Any, mask: Any, settings: Any,
           **kwargs: Any) -> Any:
    """Window alone, then window and copy; rows COPY_ROWS from the second solve."""
    staged = solve_plain_first(net, settings, **kwargs)
    if staged is None:
        return ORIGINAL_TRAIN(net, u, y, targets, mask, settings, **kwargs)
    first, warm = staged
    second = ORIGINAL_TRAIN(warm, u, y, targets, mask, replace(settings, standardize=False),
                            **kwargs)
    state = {key: value.clone() for key, value in first.state_dict.items()}
    for key in ROW_KEYS:
        for row in COPY_ROWS:
            if row < state[key].shape[0]:
                state[key][row] = second.state_dict[key][row]
    return replace(first, state_dict=state)


def main(argv: list[str]) -> int:
    """Strip ``--copy-rows R ...``, patch the two functions in `retraining`, run the probe."""
    global COPY_ROWS
    if '--copy-rows' in argv:
        at = argv.index('--copy-rows')
        end = at + 1
        while end < len(argv) and argv[end].isdigit():
            end += 1
        COPY_ROWS = tuple(int(a) for a in argv[at + 1:end])
        argv = argv[:at] + argv[end:]
    setattr(retraining, 'training_data', remember_plain)  # noqa: B010 - the patch is the point
    setattr(retraining, 'train', _train)  # noqa: B010
    return method_probe.main(argv)


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
