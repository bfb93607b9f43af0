"""A long-lived worker thread for the predictor's training and ω0 jobs (issue 13, cost).

Starting a `threading.Thread` per job blocks the caller until the new thread has started. On the
project's 2-core machine the pose callback that started a training took 5.3 ms (median of 25;
1.2–1.4 ms with this worker; docs/BENCHMARKS.md, twenty-eighth session). One daemon thread fed
by a queue costs the caller a queue put, and the thread is started once.

Jobs run one at a time, in the order submitted. The thread ends after ``idle_timeout`` seconds
without a job, or after `shutdown` once the queue is empty; the next `submit` starts a new one.
So a worker dropped without `shutdown` (its owner garbage collected) does not keep its thread
for long.

Not `concurrent.futures.ThreadPoolExecutor`: its threads are not daemons and are joined at
interpreter exit *before* `atexit` hooks run, so a script that forgets `close()` would wait out a
whole training before the predictor's hook could stop it.
"""
from __future__ import annotations

from collections.abc import Callable
import queue
import threading
import traceback
from typing import Any

# [s] a thread with no job for this long ends: 10 × the default Δ (60 s). With a longer Δ the
# thread ends between trainings and each job starts one, as every job did before this worker.
IDLE_TIMEOUT = 600.0

_Job = tuple[Callable[..., object], tuple[Any, ...]] | None  # None: the shutdown marker


class JobWorker:
    """One daemon thread that runs submitted jobs one after the other."""

    def __init__(self, name: str, idle_timeout: float = IDLE_TIMEOUT) -> None:
        """A worker whose thread is called ``name``; no thread runs until the first job.

        Raises:
            ValueError: ``idle_timeout`` is not positive.
        """
        if not idle_timeout > 0.0:
            raise ValueError(f'idle_timeout must be > 0 s, got {idle_timeout}')
        self.name = name
        self.idle_timeout = idle_timeout
        self._jobs: queue.SimpleQueue[_Job] = queue.SimpleQueue()
        self._lock = threading.Condition()
        self._pending = 0  # submitted and not yet finished (guarded by _lock)
        self._thread: threading.Thread | None = None  # None: no thread (guarded by _lock)

    @property
    def busy(self) -> bool:
        """A submitted job has not finished yet (queued or running).

        Read without the lock (one int, for the pose callback's check); `wait` synchronizes.
        """
        return self._pending > 0

    @property
    def thread(self) -> threading.Thread | None:
        """The worker's thread while it has one (for tests and diagnostics)."""
        return self._thread

    def submit(self, job: Callable[..., object], *args: Any) -> None:
        """Run ``job(*args)`` on the worker thread after the jobs before it.

        The job should not raise: an exception's traceback is printed to stderr (as for an
        uncaught exception in a thread) and the worker goes on with the next job.
        """
        with self._lock:
            self._pending += 1
            self._jobs.put((job, args))
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
                self._thread.start()  # once per thread, not once per job

    def wait(self, timeout: float | None = None) -> bool:
        """Block until every submitted job has finished or ``timeout`` [s] has passed.

        True when none is pending any more.
        """
        with self._lock:
            return self._lock.wait_for(lambda: self._pending == 0, timeout)

    def shutdown(self) -> None:
        """Let the thread end once the queue is empty (does not wait).

        The jobs already submitted still run; a job submitted later keeps the thread (or starts
        a new one), and the next `shutdown` ends it.
        """
        with self._lock:
            if self._thread is not None:
                self._jobs.put(None)

    def _run(self) -> None:
        while True:
            try:
                item = self._jobs.get(timeout=self.idle_timeout)
            except queue.Empty:
                item = None
            if item is None:
                with self._lock:  # end only if no job came in meanwhile (submit holds the lock)
                    if self._jobs.empty():
                        self._thread = None
                        return
                continue
            job, args = item
            try:
                job(*args)
            except Exception:  # noqa: BLE001 - report it, keep serving the next jobs
                traceback.print_exc()
            finally:
                with self._lock:
                    self._pending -= 1
                    self._lock.notify_all()
