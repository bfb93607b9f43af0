"""The adaptive predictor in its own DP loop: estimate error and true offset per frequency band.

    python docs/scripts/own_loop_band_probe.py rao_swell 5 default
    python docs/scripts/own_loop_band_probe.py rao_swell 5 dof_coupling:heading   # a field:value
    python docs/scripts/own_loop_band_probe.py rao_swell 5 observer   # a baseline's own loop

One loop per call: the seed's scenario (its scheduled events delayed as `method_probe.py` and
`benchmark` delay them), the shipped predictor with the one override, the PID on its estimate
(`suite._run_loop`), scored from the benchmark's first scored sample. Printed as one JSON line,
for north and east each: the RMS of the estimate error it acted on (`suite._loop_estimate_error`)
and of the true LF pose's offset from the loop reference (the ideal loop's track) in the control
band (0–0.1 rad/s, mean included), between it and the wave band (0.1–0.3) and in the wave band
(0.3–1.3). The twenty-fourth session used it to show that a variant can lose position in the
control band while its estimate error there does not grow (docs/BENCHMARKS.md).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import json
from pathlib import Path
import sys
from typing import Any

import numpy as np
import torch

from lf_predictor_ros.benchmark import stability
from lf_predictor_ros.benchmark.benchmark import SCHEDULE_SPREAD
from lf_predictor_ros.benchmark.estimators import CAUSAL, PREDICTORS, predictor_params
from lf_predictor_ros.benchmark.recordings import grid_stride
from lf_predictor_ros.benchmark.suite import (
    _loop_estimate_error,
    _loop_reference,
    _run_loop,
    make_recording,
    make_setup,
    schedule_shift_for_seed,
    scored_start,
)
from lf_predictor_ros.core.evaluation import band_rms
from sim_ros.simulation import load_scenario, scenario_with_schedule_shift, simulate

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import parse_variant  # noqa: E402 - the sibling script

DURATION = 1800.0  # [s] as method_probe
BANDS = ((0.0, 0.1), (0.1, 0.3), (0.3, 1.3))  # [rad/s] control band, between, wave band
# estimators whose loop the probe runs by name, for comparison: the causal ones that are not
# the predictor (benchmark.estimators)
BASELINES = tuple(name for name in CAUSAL if name not in PREDICTORS)


def bands(x: np.ndarray, sample_time: float) -> list[list[float]]:
    """Per column (north, east): RMS in each of BANDS (`band_rms`: the first with the mean)."""
    return [[band_rms(x[:, i], sample_time, band) for band in BANDS] for i in range(2)]


@dataclass(frozen=True)
class LoopCase:
    """One seed's loop set up as `method_probe.py` and `benchmark` set it up."""

    scenario: Any  # the scenario, its scheduled events delayed for the seed
    shift: float  # [s] that delay
    setup: Any  # EstimatorSetup with the variant's predictor parameters
    ideal: Any  # SimRecord of the ideal loop (the PID on the true LF pose)
    start: float  # [s] the first scored sample
    estimator: str  # 'adaptive', or a baseline's name (BASELINES)


def loop_case(name: str, seed: int, variant: str) -> LoopCase:
    """The case of ``variant``: 'default', 'field:value[;field:value]' or a baseline's name.

    Overrides are typed as method_probe types them ('0.2' is a float); a baseline's name
    (observer, oracle_kf, cascade, raw, ...) runs that estimator's loop instead. The fair
    recording is made first, as method_probe makes it (the scored start comes from it).
    """
    estimator = variant if variant in BASELINES else 'adaptive'
    overrides = None if variant == 'default' or estimator != 'adaptive' else \
        parse_variant(f'v={variant}')[1]
    shift = schedule_shift_for_seed(seed, SCHEDULE_SPREAD)
    scenario = scenario_with_schedule_shift(load_scenario(name), shift)
    params = predictor_params(scenario, None)
    setup = make_setup(scenario, seed, params)
    data = make_recording(scenario, seed, DURATION, setup).data()
    start = float(data['t'][scored_start(params, len(data['t']))])
    ideal = simulate(scenario, seed=seed, duration=DURATION, controller=True, feedback='truth_lf')
    return LoopCase(scenario, shift, replace(setup, params=predictor_params(scenario, overrides)),
                    ideal, start, estimator)


def main(argv: list[str]) -> None:
    """Run one loop (module docstring) and print its JSON line."""
    name, seed, variant = argv[0], int(argv[1]), argv[2]
    torch.set_num_threads(1)
    case = loop_case(name, seed, variant)
    outcome = _run_loop(case.estimator, case.scenario, seed, DURATION, case.setup, case.ideal)
    record = outcome.record
    keep = record.t >= case.start
    offset = stability.pose_offset(record.truth_lf_pose[keep],
                                   _loop_reference(case.scenario, record, case.ideal)[keep], 3)
    sample_time = case.setup.params.sample_time
    stride = grid_stride(case.scenario, sample_time)  # sensor samples per h
    print(json.dumps({'seed': seed, 'variant': variant,
                      'err': bands(_loop_estimate_error(outcome, 3, case.start), sample_time),
                      'pos': bands(offset[stride - 1::stride], sample_time)}))


if __name__ == '__main__':
    main(sys.argv[1:])
