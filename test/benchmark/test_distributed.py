"""Cases on Dask: identical numbers in process, on a LocalCluster and at a scheduler address."""
from __future__ import annotations

import io

import pytest

from lf_predictor_ros.benchmark.distributed import (
    IN_PROCESS,
    CaseSpec,
    ProgressBar,
    run_case_task,
    run_cases,
)
from lf_predictor_ros.benchmark.suite import CaseResult

SPECS = [CaseSpec('onedof_reference', seed, 700.0, {'max_epochs': 5},
                  estimators=('adaptive', 'cascade', 'raw'), loop_estimators=())
         for seed in (11, 12)]


def _numbers(results: list[CaseResult]) -> list[dict[str, object]]:
    return [{'seed': r.seed, 'metrics': {k: v.to_dict() for k, v in r.metrics.items()},
             'leak': r.leak} for r in results]


@pytest.fixture(scope='module')
def in_process() -> list[CaseResult]:
    return run_cases(SPECS, IN_PROCESS, progress=False)


@pytest.mark.slow
def test_local_cluster_and_scheduler_address_give_identical_numbers(
        in_process: list[CaseResult]) -> None:
    from dask.distributed import LocalCluster

    assert [r.seed for r in in_process] == [11, 12]  # the order of the specs
    assert in_process[0].metrics['adaptive'].rmse != in_process[1].metrics['adaptive'].rmse
    local = run_cases(SPECS, None, workers=2, progress=False)
    assert _numbers(local) == _numbers(in_process)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        remote = run_cases(SPECS[:1], cluster.scheduler_address, progress=False)
    assert _numbers(remote) == _numbers(in_process[:1])


def test_a_failing_case_raises_with_its_error() -> None:
    bad = [CaseSpec('onedof_reference', 11, 700.0, estimators=('no_such_estimator',))]
    with pytest.raises(ValueError, match='unknown estimator'):
        run_cases(bad, IN_PROCESS, progress=False)


def test_progress_bar_counts_and_estimates() -> None:
    stream = io.StringIO()
    bar = ProgressBar(4, stream, width=8)
    line = bar.update('supply seed 11')
    assert line.startswith('[##------] 1/4 cases') and 'last: supply seed 11' in line
    bar.update('x')
    assert stream.getvalue().count('\n') == 2 and '[####----] 2/4 cases' in stream.getvalue()


def test_spec_runs_the_same_case_as_run_case_task(in_process: list[CaseResult]) -> None:
    again = run_case_task(SPECS[0])
    assert _numbers([again]) == _numbers(in_process[:1])
    assert SPECS[0].key.startswith('case-onedof_reference-seed11-')
