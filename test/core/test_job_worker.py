"""The predictor's long-lived worker thread (core.job_worker)."""
from __future__ import annotations

import threading
import time

import pytest

from lf_predictor_ros.core.job_worker import JobWorker


def test_jobs_run_in_order_on_one_thread_started_once() -> None:
    worker = JobWorker('test-worker')
    assert worker.thread is None and not worker.busy  # no thread before the first job
    ran: list[tuple[int, int | None]] = []
    for k in range(5):
        worker.submit(lambda k: ran.append((k, threading.get_ident())), k)
    assert worker.wait(5.0)
    assert [k for k, _ in ran] == [0, 1, 2, 3, 4]
    assert len({ident for _, ident in ran}) == 1
    assert ran[0][1] != threading.get_ident()
    thread = worker.thread
    assert thread is not None and thread.name == 'test-worker' and thread.daemon
    worker.submit(lambda: None)
    assert worker.wait(5.0)
    assert worker.thread is thread  # reused, not started again
    worker.shutdown()


def test_submit_does_not_wait_for_a_running_job() -> None:
    worker = JobWorker('test-worker')
    release = threading.Event()
    worker.submit(release.wait, 10.0)
    start = time.monotonic()
    worker.submit(lambda: None)  # queued behind the blocked job
    assert time.monotonic() - start < 5.0  # waiting for the job would take 10 s
    assert worker.busy
    assert not worker.wait(0.05)  # still blocked: False after the timeout
    release.set()
    assert worker.wait(5.0)
    assert not worker.busy
    worker.shutdown()


def test_an_idle_thread_ends_and_the_next_job_starts_a_new_one() -> None:
    worker = JobWorker('test-worker', idle_timeout=0.05)
    worker.submit(lambda: None)
    assert worker.wait(5.0)
    first = worker.thread
    assert first is not None
    first.join(5.0)
    assert not first.is_alive() and worker.thread is None
    done = threading.Event()
    worker.submit(done.set)
    assert done.wait(5.0)
    assert worker.thread is not first
    worker.shutdown()


def test_shutdown_ends_the_thread_once_the_queue_is_empty() -> None:
    worker = JobWorker('test-worker')
    release = threading.Event()
    ran: list[int] = []
    worker.submit(release.wait, 10.0)
    worker.submit(ran.append, 1)
    thread = worker.thread
    assert thread is not None
    worker.shutdown()
    worker.submit(ran.append, 2)  # after the shutdown: runs, and the thread stays for it
    release.set()
    assert worker.wait(5.0)
    assert ran == [1, 2]
    assert worker.thread is thread and thread.is_alive()
    worker.shutdown()
    thread.join(5.0)
    assert not thread.is_alive() and worker.thread is None
    worker.submit(ran.append, 3)  # a new thread after a shutdown
    assert worker.wait(5.0)
    assert ran == [1, 2, 3]
    worker.shutdown()
    worker.shutdown()  # twice is harmless


def test_a_raising_job_is_reported_and_the_next_job_runs(
        capsys: pytest.CaptureFixture[str]) -> None:
    worker = JobWorker('test-worker')

    def fail() -> None:
        raise RuntimeError('job failed on purpose')
    ran: list[int] = []
    worker.submit(fail)
    worker.submit(ran.append, 7)
    assert worker.wait(5.0)
    assert ran == [7] and not worker.busy
    assert 'job failed on purpose' in capsys.readouterr().err
    worker.shutdown()


@pytest.mark.parametrize('idle_timeout', [0.0, -1.0, float('nan')])
def test_invalid_idle_timeout_is_refused(idle_timeout: float) -> None:
    with pytest.raises(ValueError, match='idle_timeout'):
        JobWorker('test-worker', idle_timeout=idle_timeout)
