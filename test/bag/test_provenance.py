"""bag.provenance: the custom data of a simulated recording and the leak warning."""
from __future__ import annotations

from lf_predictor_ros.bag.provenance import (
    RECORDING_ESTIMATOR_KEY,
    RECORDING_LOOP_KEY,
    SCENARIO_KEY,
    SEED_KEY,
    leak_warning,
    recording_custom_data,
)
from lf_predictor_ros.benchmark.recordings import LOOPS


def test_custom_data_names_scenario_seed_loop_and_estimator() -> None:
    assert recording_custom_data('rao_supply', 17, 'estimator', 'observer') == {
        SCENARIO_KEY: 'rao_supply', SEED_KEY: '17', RECORDING_LOOP_KEY: 'estimator',
        RECORDING_ESTIMATOR_KEY: 'observer'}
    assert RECORDING_ESTIMATOR_KEY not in recording_custom_data('x', 1, 'open')


def test_only_a_loop_on_the_truth_warns() -> None:
    warnings = {loop: leak_warning(recording_custom_data('s', 1, loop)) for loop in LOOPS}
    assert warnings['open'] is None and warnings['estimator'] is None
    assert warnings['truth_lf'] is not None and 'true LF pose' in warnings['truth_lf']
    assert leak_warning({}) is None  # a bag without custom data claims nothing
