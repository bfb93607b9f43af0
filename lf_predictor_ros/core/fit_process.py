"""The ω0 spectrum fit in a child process (issue 13, cost: the node's callbacks while training).

scipy's Nelder-Mead (`frequency._fit_peak`), run on the predictor's worker thread, keeps the
node's pose callbacks from taking the GIL for up to 132 ms; the longest callbacks while training
(37–112 ms) overlapped it (docs/BENCHMARKS.md, twenty-eighth session). In a child process the fit
holds no lock of the node's, and the worker thread waits for its result with the GIL released.

`FitProcess` is a `frequency.SpectrumFit`: called with `frequency.spectrum_estimate`'s
arguments, it returns that function's result, computed in one long-lived child process (a
`ProcessPoolExecutor` of one worker, started by `FitProcess.start` or the first call). The
child comes from the 'forkserver' start method: a fork of a small server process that has
imported numpy, scipy and `core.frequency` only, never a fork of the node, whose rclpy and torch
threads a fork would copy in an unknown state ('spawn' where forkserver does not exist). Its
numbers are those of the calling thread: the same function, library and CPU
(`test/core/test_fit_process.py`).

An error of the estimate itself (a ValueError for too little data) is raised to the caller as
it is. When the child cannot be started or dies, the estimate is computed on the calling thread
instead (the same numbers; counted in ``failures``) and the next call starts a new child.

The predictor uses it for its background jobs only (`frequency.spectrum_fit_by`); inline
predictors (replay, benchmarks) compute on their own thread as before.
"""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import CancelledError, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
import multiprocessing
import os
import signal
import threading
import time
from typing import TypeVar

from lf_predictor_ros.core.frequency import FrequencyEstimate, _FloatArray, spectrum_estimate

# what the forkserver imports once, before it forks the child
PRELOAD = ['lf_predictor_ros.core.frequency']
PARENT_CHECK_PERIOD = 1.0  # [s] how often the child checks that the node still exists
_T = TypeVar('_T')


class FitProcess:
    """`frequency.spectrum_estimate` in one long-lived child process (module docstring)."""

    def __init__(self) -> None:
        """No process runs until `start` or the first call."""
        self._lock = threading.Lock()
        self._executor: ProcessPoolExecutor | None = None
        self.failures = 0  # fits computed on the caller's thread: no child, or it died
        self.starts = 0  # children started

    def __call__(self, data: _FloatArray, sample_time: float, highpass_cutoff: float,
                 wave_band: tuple[float, float], min_peak_ratio: float,
                 previous: float | FrequencyEstimate | None) -> FrequencyEstimate:
        """`spectrum_estimate` of these arguments, computed in the child."""
        args = (data, sample_time, highpass_cutoff, wave_band, min_peak_ratio, previous)
        answer = self._ask(spectrum_estimate, *args)
        if answer is None:  # no child (cannot start, killed, closed meanwhile): computed here
            with self._lock:
                self.failures += 1
            return spectrum_estimate(*args)
        return answer

    def start(self) -> bool:
        """Start the child now and wait until it answers (not at the first fit).

        The first start of a process's forkserver imports numpy and scipy in a fresh
        interpreter (1–2 s): at the first fit, a lockstep run would wait that long for its first
        ω0 (the demo lost its first two trainings). False if no child can be started.
        """
        return self._ask(_ready) is not None

    def _ask(self, function: Callable[..., _T], *args: object) -> _T | None:
        """``function(*args)`` in the child; None when the child is not there.

        An exception of ``function`` itself is raised here as it is.
        """
        try:
            future = self._running().submit(function, *args)
        except Exception:  # noqa: BLE001 - no child: cannot start (e.g. in a daemonic process,
            future = None  # an AssertionError), or a broken or closed pool
        if future is not None:
            try:
                return future.result()
            except (BrokenProcessPool, CancelledError):  # the child died, or close() meanwhile
                pass
        self._discard()
        return None

    @property
    def running(self) -> bool:
        """A child process is (or is being) started."""
        return self._executor is not None

    def close(self) -> None:
        """Stop the child (does not wait); the next call starts a new one."""
        self._discard()

    def _running(self) -> ProcessPoolExecutor:
        with self._lock:
            if self._executor is None:
                self._executor = ProcessPoolExecutor(max_workers=1, mp_context=_context(),
                                                     initializer=_child_setup,
                                                     initargs=(os.getpid(),))
                self.starts += 1
            return self._executor

    def _discard(self) -> None:
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=False, cancel_futures=True)


def _ready() -> bool:
    """The child's answer to `FitProcess.start`."""
    return True


def _child_setup(parent: int) -> None:
    """In the child: Ctrl-C is the parent's to handle, and the child ends with its parent.

    A terminal's Ctrl-C reaches the whole process group. The parent (the node) ends on it and
    shuts the child down; the child itself would only print a KeyboardInterrupt traceback.
    A parent killed outright (SIGKILL, a crash) cannot shut it down, and a pool worker waits for
    work forever (it holds its own queue's write end), keeping the forkserver alive with it: a
    daemon thread checks every `PARENT_CHECK_PERIOD` that the parent still exists.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_end_with, args=(parent,), name='fit-parent-watch',
                     daemon=True).start()


def _end_with(parent: int) -> None:
    """End this process once ``parent`` has ended.

    Polled: the parent of a forkserver child is the forkserver, not the node, so Linux's
    parent-death signal cannot tell.
    """
    while True:
        time.sleep(PARENT_CHECK_PERIOD)
        try:
            os.kill(parent, 0)
        except (ProcessLookupError, PermissionError):  # gone (or the pid is another user's now)
            os._exit(0)


def _context() -> multiprocessing.context.BaseContext:
    """The forkserver context with the frequency module preloaded; spawn without forkserver."""
    if 'forkserver' not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context('spawn')
    context = multiprocessing.get_context('forkserver')
    context.set_forkserver_preload(PRELOAD)  # only read when the server starts
    return context


_SHARED: FitProcess | None = None
_SHARED_LOCK = threading.Lock()


def shared_fit_process() -> FitProcess:
    """The process-wide `FitProcess` (one child for every predictor of this process)."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is None:
            _SHARED = FitProcess()
        return _SHARED
