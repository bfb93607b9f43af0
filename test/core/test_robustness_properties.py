"""Property tests (issue 7): arbitrary, hostile input streams never crash the input chain.

The chain a node runs — `InputAligner` → `AdaptivePredictor` — is fed sequences that mix valid
samples with NaN/Inf, wrong shapes, absurd positions, duplicate and out-of-order stamps, gaps
from one sample to minutes, time jumping backwards and heading crossing ±π. Properties:
nothing raises; every output is finite with yaw in (−π, π]; the counters account for what was
dropped.
"""
from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
import numpy as np

from lf_predictor_ros.core.alignment import AlignerSettings, InputAligner
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.predictor import AdaptivePredictor

# Small windows so trainings happen within a few hundred samples (fast, inline, deterministic).
SMALL = PredictorParams(ndof=3, sample_time=1.0, retrain_period=20.0, training_window=200.0,
                        transient_length=10.0, filter_window=60.0, append_length=40.0,
                        estimation_window=480.0, max_epochs=3, nu=2, ny=4)

_BAD = [math.nan, math.inf, -math.inf, 1e12]
value = st.one_of(st.floats(-50.0, 50.0), st.sampled_from(_BAD))
step = st.one_of(st.floats(0.05, 2.0), st.floats(-0.5, 0.0),  # normal, duplicate/out of order
                 st.floats(5.0, 400.0), st.floats(-600.0, -10.0))  # gaps, backward jumps
event = st.tuples(step, value, value, st.floats(-10.0, 10.0), st.booleans(),
                  st.sampled_from(['ok', 'ok', 'ok', 'short', 'nan_force']))


def _chain() -> tuple[InputAligner, AdaptivePredictor]:
    return (InputAligner(AlignerSettings(sample_time=1.0, max_gap=5.0)),
            AdaptivePredictor(SMALL, background=False))


def _run(events: list[tuple[float, float, float, float, bool, str]],
         ) -> tuple[list[np.ndarray], InputAligner, AdaptivePredictor]:
    aligner, predictor = _chain()
    outputs, t, first = [], 1000.0, True
    for dt, north, east, yaw, with_force, kind in events:
        t += dt
        pose: object = [north, east, yaw]
        if kind == 'short':
            pose = [north, east]
        force = [math.nan, 0.0, 0.0] if kind == 'nan_force' else [1e4 * north, 0.0, 1e5]
        if with_force:
            aligner.add_force(t, force)
        for sample in aligner.add_pose(t, pose):
            if sample.segment_start and not first:
                predictor.restart_segment()
            first = False
            outputs.append(predictor.update(sample.t, sample.pose, sample.force))
    return outputs, aligner, predictor


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(event, min_size=1, max_size=120))
def test_hostile_streams_never_raise_and_outputs_stay_finite(events: list) -> None:
    for out in _run(events)[0]:
        assert out.shape == (3,) and np.all(np.isfinite(out))
        assert -math.pi < out[2] <= math.pi


@settings(max_examples=5, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**31 - 1))
def test_long_noisy_stream_with_faults_trains_and_stays_finite(seed: int) -> None:
    """300+ samples of LF + waves with 5 % faults: trainings run, outputs stay finite."""
    rng = np.random.default_rng(seed)
    n = 360
    t = np.arange(n, dtype=float)
    north = np.cumsum(rng.normal(0, 0.05, n)) + 0.5 * np.sin(0.8 * t)
    yaw = np.angle(np.exp(1j * (3.1 + 0.02 * t + 0.05 * np.sin(0.8 * t))))  # crosses ±π
    events = []
    for k in range(n):
        fault = {50: 0.01, 100: 0.045, 150: 0.03}.get(k, rng.random())  # one of each for sure
        n_val = math.nan if fault < 0.02 else (1e12 if fault < 0.04 else north[k])
        dt = -0.3 if 0.04 <= fault < 0.05 else 1.0
        events.append((dt, n_val, 0.3 * north[k], float(yaw[k]), True, 'ok'))
    outputs, aligner, predictor = _run(events)
    assert len(outputs) > 0.8 * n
    counters = aligner.counters
    assert counters.invalid + counters.outliers >= 1 and counters.out_of_order >= 1
    status = predictor.status()
    assert status.trainings + status.rejected_trainings >= 3
    assert all(np.all(np.isfinite(o)) and -math.pi < o[2] <= math.pi for o in outputs)
