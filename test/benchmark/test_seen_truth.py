"""The LF truth a filter of the measurement can see (`benchmark.seen_truth`)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lf_predictor_ros.benchmark.recordings import Provenance, Recording
from lf_predictor_ros.benchmark.seen_truth import (
    SLOW_WAVE_FRACTION,
    recording_seen_truth,
    seen_lf_truth,
    slow_wave_motion,
)

H = 1.0  # s
OMEGA = 0.8  # rad/s, ω0


def _grid(samples: int = 4000) -> np.ndarray:
    return np.arange(samples) * H


def test_slow_wave_motion_keeps_the_slow_part_and_removes_the_wave_band() -> None:
    t = _grid()
    slow = 0.1 * np.sin(0.2 * SLOW_WAVE_FRACTION * OMEGA * t)  # far below the cutoff
    wave = 0.5 * np.sin(OMEGA * t + 0.3)  # at ω0
    motion = np.column_stack([slow + wave, wave, np.zeros_like(t)])
    out = slow_wave_motion(motion, H, OMEGA)
    inner = slice(300, -300)  # away from the record's ends
    # 4th-order Butterworth, forward and backward: gain (1 + (ω/ωc)^8)^-1 = 1 - 2.6e-6 at 0.2 ωc
    # for the slow part, (1 + 4^8)^-1 = 1.5e-5 at ω0 = 4 ωc for the wave band
    assert np.max(np.abs(out[inner, 0] - slow[inner])) < 1e-3
    assert np.max(np.abs(out[inner, 1])) < 1e-3
    assert np.all(out[:, 2] == 0.0)


def test_seen_truth_is_the_twin_plus_the_slow_wave_motion_with_the_heading_wrapped() -> None:
    t = _grid()
    truth = np.column_stack([0.01 * t, np.zeros_like(t), np.full_like(t, np.pi - 0.01)])
    motion = np.column_stack([np.full_like(t, 0.2), np.zeros_like(t), np.full_like(t, 0.02)])
    before_truth, before_motion = truth.copy(), motion.copy()
    seen = seen_lf_truth(truth, motion, H, OMEGA)
    assert np.allclose(seen[:, 0], truth[:, 0] + 0.2, atol=1e-9)
    assert np.allclose(seen[:, 2], -np.pi + 0.01, atol=1e-9)  # π + 0.01 wrapped
    assert np.array_equal(truth, before_truth) and np.array_equal(motion, before_motion)


@pytest.mark.parametrize(('motion', 'sample_time', 'omega', 'match'), [
    (np.full((100, 3), np.nan), H, OMEGA, 'finite'),
    (np.zeros(100), H, OMEGA, 'finite'),
    (np.zeros((100, 3)), 0.0, OMEGA, 'positive'),
    (np.zeros((100, 3)), H, 20.0, 'Nyquist'),
    (np.zeros((10, 3)), H, OMEGA, 'too few'),
])
def test_bad_input_is_refused_with_a_reason(motion: np.ndarray, sample_time: float,
                                            omega: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        slow_wave_motion(motion, sample_time, omega)


def test_the_record_ends_do_not_turn_the_last_wave_into_a_slow_step() -> None:
    """A wave ending at its crest: odd-extension padding would make a 0.40 m step of it."""
    t = _grid(1000)
    wave = 0.5 * np.cos(OMEGA * (t - t[-1]))
    out = slow_wave_motion(np.column_stack([wave, wave, wave]), H, OMEGA)
    assert np.max(np.abs(out)) < 0.1  # Gustafsson's initial conditions: 0.046 m


def test_a_recordings_seen_truth_uses_its_lowest_peak_frequency() -> None:
    """`recording_seen_truth`: the recording's twin and wave motion at its lowest true ω0."""
    t = _grid()
    motion = np.column_stack([0.05 + 0.5 * np.sin(OMEGA * t), np.zeros((t.size, 2))])
    truth = np.column_stack([0.01 * t, np.zeros(t.size), np.full(t.size, 0.2)])
    omega = np.where(t < 2000.0, OMEGA, 2.0 * OMEGA)
    provenance = Provenance('x', 1, float(t[-1]), H, 'open')
    rec = Recording(provenance, t, truth, np.zeros_like(truth), truth, omega, wave=motion)
    np.testing.assert_array_equal(recording_seen_truth(rec, H),
                                  seen_lf_truth(truth, motion, H, OMEGA))
    assert recording_seen_truth(replace(rec, wave=None), H) is None
