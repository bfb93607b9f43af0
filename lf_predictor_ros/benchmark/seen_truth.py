"""The LF truth a filter of the measurement can see, next to the simulator's twin truth.

Under force superposition (`sim_ros.physics.vessels`, ``wave_rates_fn``; the thesis vessels'
scenarios, ``waves.model: force``) the true LF pose is the *twin*'s: the vessel driven by
everything but the first-order wave force. The wave-frequency state η_w is the vessel's
response to that force, and it has no restoring force, so any slow part of η_w is in the
measured pose and not in the twin: every filter of the measurement — notch + low-pass, the
learned filter, a zero-phase smoother — passes it as LF motion and is scored as if it had erred;
only the oracle, which knows the model, the thrust and the initial state, can split it off.
Until the eighteenth session the simulator made such a part: its WF damping followed the LF
velocity (the mean of η_w shifted whenever the vessel passed u0 = 0.1 m/s: 0.06–0.19 m RMS on
onedof_feedback) and the RK4 stages' interpolated wave force missed each step's impulse by
O(h³) (a random walk of the mean: 0.025 m RMS at h = 0.05 s). Both are fixed; what is left is
the shaping filter's own tail below the wave band, ≈ 0.005 m RMS (`docs/BENCHMARKS.md`,
"Seventeenth session" and "Eighteenth session").

``seen_lf_truth`` = twin + the part of η_w below ``SLOW_WAVE_FRACTION`` · ω0 (zero-phase
Butterworth of order ``SLOW_WAVE_ORDER``, forward and backward: the truth may look ahead). The
record's ends use Gustafsson's initial conditions (`core.filters.zero_phase`, as the targets):
odd-extension padding reflects the last instantaneous wave value into a step (measured on
supply_closed_loop seed 1, 1800 s against the same filter on a 2400 s record: up to 1.3 m error in
the last 200 s with odd padding, ≤ 0.05 m with Gustafsson's). Under
motion superposition the shaping filter 2λω0σ s / (…) leaves an ω² tail there, and a 1 s grid
aliases some of the wave band down (0.02-0.03 m RMS on the supply vessel and on omega_steps at
1.25 rad/s); the RAO seas, JONSWAP components from 0.5 ω_p up, leave nothing (≤ 0.002 m). This
is a reported second truth, not a replacement: the benchmark's verdicts stay on the twin.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from lf_predictor_ros.benchmark.recordings import Recording
from lf_predictor_ros.core.filters import zero_phase
from lf_predictor_ros.core.heading import wrap_angle

FloatArray = NDArray[np.float64]
SLOW_WAVE_FRACTION = 0.25  # × the lowest ω0: the force spectrum's wave band starts near 0.5 ω0
SLOW_WAVE_ORDER = 4
MIN_SAMPLES = 30


def slow_wave_motion(wave_motion: FloatArray, sample_time: float,
                     wave_peak_freq: float) -> FloatArray:
    """The part of η_w (m, k) below SLOW_WAVE_FRACTION · ω0 [rad/s], zero-phase, per column.

    ``wave_motion``: η_w = total true pose − twin pose on a uniform grid of ``sample_time`` s,
    heading column already wrapped. Raises ValueError for a record too short to filter or a cutoff
    at or above the Nyquist frequency.
    """
    motion = np.asarray(wave_motion, dtype=np.float64)
    if motion.ndim != 2 or not np.all(np.isfinite(motion)):
        raise ValueError('wave_motion must be a finite (samples, dof) array')
    if not (sample_time > 0.0 and wave_peak_freq > 0.0):
        raise ValueError(f'sample_time {sample_time} s and wave_peak_freq {wave_peak_freq} rad/s '
                         'must be positive')
    cutoff = SLOW_WAVE_FRACTION * wave_peak_freq / (np.pi / sample_time)
    if cutoff >= 1.0:
        raise ValueError(f'the slow-wave cutoff {SLOW_WAVE_FRACTION} × ω0 is above the Nyquist '
                         f'frequency of h = {sample_time} s: use a finer grid')
    if motion.shape[0] < MIN_SAMPLES:
        raise ValueError(f'{motion.shape[0]} samples are too few to filter the wave motion '
                         f'(at least {MIN_SAMPLES})')
    return zero_phase(motion, signal.butter(SLOW_WAVE_ORDER, cutoff, output='sos'))


def seen_lf_truth(truth: FloatArray, wave_motion: FloatArray, sample_time: float,
                  wave_peak_freq: float) -> FloatArray:
    """Twin truth (m, 3) + the slow part of η_w (m, 3); heading wrapped. Inputs unchanged."""
    out = np.array(truth, dtype=np.float64, copy=True)
    out += slow_wave_motion(wave_motion, sample_time, wave_peak_freq)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def recording_seen_truth(recording: Recording, sample_time: float) -> FloatArray | None:
    """`seen_lf_truth` of a recording on its grid of ``sample_time`` s, at its lowest true ω0.

    None when the recording does not carry its wave motion (``Recording.wave``).
    """
    if recording.wave is None:
        return None
    return seen_lf_truth(recording.truth, recording.wave, sample_time,
                         float(np.min(recording.omega)))
