"""The published history as columns (core/published_columns.py): lossless, and snapshots hold."""
from __future__ import annotations

import pickle
from typing import get_args

import numpy as np
import pytest

from lf_predictor_ros.core.published_columns import (
    SOURCES,
    EstimateSource,
    Published,
    PublishedLog,
)
from lf_predictor_ros.core.row_buffer import MIN_ROWS


def history(count: int, seed: int) -> list[Published]:
    """Seeded 3-DOF records: two sources, the twin excess on every third record only."""
    rng = np.random.default_rng(seed)
    return [Published(float(100.0 + i + rng.uniform()), rng.normal(size=3), rng.normal(size=3),
                      'network' if i % 2 else 'fallback', rng.normal(size=3),
                      rng.normal(size=3), rng.normal(size=3) if i % 3 == 0 else None)
            for i in range(count)]


def logged(records: list[Published], capacity: int | None = None) -> PublishedLog:
    log = PublishedLog(capacity or max(1, len(records)))
    for record in records:
        log.append(record)
    return log


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
    columns = pickle.loads(pickle.dumps(logged(records).columns()))
    assert columns.sources == ('fallback', 'network')  # in the order they first came
    assert len(columns) == 50 and columns.pose.shape == (50, 3)
    assert int(np.count_nonzero(columns.has_twin_excess)) == 17  # records 0, 3, …, 48
    assert np.isnan(columns.twin_excess[1]).all()
    assert_same_records(columns.records(), records)


def test_each_record_gets_arrays_of_its_own_and_the_columns_are_read_only() -> None:
    columns = logged(history(3, seed=2)).columns()
    first, second = columns.records()[:2]
    first.pose[0] = 1e9  # a record's arrays are copies, not views of the columns
    assert second.pose[0] != 1e9 and columns.pose[0, 0] != 1e9
    with pytest.raises(ValueError, match='read-only'):
        columns.twist[0, 0] = 1.0


def test_the_log_keeps_the_newest_capacity_records_across_its_buffer_moves() -> None:
    records = history(10 * MIN_ROWS + 7, seed=4)
    log = PublishedLog(100)
    for count, record in enumerate(records, start=1):
        log.append(record)
        assert len(log) == min(count, 100)
    assert_same_records(log.columns().records(), records[-100:])


def test_a_snapshot_is_not_changed_by_later_appends_or_moves() -> None:
    records = history(600, seed=5)
    log = logged(records[:150], capacity=100)
    snapshot = log.columns()
    kept = pickle.dumps(snapshot)
    for record in records[150:]:  # past several moves of the buffers (2 × 100 rows each)
        log.append(record)
    assert pickle.dumps(snapshot) == kept
    assert_same_records(snapshot.records(), records[50:150])
    assert_same_records(log.columns().records(), records[-100:])


def test_a_log_of_one() -> None:
    records = history(5, seed=6)
    log = logged(records, capacity=1)
    assert_same_records(log.columns().records(), records[-1:])


def test_without_twin_excess_other_widths_and_empty() -> None:
    records = [Published(1.0, np.zeros(1), np.ones(1), 'network', np.zeros(1), np.ones(2))]
    assert_same_records(logged(records).columns().records(), records)
    empty = PublishedLog(5).columns()
    assert len(empty) == 0 and empty.records() == [] and empty.sources == ()


def test_integer_vectors_are_kept_as_float64() -> None:
    record = Published(2.0, np.array([1, 2, 3]), np.zeros(3), 'fallback', np.zeros(3),
                       np.zeros(3))
    (back,) = logged([record]).columns().records()
    assert back.pose.dtype == np.float64 and back.pose.tolist() == [1.0, 2.0, 3.0]


@pytest.mark.parametrize('odd', [np.zeros(2), np.zeros((1, 3)), [0.0, 0.0, 0.0], np.float64(0.0),
                                 np.zeros(3, dtype=complex), np.array(['a', 'b', 'c'])])
def test_rows_of_another_shape_or_type_are_refused_and_the_log_stays(odd: object) -> None:
    records = history(4, seed=3)
    log = logged(records[:2], capacity=10)
    before = pickle.dumps(log.columns())
    bad = Published(records[2].stamp, records[2].pose, records[2].twist, 'network',
                    records[2].accel, records[2].lag, odd)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match='twin_excess must be a real array of shape'):
        log.append(bad)
    assert pickle.dumps(log.columns()) == before
    log.append(records[3])
    assert_same_records(log.columns().records(), records[:2] + records[3:])


def test_the_first_record_must_carry_vectors() -> None:
    with pytest.raises(ValueError, match='pose must be a 1-D numpy array'):
        PublishedLog(3).append(Published(1.0, [0.0], np.zeros(1), 'network',  # type: ignore
                                          np.zeros(1), np.zeros(1)))


@pytest.mark.parametrize('capacity', [0, -1, 2.0])
def test_invalid_capacity(capacity: object) -> None:
    with pytest.raises(ValueError, match='capacity >= 1'):
        PublishedLog(capacity)  # type: ignore[arg-type]


def test_sources_are_every_estimate_source() -> None:
    assert SOURCES == get_args(EstimateSource) == ('network', 'fallback')
