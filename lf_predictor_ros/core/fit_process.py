"""The node's background jobs in a child process (issue 13, cost: the callbacks while training).

The ω0 spectrum fit, the retraining and the vessel memory's job run on worker threads of the
node's process, and every Python step of theirs holds the GIL against the pose callbacks. A
thread waiting for the GIL takes it back only after Python's switch interval (5 ms) if the
holder does not release it sooner, so a callback that meets a running job can take milliseconds
instead of a tenth of one. scipy's Nelder-Mead (`frequency._fit_peak`) kept the callbacks from
the GIL for up to 132 ms (docs/BENCHMARKS.md, twenty-eighth session); with the fit here, the
retraining and the vessel memory's job still stretched callbacks that only store a pose to
1.4–7.5 ms (45 of 9500 while training in one run; sixty-sixth session). In a child process a job
holds no lock of the node's, and the worker thread waits for its result with the GIL released.

`FitProcess.run` computes any module-level function of picklable arguments in one long-lived
child process (a `ProcessPoolExecutor` of one worker, started by `FitProcess.start` or the first
call); called with `frequency.spectrum_estimate`'s arguments a `FitProcess` is a
`frequency.SpectrumFit`. The child comes from the 'forkserver' start method: a fork of a small
server process that has imported numpy, scipy, torch and the jobs' modules only (`PRELOAD`),
never a fork of the node, whose rclpy and torch threads a fork would copy in an unknown state
('spawn' where forkserver does not exist). Its numbers are those of the calling thread: the same
functions, libraries and CPU (`test/core/test_fit_process.py`). Jobs run one at a time, in the
order asked.

An error of the job itself (a ValueError for too little data) is raised to the caller as it is.
When the child cannot be started or dies, the job is computed on the calling thread instead (the
same numbers; counted in ``failures``) and the next call starts a new child.

The predictor and the vessel memory use it for their background jobs only (`predictor`,
`lf_state`); inline ones (replay, benchmarks) compute on their own thread as before.

A job and its result cross as bytes of a plain pickle in which torch tensors travel as numpy
arrays (`_packed`). The executor's own pickler (multiprocessing's) would move every tensor of a
state_dict into a shared-memory file and pass its descriptor through a helper thread and a
socket: a round trip of a linear network's state_dict took 20–46 ms of threads in the node that
take the GIL in turns with the callbacks, against 0.6 ms as arrays (docs/BENCHMARKS.md,
sixty-seventh session). A job the child cannot unpickle (a function it cannot import) is
computed on the calling thread, and the child stays.
"""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import CancelledError, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
import io
import multiprocessing
import os
import pickle
import signal
import sys
import threading
import time
from typing import Any, TypeVar, cast
import weakref

import numpy as np

from lf_predictor_ros.core.frequency import FrequencyEstimate, _FloatArray, spectrum_estimate
from lf_predictor_ros.core.math_threads import use_one_math_thread

# what the forkserver imports once, before it forks the child: the jobs' modules (torch with
# them), so that no job waits for an import
PRELOAD = ['lf_predictor_ros.core.frequency', 'lf_predictor_ros.core.retraining',
           'lf_predictor_ros.core.lf_state']
PARENT_CHECK_PERIOD = 1.0  # [s] how often the child checks that the node still exists
STOP_CHECK_PERIOD = 0.05  # [s] how often `FitProcess.run` looks at its ``stop`` while waiting
ABANDONED_RETRIES = 2  # times a job cut off by another's abandonment is asked of a new child
_T = TypeVar('_T')
_NO_CHILD = object()  # `FitProcess._ask`'s answer when there is no child


class JobAbandonedError(Exception):
    """`FitProcess.run` stopped waiting: its ``stop`` was set (the child was ended)."""


class JobNotLoadableError(Exception):
    """The child could not unpickle a job (e.g. a function it cannot import)."""


