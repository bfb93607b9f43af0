"""The background jobs in a child process (core/fit_process.py): the ω0 fit and any job."""
from __future__ import annotations

import math
import operator
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time
import types

import numpy as np
import pytest
import torch

from lf_predictor_ros.core import fit_process, frequency
from lf_predictor_ros.core.fit_process import PARENT_CHECK_PERIOD, FitProcess, shared_fit_process
from lf_predictor_ros.core.frequency import FrequencyEstimate, spectrum_estimate, spectrum_fit_by
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import plan_fallback_at

WAVE_BAND = (0.25, 1.4)  # rad/s
HIGHPASS_CUTOFF = 0.2  # rad/s
MIN_PEAK_RATIO = 5.0


def measured(seed: int, wave_std: float) -> np.ndarray:
    """20 min at 1 s: a random walk, waves of std ``wave_std`` [m] and sensor noise (0.05 m).

    The waves: 120 random-phase sinusoids, frequencies drawn about 0.6 rad/s.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(1200.0)
    freqs = rng.normal(0.6, 0.03, 120)
    waves = np.sin(np.outer(t, freqs) + rng.uniform(0.0, 2.0 * math.pi, 120)).sum(axis=1)
    walk = np.cumsum(rng.standard_normal(t.size)) * 0.05
    return walk + wave_std * waves / waves.std() + 0.05 * rng.standard_normal(t.size)


def arguments(seed: int, previous: float | FrequencyEstimate | None = None) -> tuple[
        np.ndarray, float, float, tuple[float, float], float, float | FrequencyEstimate | None]:
    """`spectrum_estimate`'s arguments for a seeded two-DOF record (20 min at 1 s)."""
    data = np.column_stack([measured(seed, 0.7), measured(seed + 100, 0.3)])
    return data, 1.0, HIGHPASS_CUTOFF, WAVE_BAND, MIN_PEAK_RATIO, previous


@pytest.fixture
def fit() -> FitProcess:
    process = FitProcess()
    yield process
    process.close()


def test_the_child_computes_the_same_numbers_as_this_thread(fit: FitProcess) -> None:
    assert not fit.running
    for seed, previous in ((1, None), (2, 0.5), (3, FrequencyEstimate(0.7, True, 9.0, (0.7,)))):
        args = arguments(seed, previous)
        here = spectrum_estimate(*args)
        there = fit(*args)
        assert there == here  # every field, to the last bit (NaN-free here)
        assert 0.55 < there.wave_peak_freq < 0.65 and there.confident
    assert fit.running and fit.starts == 1 and fit.failures == 0


def test_an_estimate_error_reaches_the_caller_as_it_is(fit: FitProcess) -> None:
    data, *rest = arguments(4)
    with pytest.raises(ValueError, match='padlen') as here:
        spectrum_estimate(data[:3], *rest)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match='padlen') as there:  # scipy's, raised in the child
        fit(data[:3], *rest)  # type: ignore[arg-type]
    assert str(there.value) == str(here.value)
    assert fit.failures == 0 and fit.running


def test_a_killed_child_is_replaced_and_the_call_answered_here(fit: FitProcess) -> None:
    args = arguments(5)
    expected = spectrum_estimate(*args)
    assert fit(*args) == expected
    executor = fit._executor
    assert executor is not None
    for process in list(executor._processes.values()):  # type: ignore[union-attr]
        process.kill()
        process.join(timeout=10.0)
    assert fit(*args) == expected  # the pool is broken: computed on this thread
    assert fit.failures == 1 and not fit.running
    assert fit(*args) == expected  # a new child
    assert fit.starts == 2 and fit.failures == 1


def test_any_job_runs_in_the_child_and_its_errors_come_back_as_they_are(fit: FitProcess) -> None:
    # module-level functions only: the child imports them (this test module it could not)
    assert fit.run(math.fsum, [0.1] * 10) == math.fsum([0.1] * 10)
    assert fit.run(os.getpid) != os.getpid()  # computed elsewhere
    with pytest.raises(ZeroDivisionError):
        fit.run(operator.truediv, 1.0, 0.0)
    stop = threading.Event()
    with pytest.raises(TimeoutError, match='the job'):  # not taken for a wait's timeout
        fit.run(exec, "raise TimeoutError('the job')", stop=stop)
    assert fit.starts == 1 and fit.failures == 0


def test_the_fallback_planned_in_the_child_is_this_thread_s_to_the_bit(fit: FitProcess) -> None:
    """The predictor's job plans its cascade fallback in the child (`retrain_and_plan`)."""
    params = PredictorParams()
    here = plan_fallback_at(params, 0.6283)
    there = fit.run(plan_fallback_at, params, 0.6283)
    assert fit.starts == 1 and fit.failures == 0  # computed in the child
    assert (there.wave_peak_freq, there.sample_time, there.design) == \
        (here.wave_peak_freq, here.sample_time, here.design)
    for mine, theirs in ((here.retune.sos, there.retune.sos),
                         (here.retune.observability, there.retune.observability),
                         (here.retune.state_space.a, there.retune.state_space.a),
                         (here.retune.state_space.b, there.retune.state_space.b),
                         (here.retune.state_space.c, there.retune.state_space.c),
                         *zip(here.retune.markov, there.retune.markov, strict=True)):
        np.testing.assert_array_equal(theirs, mine)
    assert there.retune.state_space.d == here.retune.state_space.d


