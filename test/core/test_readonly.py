"""Read-only arrays through pickling (core/readonly.py): a child process's results stay frozen."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from lf_predictor_ros.core.lf_dynamics import LfDynamics
from lf_predictor_ros.core.lf_state import ControllerRead
from lf_predictor_ros.core.readonly import read_only
from lf_predictor_ros.core.targets import TargetWindow


def test_read_only_freezes_arrays_in_place_also_inside_tuples() -> None:
    a, b = np.zeros(2), np.ones(3)
    value = (a, (b, 'text'), None)
    assert read_only(value) is value
    assert not a.flags.writeable and not b.flags.writeable
    assert np.array_equal(b, np.ones(3))


def test_numpy_alone_loses_the_flag() -> None:
    """Why the mixin exists: numpy does not pickle ``writeable``."""
    array = np.zeros(3)
    array.setflags(write=False)
    assert pickle.loads(pickle.dumps(array)).flags.writeable


@pytest.mark.parametrize('record', [
    TargetWindow(np.arange(6.0).reshape(3, 2), 41),
    LfDynamics(np.diag([-0.1, -0.2]), np.diag([1e-6, 2e-6]), np.zeros((2, 3)), np.ones(2)),
    ControllerRead(np.array([1e-6, 2e-6, 3e-9]), 'read', 'read', 12.0, np.ones(3)),
])
def test_records_stay_read_only_and_equal_through_pickling(record: object) -> None:
    copy = pickle.loads(pickle.dumps(record))
    for name, value in vars(record).items():
        got = getattr(copy, name)
        if isinstance(value, np.ndarray):
            assert np.array_equal(got, value) and got.dtype == value.dtype
            assert not value.flags.writeable and not got.flags.writeable
        else:
            assert got == value


def test_a_retraining_result_keeps_its_narrow_reference_read_only() -> None:
    from lf_predictor_ros.core.frequency import FrequencyEstimate
    from lf_predictor_ros.core.retraining import RetrainResult

    reference = read_only(np.arange(4.0))
    spread = np.ones(2)  # not read-only in the worker's result: it stays as it was
    frequency = FrequencyEstimate(0.6, True, 9.0, (0.6,), 0.2)
    result = RetrainResult(segment=0, end_index=9, frequency=frequency,
                           targets=TargetWindow(np.zeros(4), 9), model=None, state_dict=None,
                           loss=1.0, incumbent_loss=None, accepted=False, reason='test',
                           seconds=0.1, epochs=1, wave_spread=spread, narrow_reference=reference)
    copy = pickle.loads(pickle.dumps(result))
    assert copy.narrow_reference is not None and np.array_equal(copy.narrow_reference, reference)
    assert not copy.narrow_reference.flags.writeable and not copy.targets.values.flags.writeable
    assert copy.wave_spread is not None and copy.wave_spread.flags.writeable
    assert copy.frequency == result.frequency and copy.reason == 'test'