class FitProcess:
    """Background jobs in one long-lived child process (module docstring)."""

    def __init__(self) -> None:
        """No process runs until `start` or the first call."""
        self._lock = threading.Lock()
        self._executor: ProcessPoolExecutor | None = None
        self.failures = 0  # jobs computed on the caller's thread: no child, or it died
        # children ended because their job was abandoned (`_end_abandoned`): not broken
        self._ended: weakref.WeakSet[ProcessPoolExecutor] = weakref.WeakSet()
        self.starts = 0  # children started

    def __call__(self, data: _FloatArray, sample_time: float, highpass_cutoff: float,
                 wave_band: tuple[float, float], min_peak_ratio: float,
                 previous: float | FrequencyEstimate | None) -> FrequencyEstimate:
        """`spectrum_estimate` of these arguments, computed in the child."""
        return self.run(spectrum_estimate, data, sample_time, highpass_cutoff, wave_band,
                        min_peak_ratio, previous)

    def run(self, function: Callable[..., _T], *args: object,
            stop: threading.Event | None = None,
            fallback: Callable[[], _T] | None = None) -> _T:
        """``function(*args)`` computed in the child (a module-level function, picklable args).

        Without a child (it cannot start, was killed, or closed meanwhile) ``fallback()`` is
        computed on this thread instead (None: ``function(*args)``), counted in ``failures``.
        Raises what ``function`` raised, and `JobAbandonedError` once ``stop`` is set while waiting
        (looked at every `STOP_CHECK_PERIOD`; the child computing it is ended, `_ask`).
        """
        answer = self._ask(function, *args, stop=stop)
        if answer is _NO_CHILD:
            with self._lock:
                self.failures += 1
            return fallback() if fallback is not None else function(*args)
        return cast(_T, answer)

    def start(self) -> bool:
        """Start the child now and wait until it answers (not at the first fit).

        The first start of a process's forkserver imports `PRELOAD` (numpy, scipy, torch) in a
        fresh interpreter (seconds): at the first job, a lockstep run would wait that long for
        its first ω0 (the demo lost its first two trainings). False if no child can be started.
        """
        return self._ask(_ready) is not _NO_CHILD

    def _ask(self, function: Callable[..., _T], *args: object,
             stop: threading.Event | None = None) -> object:
        """``function(*args)`` in the child; `_NO_CHILD` when the child is not there.

        An exception of ``function`` itself is raised here as it is; `JobAbandonedError` once
        ``stop`` is set while waiting, and the child is then ended (`_end_abandoned`): a long
        training it went on with would hold up every job after it. A job of another thread
        that this ending cut off is asked again of a new child.
        """
        try:
            job = _packed((function, args))
        except Exception:  # noqa: BLE001 - cannot be pickled: computed here, the child stays
            return _NO_CHILD
        for _ in range(ABANDONED_RETRIES + 1):
            executor: ProcessPoolExecutor | None = None
            try:
                executor = self._running()
                future = executor.submit(_call_packed, job)
            except Exception:  # noqa: BLE001 - no child: cannot start (e.g. in a daemonic
                future = None  # process, an AssertionError), or a broken or closed pool
            if future is not None:
                try:
                    return _unpacked(_result(future, stop))
                except JobNotLoadableError:
                    return _NO_CHILD  # computed here; the child is fine
                except JobAbandonedError:
                    self._end_abandoned(executor)
                    raise
                except (BrokenProcessPool, CancelledError):  # the child died, or closed
                    if executor in self._ended:
                        continue  # ended by an abandoned job, not broken: a new child
            self._discard()
            return _NO_CHILD
        return _NO_CHILD

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

    def _end_abandoned(self, executor: ProcessPoolExecutor | None) -> None:
        """End the child computing an abandoned job (the next job starts a new one)."""
        if executor is None:
            return
        with self._lock:
            self._ended.add(executor)
            if self._executor is executor:
                self._executor = None
        for process in list((getattr(executor, '_processes', None) or {}).values()):
            process.terminate()  # ProcessPoolExecutor has no public way before Python 3.14
        executor.shutdown(wait=False, cancel_futures=True)


def _result(future: Future[_T], stop: threading.Event | None) -> _T:
    """The future's result; `JobAbandonedError` once ``stop`` is set before it is there."""
    if stop is None:
        return future.result()
    while True:
        try:
            return future.result(timeout=STOP_CHECK_PERIOD)
        except TimeoutError:
            if future.done():  # the job itself raised a TimeoutError
                raise
            if stop.is_set():
                raise JobAbandonedError('stopped while the child computes the job') from None


def _ready() -> bool:
    """The child's answer to `FitProcess.start`."""
    return True


class _ArrayPickler(pickle.Pickler):
    """A plain pickler that writes a CPU torch tensor as its numpy array (`_packed`).

    Each tensor arrives with its own memory: tensors that were views of one storage (none in
    a state_dict of this package's networks) are no longer shared.
    """

    def reducer_override(self, obj: Any) -> Any:
        torch = sys.modules.get('torch')  # no tensor exists before torch is imported
        if torch is None or type(obj) is not torch.Tensor or obj.requires_grad or \
                obj.device.type != 'cpu' or obj.layout != torch.strided:
            return NotImplemented
        try:
            array = obj.numpy()  # the tensor's own memory: written by value below
        except (TypeError, RuntimeError):  # a dtype numpy has not (bfloat16): pickled as usual
            return NotImplemented
        return _tensor_from_array, (array,)


def _tensor_from_array(array: np.ndarray) -> Any:
    """The tensor `_ArrayPickler` wrote (same dtype, shape and numbers)."""
    import torch
    return torch.from_numpy(array)


def _packed(value: object) -> bytes:
    """``value`` as plain pickle bytes, its tensors as numpy arrays (module docstring)."""
    buffer = io.BytesIO()
    _ArrayPickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(value)
    return buffer.getvalue()


def _unpacked(data: object) -> object:
    """The value `_packed` wrote (`_call_packed`'s answer)."""
    return pickle.loads(cast(bytes, data))


def _call_packed(job: bytes) -> bytes:
    """In the child: the packed ``(function, args)`` computed, its result packed.

    `JobNotLoadableError` when the job cannot be unpickled here; the function's own errors
    are raised as they are.
    """
    try:
        function, args = pickle.loads(job)
    except Exception as error:  # noqa: BLE001 - e.g. a function of a module not importable here
        raise JobNotLoadableError(f'{type(error).__name__}: {error}') from None
    return _packed(function(*args))


def _child_setup(parent: int) -> None:
    """In the child: Ctrl-C is the parent's to handle, and the child ends with its parent.

    A terminal's Ctrl-C reaches the whole process group. The parent (the node) ends on it and
    shuts the child down; the child itself would only print a KeyboardInterrupt traceback.
    A parent killed outright (SIGKILL, a crash) cannot shut it down, and a pool worker waits for
    work forever (it holds its own queue's write end), keeping the forkserver alive with it: a
    daemon thread checks every `PARENT_CHECK_PERIOD` that the parent still exists. The math
    libraries run on one thread (`math_threads.use_one_math_thread`).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    use_one_math_thread()  # the other core is the node's (`core.math_threads`)
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