def test_a_job_the_child_cannot_load_is_computed_here_and_the_child_stays(
        fit: FitProcess, monkeypatch: pytest.MonkeyPatch) -> None:
    module = types.ModuleType('lf_parent_only_jobs')  # importable in this process only
    exec('def plus_one(value):\n    return value + 1\n', module.__dict__)  # noqa: S102
    monkeypatch.setitem(sys.modules, module.__name__, module)
    assert fit.run(module.plus_one, 1) == 2
    assert fit.failures == 1 and fit.starts == 1 and fit.running
    assert fit.run(os.getpid) != os.getpid()  # the same child answers the next job
    assert fit.starts == 1 and fit.failures == 1


def test_tensors_cross_as_arrays_not_through_shared_memory(fit: FitProcess) -> None:
    # multiprocessing's own pickler moves each tensor into a shared-memory file whose
    # descriptor a helper thread hands over (a state_dict's round trip 20–46 ms of GIL turns)
    generator = torch.Generator().manual_seed(1)
    state = {'weight': torch.randn(3, 108, dtype=torch.float64, generator=generator),
             'count': torch.arange(4), 'flag': torch.tensor([True, False]),
             'turned': torch.arange(6.0).reshape(2, 3).t()}  # not contiguous
    back = fit.run(dict, state)
    assert back.keys() == state.keys()
    for key, value in state.items():
        assert back[key].dtype == value.dtype and torch.equal(back[key], value)  # every bit
        assert not back[key].is_shared()
    assert fit.run(torch.Tensor.is_shared, state['weight']) is False  # as the child got it
    assert fit.starts == 1 and fit.failures == 0


def test_tensors_numpy_cannot_hold_are_pickled_as_usual() -> None:
    tensors = {'half': torch.tensor([1.5, -2.25], dtype=torch.bfloat16),
               'grad': torch.ones(3, dtype=torch.float64, requires_grad=True)}
    back = fit_process._unpacked(fit_process._packed(tensors))
    assert back['half'].dtype == torch.bfloat16 and torch.equal(back['half'], tensors['half'])
    assert back['grad'].requires_grad and torch.equal(back['grad'], tensors['grad'])


def test_a_set_stop_abandons_the_job_and_ends_its_child(fit: FitProcess) -> None:
    stop = threading.Event()
    threading.Timer(0.2, stop.set).start()
    start = time.monotonic()
    with pytest.raises(fit_process.JobAbandonedError):
        fit.run(time.sleep, 30.0, stop=stop)
    assert time.monotonic() - start < 0.2 + 10 * fit_process.STOP_CHECK_PERIOD + 5.0
    assert not fit.running  # the child sleeping on would hold up every job after it
    start = time.monotonic()
    assert fit.run(math.fsum, [1.0, 2.0]) == 3.0  # a new child, at once
    assert time.monotonic() - start < 10.0
    assert fit.starts == 2 and fit.failures == 0


def test_a_job_queued_behind_an_abandoned_one_is_asked_of_the_new_child(fit: FitProcess) -> None:
    stop = threading.Event()
    answers: list[object] = []
    raised: list[object] = []
    abandoned = threading.Thread(target=lambda: raised.append(pytest.raises(
        fit_process.JobAbandonedError, fit.run, time.sleep, 30.0, stop=stop)))
    abandoned.start()
    time.sleep(0.5)  # the sleep is running in the child
    queued = threading.Thread(target=lambda: answers.append(fit.run(os.getpid)))
    queued.start()
    time.sleep(0.3)  # queued behind it
    stop.set()
    abandoned.join(10.0)
    queued.join(10.0)
    assert not abandoned.is_alive() and not queued.is_alive()
    assert len(raised) == 1 and len(answers) == 1
    assert isinstance(answers[0], int) and answers[0] != os.getpid()  # computed in a child
    assert fit.starts == 2 and fit.failures == 0  # not counted as computed here


