"""The limit of the linear family: the best causal linear filter fitted on the truth (in-sample).

For any vessel, with or without a known model, the question "how good can a learned filter on
these regressors be?" has a linear answer: fit, by least squares on the *true* LF pose, the causal
linear map from the predictor's own regressors to the LF pose, over the very samples it is
scored on. No causal linear filter on those regressors can do better on that data, so the row is
a limit (it sees the truth), not a competitor.

Regressors at grid sample k (the predictor's, `core.regressors`, in its relative coordinates):
u[k], …, u[k − nu + 1] (body-frame thrust of the ndof channels), y[k − j] − y[k] for
j = 1 … ny − 1 (measured pose relative to the newest one, heading unwrapped) and a constant; the
target is truth[k] − y[k]. The estimate at k is y[k] + the fitted value (the pose at k, like the
other filters, not one step ahead).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from lf_predictor_ros.core.estimator import check_ndof
from lf_predictor_ros.core.heading import wrap_angle

FloatArray = NDArray[np.float64]


def _continuous(pose: FloatArray, ndof: int) -> FloatArray:
    out = np.array(pose[:, :ndof], dtype=np.float64)
    if ndof == 3:
        out[:, 2] = np.unwrap(out[:, 2])
    return out


def _lagged(series: FloatArray, rows: NDArray[np.intp], lags: range) -> FloatArray:
    index = rows[:, None] - np.asarray(list(lags), dtype=np.intp)[None, :]
    return np.asarray(series[index].reshape(rows.size, -1), dtype=np.float64)


def regressor_design(positions: FloatArray, u: FloatArray, rows: NDArray[np.intp], ndof: int,
                     nu: int, ny: int) -> tuple[FloatArray, FloatArray]:
    """(design, newest pose) of the regressors at grid ``rows`` (module docstring).

    ``positions`` (n, ≥ ndof) with the heading continuous, ``u`` (n, ≥ ndof); each row k holds
    u[k], …, u[k − nu + 1], y[k − j] − y[k] for j = 1 … ny − 1 and a constant; rows must be
    ≥ max(nu, ny) − 1. The newest pose y[k] is returned with it (the fit's target is relative).
    """
    y_c = positions[:, :ndof]
    newest = y_c[rows]
    blocks = [_lagged(u[:, :ndof], rows, range(nu)),
              _lagged(y_c, rows, range(1, ny)) - np.tile(newest, ny - 1),
              np.ones((rows.size, 1))]
    return np.hstack(blocks), newest


def scaled_least_squares(design: FloatArray, target: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(coef, scale): least squares on unit-std columns; the fit is design / scale @ coef."""
    scale = np.std(design, axis=0)
    scale[scale == 0.0] = 1.0
    coef, *_ = np.linalg.lstsq(design / scale, target, rcond=None)
    return coef, scale


def linear_limit(y: FloatArray, u: FloatArray, truth: FloatArray, ndof: int, nu: int, ny: int,
                 begin: int) -> FloatArray:
    """In-sample least-squares estimate (n, 3) of the LF pose; rows before the fit repeat y.

    ``y``, ``u``, ``truth`` are (n, 3) grid series (oldest first); the fit uses the samples
    k ≥ max(begin, nu − 1, ny − 1). Inputs are not modified.
    """
    check_ndof(ndof)
    if nu < 0 or ny < 1:
        raise ValueError(f'need nu >= 0 and ny >= 1 samples, got nu = {nu}, ny = {ny}')
    n = y.shape[0]
    if y.shape != (n, 3) or u.shape != (n, 3) or truth.shape != (n, 3):
        raise ValueError(f'y, u, truth must all be (n, 3), got {y.shape}, {u.shape}, '
                         f'{truth.shape}')
    first = max(begin, nu - 1, ny - 1)
    rows = np.arange(first, n)
    columns = ndof * (nu + ny - 1) + 1
    if rows.size < 4 * columns:
        raise ValueError(f'the linear limit needs >= {4 * columns} samples to fit {columns} '
                         f'coefficients, got {rows.size}: record longer')
    design, newest = regressor_design(_continuous(y, ndof), u, rows, ndof, nu, ny)
    target = _continuous(truth, ndof)[rows] - newest
    if ndof == 3:  # truth and measurement unwrapped separately: keep the offset in (−π, π]
        target[:, 2] = wrap_angle(target[:, 2])
    coef, scale = scaled_least_squares(design, target)
    out = np.array(y, dtype=np.float64)
    out[:, ndof:] = 0.0
    fitted = newest + (design / scale) @ coef
    if ndof == 3:
        fitted[:, 2] = wrap_angle(fitted[:, 2])
    out[rows, :ndof] = fitted
    return out


__all__ = ['linear_limit', 'regressor_design', 'scaled_least_squares']
