"""The published history as columns (core/published_columns.py): a lossless round trip."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from lf_predictor_ros.core.odometry import Published
from lf_predictor_ros.core.published_columns import PublishedColumns


def history(count: int, seed: int) -> list[Published]:
    """Seeded 3-DOF records: two sources, the twin excess on every third record only."""
    rng = np.random.default_rng(seed)
    return [Published(float(100.0 + i + rng.uniform()), rng.normal(size=3), rng.normal(size=3),
                      'network' if i % 2 else 'fallback', rng.normal(size=3),
                      rng.normal(size=3), rng.normal(size=3) if i % 3 == 0 else None)
            for i in range(count)]


def assert_same_records(got: list[Published], expected: list[Published]) -> None:
    assert len(got) == len(expected)
    for a, b in zip(got, expected, strict=True):
        assert a.stamp == b.stamp and a.source == b.source
        for name in ('pose', 'twist', 'accel', 'lag'):
            assert np.array_equal(getattr(a, name), getattr(b, name))  # to the last bit
            assert getattr(a, name).dtype == np.float64
        if b.twin_excess is None:
            assert a.twin_excess is None
        else:
            assert a.twin_excess is not None and np.array_equal(a.twin_excess, b.twin_excess)


def test_records_come_back_value_for_value_through_pickling() -> None:
    records = history(50, seed=1)
    columns = pickle.loads(pickle.dumps(PublishedColumns.of(records)))
    assert columns.sources == ('fallback', 'network')
    assert int(np.count_nonzero(columns.has_twin_excess)) == 17  # records 0, 3, …, 48
    assert_same_records(columns.records(), records)


def test_each_record_gets_arrays_of_its_own() -> None:
    columns = PublishedColumns.of(history(3, seed=2))
    first, second = columns.records()[:2]
    first.pose[0] = 1e9  # a record's arrays are copies, not views of the columns
    assert second.pose[0] != 1e9 and columns.pose[0, 0] != 1e9


def test_without_twin_excess_and_empty() -> None:
    records = [Published(1.0, np.zeros(1), np.ones(1), 'network', np.zeros(1), np.ones(2))]
    assert_same_records(PublishedColumns.of(records).records(), records)
    assert PublishedColumns.of([]).records() == []


@pytest.mark.parametrize('odd', [np.zeros(2), np.zeros(3, dtype=np.float32), [0.0, 0.0, 0.0]])
def test_rows_of_another_shape_or_type_are_refused(odd: object) -> None:
    records = history(4, seed=3)
    records[2] = Published(records[2].stamp, odd, records[2].twist,  # type: ignore[arg-type]
                           'network', records[2].accel, records[2].lag)
    with pytest.raises(ValueError, match='send the records as they are'):
        PublishedColumns.of(records)