def test_without_a_child_the_fallback_is_computed_here(
        fit: FitProcess, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_process() -> None:  # multiprocessing's refusal inside a daemonic process
        raise AssertionError('daemonic processes are not allowed to have children')

    monkeypatch.setattr(fit_process, '_context', no_process)
    assert fit.run(math.fsum, [1.0, 2.0], fallback=lambda: 42.0) == 42.0
    assert fit.run(math.fsum, [1.0, 2.0]) == 3.0  # no fallback: the job itself, here
    assert fit.failures == 2 and fit.starts == 0


def test_the_setting_is_per_thread_and_restored() -> None:
    calls: list[str] = []

    def counting(*args: object) -> FrequencyEstimate:
        calls.append(threading.current_thread().name)
        return FrequencyEstimate(0.61, True, 20.0, (0.61,))

    data = arguments(6)[0]
    other: list[FrequencyEstimate] = []
    with spectrum_fit_by(counting):
        first = frequency.estimate_wave_peak_freq(data, 1.0, highpass_cutoff=HIGHPASS_CUTOFF,
                                                  wave_band=WAVE_BAND,
                                                  min_peak_ratio=MIN_PEAK_RATIO, previous=0.42)
        thread = threading.Thread(target=lambda: other.append(frequency.estimate_wave_peak_freq(
            data, 1.0, highpass_cutoff=HIGHPASS_CUTOFF, wave_band=WAVE_BAND,
            min_peak_ratio=MIN_PEAK_RATIO, previous=0.43)))
        thread.start()
        thread.join()
    after = frequency.estimate_wave_peak_freq(data, 1.0, highpass_cutoff=HIGHPASS_CUTOFF,
                                              wave_band=WAVE_BAND, min_peak_ratio=MIN_PEAK_RATIO,
                                              previous=0.44)
    assert first.wave_peak_freq == 0.61 and len(calls) == 1  # only this thread's call
    assert other[0] == after == spectrum_estimate(data, 1.0, HIGHPASS_CUTOFF, WAVE_BAND,
                                                  MIN_PEAK_RATIO, 0.44)
    assert math.isclose(after.wave_peak_freq, 0.6, rel_tol=0.08)


def test_one_shared_process_for_the_background_predictors() -> None:
    from lf_predictor_ros.core.params import PredictorParams
    from lf_predictor_ros.core.predictor import AdaptivePredictor

    background = AdaptivePredictor(PredictorParams(), background=True)
    inline = AdaptivePredictor(PredictorParams(), background=False)
    try:
        assert background._fit_process is shared_fit_process()
        assert background._moving is not None
        assert background._moving._fit_process is shared_fit_process()
        assert inline._fit_process is None
    finally:
        background.close()
        inline.close()


def test_ctrl_c_is_left_to_the_parent(fit: FitProcess) -> None:
    """A terminal's Ctrl-C reaches the child too: it ignores it (no traceback, still serving)."""
    args = arguments(7)
    expected = fit(*args)
    executor = fit._executor
    assert executor is not None
    for process in list(executor._processes.values()):  # type: ignore[union-attr]
        assert process.pid is not None
        os.kill(process.pid, signal.SIGINT)
    time.sleep(0.5)
    assert fit(*args) == expected
    assert fit.failures == 0 and fit.starts == 1


def test_started_ahead_and_no_child_means_the_same_numbers_here(
        fit: FitProcess, monkeypatch: pytest.MonkeyPatch) -> None:
    assert fit.start() and fit.running and fit.starts == 1
    args = arguments(8)
    assert fit(*args) == spectrum_estimate(*args)
    assert fit.starts == 1 and fit.failures == 0
    fit.close()

    def no_process() -> None:  # multiprocessing's refusal inside a daemonic process
        raise AssertionError('daemonic processes are not allowed to have children')

    monkeypatch.setattr(fit_process, '_context', no_process)
    assert not fit.start() and not fit.running and fit.failures == 0  # no fit yet
    assert fit(*args) == spectrum_estimate(*args)  # computed on this thread
    assert fit.failures == 1 and fit.starts == 1  # one fit here; no child started


def test_closed_then_called_starts_a_new_child(fit: FitProcess) -> None:
    args = arguments(9)
    expected = fit(*args)
    fit.close()
    assert not fit.running
    assert fit(*args) == expected
    assert fit.starts == 2 and fit.failures == 0


def _alive(pid: int) -> bool:
    """The process exists and is no zombie (Linux /proc)."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text()
    except FileNotFoundError:
        return False
    return stat[stat.rindex(')') + 2] not in 'ZX'


@pytest.mark.skipif(not Path('/proc/self/stat').exists(), reason='reads Linux /proc')
def test_the_child_and_its_forkserver_end_when_the_node_is_killed() -> None:
    """SIGKILL leaves no shutdown to the node: the child notices and ends, the server with it."""
    code = ('import time\n'
            'from lf_predictor_ros.core.fit_process import FitProcess\n'
            'fit = FitProcess()\n'
            'assert fit.start()\n'
            'print(*[p.pid for p in fit._executor._processes.values()], flush=True)\n'
            'time.sleep(120)\n')
    node = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE)
    try:
        assert node.stdout is not None
        child = int(node.stdout.readline())
        stat = Path(f'/proc/{child}/stat').read_text()
        server = int(stat[stat.rindex(')') + 2:].split()[1])  # the child's parent
        assert _alive(child) and _alive(server) and server != node.pid
    finally:
        node.kill()
        node.wait()
    deadline = time.monotonic() + 10.0 * PARENT_CHECK_PERIOD
    while (_alive(child) or _alive(server)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(child) and not _alive(server)
