"""One thread for the math libraries (core/math_threads.py), in a fresh process each."""
from __future__ import annotations

import subprocess
import sys

import pytest

from lf_predictor_ros.core.fit_process import FitProcess
from lf_predictor_ros.core.math_threads import BLAS_THREAD_VARIABLES, math_threads


def run_fresh(code: str, monkeypatch: pytest.MonkeyPatch) -> str:
    """``code`` in a new interpreter whose environment does not limit any thread pool."""
    for name in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=120, check=True)
    return done.stdout.strip()


def test_every_pool_gets_one_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    code = ('import numpy, scipy.linalg, torch\n'
            'from lf_predictor_ros.core.math_threads import math_threads, use_one_math_thread\n'
            'torch.set_num_threads(2)\n'  # as on a 2-core machine, whatever this one has
            'before = math_threads()\n'
            'use_one_math_thread()\n'
            'print(before[1], *math_threads())\n')
    assert run_fresh(code, monkeypatch).split() == ['2', '1', '1']


def test_a_process_without_torch_does_not_load_it(monkeypatch: pytest.MonkeyPatch) -> None:
    code = ('import sys, numpy\n'
            'from lf_predictor_ros.core.math_threads import math_threads, use_one_math_thread\n'
            'use_one_math_thread()\n'
            "print(*math_threads(), 'torch' in sys.modules)\n")
    assert run_fresh(code, monkeypatch).split() == ['1', '0', 'False']


def test_the_child_computes_on_one_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in BLAS_THREAD_VARIABLES:  # the child inherits the environment when it starts
        monkeypatch.delenv(name, raising=False)
    fit = FitProcess()
    try:
        assert fit.run(math_threads) == (1, 1)
        assert fit.starts == 1 and fit.failures == 0  # answered by the child, not here
    finally:
        fit.close()
