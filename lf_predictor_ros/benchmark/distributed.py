"""Run benchmark cases on Dask distributed: a LocalCluster here, a scheduler address on a cluster.

Every case (scenario, seed) is one task, `run_case_task`, a pure function of its `CaseSpec`: it
seeds nothing globally, runs torch and BLAS on one thread (so the numbers do not depend on how
many cores a worker has: a threaded BLAS sums in another order on some CPUs, and the last bits
then differ between this process and a worker) and returns a `CaseResult`. Where a case runs
therefore changes nothing: the same spec gives the same numbers in this process, in a
LocalCluster worker or on a remote worker (the test compares them bit for bit).

``scheduler=None`` starts an in-process `LocalCluster` with one single-threaded worker process
per core (``workers``), closed again when the cases are done; ``scheduler='tcp://HOST:PORT'``
submits to an existing cluster, whose workers must have this package installed (the same
version). ``scheduler='none'`` runs the cases one after another in this process (debugging).
Progress is a text bar on stderr, one line per finished case.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import os
import sys
import time
from typing import Any, TextIO

from threadpoolctl import threadpool_limits

from lf_predictor_ros.benchmark.suite import CaseResult, run_case
from lf_predictor_ros.core.math_threads import BLAS_THREAD_VARIABLES

IN_PROCESS = 'none'


@dataclass(frozen=True)
class CaseSpec:
    """Everything one case needs (picklable)."""

    scenario: str
    seed: int
    duration: float | None = None
    params_overrides: dict[str, Any] = field(default_factory=dict)
    recording_loop: str = 'observer'
    estimators: tuple[str, ...] | None = None  # None: every estimator
    loop_estimators: tuple[str, ...] | None = None  # None: every loop if the scenario has a PID
    schedule_shift: float = 0.0  # s, every scheduled event that much later (suite.run_case)

    @property
    def key(self) -> str:
        """Unique, readable task key."""
        return f'case-{self.scenario}-seed{self.seed}-{abs(hash(self)) % 10**8:08d}'

    def __hash__(self) -> int:
        """Hash of the printable fields (dicts are not hashable)."""
        return hash((self.scenario, self.seed, self.duration,
                     tuple(sorted(self.params_overrides.items())), self.recording_loop,
                     self.estimators, self.loop_estimators, self.schedule_shift))


def run_case_task(spec: CaseSpec) -> CaseResult:
    """One case, deterministic wherever it runs (torch and BLAS on one thread)."""
    import torch

    torch.set_num_threads(1)
    kwargs: dict[str, Any] = {'duration': spec.duration,
                              'params_overrides': dict(spec.params_overrides) or None,
                              'loop_estimators': spec.loop_estimators,
                              'recording_loop': spec.recording_loop}
    if spec.schedule_shift:
        kwargs['schedule_shift'] = spec.schedule_shift
    if spec.estimators is not None:
        kwargs['estimators'] = spec.estimators
    with threadpool_limits(limits=1):  # numpy/scipy BLAS, which the environment may thread
        return run_case(spec.scenario, spec.seed, **kwargs)


class ProgressBar:
    """``[#####-----] 12/40 cases  3m05s elapsed, ~7m left  last: supply seed 14 (41 s)``."""

    def __init__(self, total: int, stream: TextIO | None = None, width: int = 30) -> None:
        """A bar for ``total`` cases written to ``stream`` (stderr by default)."""
        self.total = total
        self.done = 0
        self.stream = stream or sys.stderr
        self.width = width
        self.start = time.monotonic()

    def update(self, label: str) -> str:
        """Count one finished case; write and return the line."""
        self.done += 1
        elapsed = time.monotonic() - self.start
        filled = int(round(self.width * self.done / max(self.total, 1)))
        left = elapsed / self.done * (self.total - self.done)
        line = (f'[{"#" * filled}{"-" * (self.width - filled)}] {self.done}/{self.total} cases'
                f'  {_clock(elapsed)} elapsed, ~{_clock(left)} left  last: {label}')
        print(line, file=self.stream, flush=True)
        return line


def _simulated_seconds(spec: CaseSpec) -> float:
    if spec.duration is not None:
        return spec.duration
    from sim_ros.simulation import load_scenario

    return load_scenario(spec.scenario).duration


def _clock(seconds: float) -> str:
    minutes, sec = divmod(int(round(seconds)), 60)
    return f'{minutes}m{sec:02d}s'


def _label(spec: CaseSpec, seconds: float | None = None) -> str:
    tail = '' if seconds is None else f' ({seconds:.0f} s)'
    return f'{spec.scenario} seed {spec.seed}{tail}'


def run_cases(specs: Sequence[CaseSpec], scheduler: str | None = None,
              workers: int | None = None, progress: bool = True,
              task: Callable[[CaseSpec], CaseResult] = run_case_task) -> list[CaseResult]:
    """Run every spec (module docstring); results in the order of ``specs``."""
    bar = ProgressBar(len(specs)) if progress else None
    if scheduler == IN_PROCESS:
        done = []
        for spec in specs:
            begin = time.monotonic()
            done.append(task(spec))
            if bar is not None:
                bar.update(_label(spec, time.monotonic() - begin))
        return done
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        # one BLAS thread per worker process: one worker per core already fills the machine,
        # and threaded BLAS on a loaded core made small-matrix filters ~10× slower
        for name in BLAS_THREAD_VARIABLES:
            os.environ.setdefault(name, '1')
        count = workers or os.cpu_count() or 1
        cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                               dashboard_address=None, silence_logs=40)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        # the longest cases first (submitted first, higher priority), so that no long case
        # starts last and runs alone at the end
        seconds = [_simulated_seconds(spec) for spec in specs]
        order = sorted(range(len(specs)), key=lambda i: -seconds[i])
        futures = [client.submit(task, specs[i], key=specs[i].key, pure=False,
                                 priority=int(seconds[i])) for i in order]
        by_key = {f.key: (i, specs[i]) for i, f in zip(order, futures, strict=True)}
        results: list[CaseResult | None] = [None] * len(specs)
        for future in as_completed(futures):
            index, spec = by_key[future.key]
            results[index] = future.result()  # re-raises a failed case here, with its traceback
            if bar is not None:
                bar.update(_label(spec))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return [r for r in results if r is not None]


__all__ = ['IN_PROCESS', 'CaseSpec', 'ProgressBar', 'run_case_task', 'run_cases']
