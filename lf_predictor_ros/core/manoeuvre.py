"""Has the vessel manoeuvred in a window of positions? (station keeping vs. moves and turns)

DP systems filter harder while the vessel holds station than while it moves: the LF motion of a
vessel holding position is slow and small, a setpoint move or a turn puts LF motion up to the
controller's bandwidth. ``PredictorParams.notch_broadband_holding_only`` uses this test to give
the targets' wide broadband notch only to windows of station keeping (issue 13; docs/
BENCHMARKS.md, eleventh session: the wide notch helps the supply vessel's loops and hurts
rao_supply's, whose windows hold its setpoint moves and turns). The same test makes
``PredictorParams.sea_change_confirm: manoeuvres`` (the default since the twentieth session) ask
for a confirmed change of sea state when a move or a turn is in the short window; ``turning``,
its heading part, does so for ``turns`` (fifteenth session). With
``OdometryParams.controller_read_holding_only`` the controller read passes over its blocks that
manoeuvred (`lf_state.block_manoeuvred`; seventy-second session).

The test needs no model: the positions are averaged over consecutive blocks of
``MANOEUVRE_BLOCK`` seconds (wave periods of 5–20 s average out), and the window shows a
manoeuvre when two consecutive block means differ by more than ``MANOEUVRE_STEP`` in any DOF.
Holding station, the block means of the tuning seeds' DP loops move by well under a metre; a
15 m setpoint move or a 45° turn moves them by several metres or tens of degrees per block.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

# Block over which the positions are averaged [s].
MANOEUVRE_BLOCK = 60.0
# Change of the block mean between two consecutive blocks that counts as a manoeuvre
# [m, m, rad] (north, east, heading; 2° in heading).
MANOEUVRE_STEP = (2.0, 2.0, 0.035)


def block_means(y: FloatArray, sample_time: float) -> FloatArray:
    """Means of ``y`` (n, ndof) over consecutive whole blocks of ``MANOEUVRE_BLOCK`` seconds.

    The newest samples set the block boundaries (a partial oldest block is left out); shape
    (blocks, ndof), oldest first. The input is not modified. (`alignment.block_mean_poses`
    averages wrapped 3-DOF poses circularly for the input grid; here every column is a plain
    series, the heading unwrapped, so that block-to-block steps never see a ±π crossing.)
    """
    data = np.asarray(y, dtype=np.float64)
    if data.ndim != 2:
        raise ValueError(f'y must have shape (n, ndof), got {data.shape}')
    if not sample_time > 0.0:
        raise ValueError(f'sample_time must be > 0 s, got {sample_time!r}')
    length = max(1, int(round(MANOEUVRE_BLOCK / sample_time)))
    blocks = data.shape[0] // length
    if blocks == 0:
        return np.empty((0, data.shape[1]))
    tail = data[data.shape[0] - blocks * length:]
    return np.asarray(tail.reshape(blocks, length, data.shape[1]).mean(axis=1), dtype=np.float64)


def manoeuvring(y: FloatArray, sample_time: float) -> bool:
    """True when two consecutive block means of ``y`` differ by more than ``MANOEUVRE_STEP``.

    ``y`` (n, ndof): positions [m] and, for 3 DOF, the unwrapped heading [rad]. Fewer than two
    whole blocks, or non-finite block means: False (no evidence of a manoeuvre).
    """
    data = np.asarray(y, dtype=np.float64)
    return _steps_exceed(block_means(data, sample_time), MANOEUVRE_STEP[:data.shape[-1]])


def turning(heading: FloatArray, sample_time: float) -> bool:
    """True when two consecutive block means of ``heading`` differ by more than 2° (a turn).

    ``heading`` (n,): the unwrapped heading [rad]; the step is ``MANOEUVRE_STEP``'s heading
    entry, whatever the positions do. Fewer than two whole blocks: False.
    """
    column = np.asarray(heading, dtype=np.float64)
    if column.ndim != 1:
        raise ValueError(f'heading must have shape (n,), got {column.shape}')
    return _steps_exceed(block_means(column[:, None], sample_time), MANOEUVRE_STEP[2:])


def _steps_exceed(means: FloatArray, limit: tuple[float, ...]) -> bool:
    """Two consecutive rows of ``means`` (blocks, k) apart by more than ``limit`` (k,) anywhere.

    Fewer than two blocks, or non-finite block means: False (no evidence of a manoeuvre).
    """
    if means.shape[0] < 2:
        return False
    steps = np.abs(np.diff(means, axis=0))
    with np.errstate(invalid='ignore'):
        return bool(np.any(steps > np.asarray(limit, dtype=np.float64)))
