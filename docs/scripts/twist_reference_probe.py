"""The twist error against the calibration reference velocity, low-passed or not, and the truth.

    OMP_NUM_THREADS=1 python docs/scripts/twist_reference_probe.py rao_supply:231 \
        supply_closed_loop:231 threedof_open_loop:231 onedof_feedback:231

Tuning and lf_odom calibration seeds only (1, 2, 231–236; issue 14, thirty-fourth session). Per
SCENARIO:SEED, `LfStateEstimator` with the shipped defaults runs inline on the fair recording
(`twin_gain_calibration.windows`: 1500 s, the benchmark's schedule spread) and every calibration
window is kept. For the last three windows, every other one, on the published twists of the
window from 481 s on and at least 30 samples from its ends: the RMS twist error against the
reference velocity (the window's reference differentiated, as `error_models.calibrate` does) and
against the true LF velocity, their ratio of mean squares (truth / reference), the reference
velocity's own content above 0.5 ω0 (zero-phase Butterworth high-pass of order 4, ω0 the
recording's median true wave peak frequency) and the ratio against the reference with that
content removed (`truth/lp`). With ``--pose`` the same for the published pose against the
window's targets, low-passed by `error_models.low_passed` (the ninth rule's reference). With
``--shared``, on the last window only: the twist error e (against the truth) and the low-passed
reference's error d (`error_models.reference_velocity`, against the truth), their RMS and
correlation on the calm half of the samples (|a| below its median per DOF, a the twist error
model's regressor), and in the band 0.1 rad/s – 0.5 ω0 (zero-phase Butterworth band-pass of
order 2) the RMS of e, of the true velocity, of the reference and of d, with the correlations
of e and d with minus the true velocity and with each other (tenth rule, thirty-fourth session).
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent))
from method_probe import run_cases  # noqa: E402 - the sibling script
import twin_gain_calibration  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark.odometry_bench import true_twist  # noqa: E402
from lf_predictor_ros.core.error_models import low_passed, reference_velocity  # noqa: E402
from lf_predictor_ros.core.heading import wrap_angle  # noqa: E402
from lf_predictor_ros.core.lf_dynamics import body_velocity  # noqa: E402
from lf_predictor_ros.core.published_columns import Published  # noqa: E402

FloatArray = NDArray[np.float64]
SCORED_FROM = 481.0  # [s] the benchmark's first scored sample at h = 1 s
EDGE = 30  # [samples] left out at each end of a window (the zero-phase filters' ends)
CUTOFF = 0.5  # × ω0
_OMEGA: dict[str, float] = {}  # the recording's median true ω0 per scenario
_fair_case = getattr(twin_gain_calibration, 'fair_case')  # noqa: B009 - its import


def _keeping_omega(scenario: str, seed: int, *args: Any) -> Any:
    out = _fair_case(scenario, seed, *args)
    _OMEGA[scenario] = float(np.median(out[3].data()['omega']))
    return out


def _high_pass(x: FloatArray, h: float, cutoff: float) -> FloatArray:
    b, a = signal.butter(4, cutoff / (np.pi / h), 'high')
    return np.asarray(signal.filtfilt(b, a, x, axis=0), dtype=np.float64)


def _unwrapped(pose: FloatArray, n: int) -> FloatArray:
    out = np.array(pose[:, :n], dtype=np.float64)
    if n == 3:
        out[:, 2] = np.unwrap(out[:, 2])
    return out


@dataclass(frozen=True)
class Examined:
    """One examined window: the published estimates kept and where they sit."""

    n: int
    h: float
    truth: FloatArray  # the run's true LF pose
    times: FloatArray  # the window's target instants
    reference: FloatArray  # the window's reference, heading unwrapped
    rows: list[Published]  # the kept estimates
    index: NDArray[np.int64]  # their rows in the window
    at: NDArray[np.int64]  # their rows in the run
    cutoff: float  # CUTOFF · ω0 [rad/s]


def examined(scenario: str, seed: int) -> Iterator[Examined]:
    """Three of the last six calibration windows of one run, every other one."""
    setattr(twin_gain_calibration, 'fair_case', _keeping_omega)  # noqa: B010 - this run only
    try:
        n, h, t, truth, captured = twin_gain_calibration.windows(scenario, seed)
    finally:
        setattr(twin_gain_calibration, 'fair_case', _fair_case)  # noqa: B010
    for history, times, reference in captured[-6::2]:
        stamps = np.array([p.stamp for p in history])
        index = np.round((stamps - times[0]) / h).astype(np.int64)
        ok = (index >= EDGE) & (index < len(times) - EDGE) & (stamps >= SCORED_FROM)
        if np.any(ok):
            yield Examined(n, h, truth, times, _unwrapped(reference.reshape(len(times), -1), n),
                           [p for p, good in zip(history, ok, strict=True) if good], index[ok],
                           np.round((stamps[ok] - t[0]) / h).astype(np.int64),
                           CUTOFF * _OMEGA[scenario])


def probe(scenario: str, seed: int) -> None:
    """Print one line per examined window."""
    true_v: FloatArray | None = None
    for w in examined(scenario, seed):
        if true_v is None:
            true_v = true_twist(w.truth, w.h, w.n)
        ref_v = body_velocity(w.reference, w.h)
        twist = np.array([p.twist for p in w.rows])
        wave = _high_pass(ref_v, w.h, w.cutoff)[w.index]
        e_ref = twist - ref_v[w.index]
        e_truth = twist - true_v[w.at]
        ref2, truth2 = np.mean(e_ref ** 2, axis=0), np.mean(e_truth ** 2, axis=0)
        low2 = np.mean((e_ref + wave) ** 2, axis=0)
        print(f'{scenario} {seed} window_end {w.times[-1]:.0f} rms vs reference '
              f'{np.sqrt(ref2).round(4)} vs truth {np.sqrt(truth2).round(4)} truth/reference '
              f'{(truth2 / ref2).round(2)} reference above {CUTOFF} w0 '
              f'{np.sqrt(np.mean(wave ** 2, axis=0)).round(4)} reference - truth '
              f'{np.sqrt(np.mean((ref_v[w.index] - true_v[w.at]) ** 2, axis=0)).round(4)} '
              f'truth/lp {(truth2 / low2).round(2)}', flush=True)


def _mean_square(pose: FloatArray, target: FloatArray) -> FloatArray:
    """Mean squared pose error per DOF (heading wrapped)."""
    error = pose - target
    if pose.shape[1] == 3:
        error[:, 2] = wrap_angle(error[:, 2])
    return np.asarray(np.mean(error ** 2, axis=0), dtype=np.float64)


def pose_probe(scenario: str, seed: int) -> None:
    """``--pose``: one line per examined window, the pose against the targets."""
    for w in examined(scenario, seed):
        clean = low_passed(w.reference, w.h, w.cutoff)
        pose = np.array([p.pose for p in w.rows])
        ref2 = _mean_square(pose, w.reference[w.index])
        clean2 = _mean_square(pose, clean[w.index])
        truth2 = _mean_square(pose, w.truth[w.at][:, :w.n])
        wave = np.sqrt(np.mean((w.reference - clean)[w.index] ** 2, axis=0))
        print(f'{scenario} {seed} window_end {w.times[-1]:.0f} pose rms vs reference '
              f'{np.sqrt(ref2).round(4)} vs truth {np.sqrt(truth2).round(4)} truth/reference '
              f'{(truth2 / ref2).round(2)} truth/lp {(truth2 / clean2).round(2)} reference '
              f'above {CUTOFF} w0 {wave.round(4)}', flush=True)


SHARED_BAND_LOW = 0.1  # [rad/s] lower edge of the --shared band (above the DP loops' ω_n)


def _rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def _corr(x: FloatArray, y: FloatArray) -> float:
    return round(float(np.corrcoef(x, y)[0, 1]), 2)


def shared_probe(scenario: str, seed: int) -> None:
    """``--shared``: what the twist's error shares with the low-passed reference's."""
    windows = list(examined(scenario, seed))[-1:]
    for w in windows:
        true_v = true_twist(w.truth, w.h, w.n)[w.at]
        twist = np.array([p.twist for p in w.rows])
        reference = reference_velocity(w.reference, w.h, w.cutoff)[w.index]
        e, d = twist - true_v, reference - true_v
        accel = np.abs(np.array([p.accel for p in w.rows]))
        calm = accel < np.median(accel, axis=0)
        b, a = signal.butter(2, [SHARED_BAND_LOW * w.h / np.pi, w.cutoff * w.h / np.pi], 'band')
        for i in range(w.n):
            c = calm[:, i]
            print(f'{scenario} {seed} window_end {w.times[-1]:.0f} dof {i} calm: rms e '
                  f'{_rms(e[c, i]):.5f} d {_rms(d[c, i]):.5f} e against the reference '
                  f'{_rms(e[c, i] - d[c, i]):.5f}; corr(e, d) {_corr(e[c, i], d[c, i])}')
            eb, tb, rb, db = (np.asarray(signal.filtfilt(b, a, x), dtype=np.float64)
                              for x in (e[:, i], true_v[:, i], reference[:, i], d[:, i]))
            print(f'  band {SHARED_BAND_LOW}-{w.cutoff:.2f} rad/s: rms e {_rms(eb):.5f} true '
                  f'{_rms(tb):.5f} reference {_rms(rb):.5f} d {_rms(db):.5f}; corr(e, -true) '
                  f'{_corr(eb, -tb)} corr(d, -true) {_corr(db, -tb)} corr(e, d) {_corr(eb, db)}',
                  flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    mode = probe
    if '--pose' in args:
        mode = pose_probe
    if '--shared' in args:
        mode = shared_probe
    return run_cases([a for a in args if a not in ('--pose', '--shared')],
                     (__doc__ or '').splitlines()[0], twin_gain_calibration.CALIBRATION_SEEDS,
                     f'calibration seeds: {twin_gain_calibration.CALIBRATION_SEEDS}', mode)


if __name__ == '__main__':
    sys.exit(main())
