"""Where a simulated bag came from, kept in its rosbag2 custom data (ROS-free).

`sim_bag` writes these keys; `replay` reads them and says so when a bag's thrust was computed
from the true LF pose. Such thrust encodes the truth, so accuracy read from that bag flatters
every estimator that regresses on thrust (the predictor does): cost measurements only.
"""
from __future__ import annotations

from collections.abc import Mapping

SCENARIO_KEY = 'lf_predictor_ros.scenario'
SEED_KEY = 'lf_predictor_ros.seed'
# 'open' (no DP loop), 'estimator' (the loop ran on RECORDING_ESTIMATOR_KEY's estimator) or
# 'truth_lf' (the loop ran on the true LF pose): `benchmark.recordings.LOOPS`
RECORDING_LOOP_KEY = 'lf_predictor_ros.recording_loop'
RECORDING_ESTIMATOR_KEY = 'lf_predictor_ros.recording_estimator'
LEAKING_LOOP = 'truth_lf'


def recording_custom_data(scenario: str, seed: int, loop: str,
                          estimator: str | None = None) -> dict[str, str]:
    """The custom data of a simulated recording (scenario, seed, DP loop and its estimator)."""
    data = {SCENARIO_KEY: scenario, SEED_KEY: str(seed), RECORDING_LOOP_KEY: loop}
    if estimator is not None:
        data[RECORDING_ESTIMATOR_KEY] = estimator
    return data


def leak_warning(custom_data: Mapping[str, str]) -> str | None:
    """A warning when the bag says its DP loop ran on the true LF pose, else None."""
    if custom_data.get(RECORDING_LOOP_KEY) != LEAKING_LOOP:
        return None
    return ("the bag's DP loop ran on the true LF pose (custom data "
            f'{RECORDING_LOOP_KEY}: {LEAKING_LOOP}), so its thrust encodes the truth and '
            'metrics against the truth flatter every estimator that uses thrust: read cost, '
            'not accuracy, from it (record with `sim_bag --loop-estimator observer` instead)')


__all__ = ['LEAKING_LOOP', 'RECORDING_ESTIMATOR_KEY', 'RECORDING_LOOP_KEY', 'SCENARIO_KEY',
           'SEED_KEY', 'leak_warning', 'recording_custom_data']
