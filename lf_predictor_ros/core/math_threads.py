"""One thread for the math libraries of the node and its child process (issue 13, cost target).

numpy and scipy's BLAS / OpenMP pools and torch's intra-op pool start one thread per core by
default. The node, its child process (`core.fit_process`) and usually the rest of a DP stack share
few cores: a job in the child that spreads over both cores of a 2-core machine takes the core
the node's pose callbacks run on. Measured with the latency bench without
``OMP_NUM_THREADS=1`` in the environment, as a plain ``ros2 run`` starts the node: the p99 while
training 0.97 and 1.09 ms against 0.79 and 0.78 ms with it, three times the pose-only callbacks
over 1 ms, and 10–20 % more CPU per simulated hour (docs/BENCHMARKS.md, sixty-eighth session).
The benchmark runs every case on one thread too (`benchmark.distributed`), so the node computes
with the same summation order as the numbers it is judged by.

`use_one_math_thread` limits the pools of the libraries loaded when it is called (threadpoolctl
sees only those): call it after the imports, as the node executables (`nodes.runner`) and the
child (`fit_process`) do.
"""
from __future__ import annotations

import sys

from threadpoolctl import threadpool_info, threadpool_limits

# environment variables that size the BLAS / OpenMP pools when a library loads
BLAS_THREAD_VARIABLES = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')


def use_one_math_thread() -> None:
    """Put the BLAS / OpenMP pools (numpy, scipy) and torch's intra-op pool on one thread.

    For good (until the process ends). torch only if this process has imported it (a node
    without torch does not load it here).
    """
    threadpool_limits(limits=1)
    torch = sys.modules.get('torch')
    if torch is not None:
        torch.set_num_threads(1)


def math_threads() -> tuple[int, int]:
    """(most threads of a loaded BLAS / OpenMP pool, torch's intra-op threads; 0: no torch)."""
    pools = [int(pool['num_threads']) for pool in threadpool_info()]
    torch = sys.modules.get('torch')
    return max(pools, default=1), int(torch.get_num_threads()) if torch is not None else 0
