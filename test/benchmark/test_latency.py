"""The latency benchmark's CPU account and collection timer (benchmark/latency.py)."""
from __future__ import annotations

import gc
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

import pytest

from lf_predictor_ros.benchmark.latency import CollectionTimer, _descendants_cpu_seconds

BURN = 0.6  # [s] CPU time the grandchild spends


@pytest.mark.skipif(not Path('/proc/self/stat').exists(), reason='reads Linux /proc')
def test_the_cpu_of_a_live_grandchild_is_counted() -> None:
    # a child that starts a grandchild burning BURN s of CPU, then both sleep (alive)
    code = ('import subprocess, sys; subprocess.run([sys.executable, "-c", "import time\\n'
            f'end = time.process_time() + {BURN}\\nwhile time.process_time() < end: pass\\n'
            'print(1, flush=True)\\ntime.sleep(30)"])')
    before = _descendants_cpu_seconds()
    child = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE,
                             start_new_session=True)  # its own group: both killed at the end
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == b'1'  # the grandchild has burnt its share
        time.sleep(0.1)
        spent = _descendants_cpu_seconds() - before
        # the burn, plus the two interpreters' start-up (≈ 0.05 s each here), less one tick
        assert BURN - 0.02 <= spent <= BURN + 1.0
    finally:
        os.killpg(child.pid, signal.SIGKILL)
        child.wait()


def test_the_collection_timer_counts_full_collections_while_it_records() -> None:
    timer = CollectionTimer()
    gc.collect()  # before start: not counted
    timer.start()
    try:
        gc.collect()  # a full collection (generation 2)
        gc.collect(0)
    finally:
        timer.stop()
    gc.collect()  # after stop: not counted
    assert timer not in gc.callbacks
    assert timer.generations.count(2) == 1 and 0 in timer.generations
    assert len(timer.seconds) == len(timer.generations) >= 2
    summary = timer.summary()
    assert summary['gc_full'] == 1.0
    assert summary['gc_max_ms'] == pytest.approx(max(timer.seconds) * 1e3)
    assert CollectionTimer().summary() == {'gc_full': 0.0, 'gc_max_ms': 0.0}
