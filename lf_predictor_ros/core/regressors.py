"""NNARMAX regressor vectors (thesis §2.3, §4.4).

The network predicts the next LF position from three tapped delay lines (thesis §4.4):

    u_p(t)    = {u(τ),    τ = t, …, t − nu + 1}     forces
    y_p(t)    = {y(τ),    τ = t, …, t − ny + 1}     measured positions
    ŷLF,p(t)  = {ŷLF(τ),  τ = t, …, t − nfb + 1}    feedback (LF prediction or LF target)

    ŷLF(t + 1) = NN(u_p(t), y_p(t), ŷLF,p(t))

Layout of one regressor row (fixed, used by the network, the trainer and the checkpoint):

    [u(t), u(t−1), …, u(t−nu+1), y(t), …, y(t−ny+1), fb(t), …, fb(t−nfb+1)]

lag-major: every lag block holds all channels (e.g. north, east, yaw). The feedback block comes
last so a parallel (recurrent) run can replace exactly those columns by the network's own output.

Arrays are time series with the oldest sample first and shape (n, channels). A row exists for every
t ≥ first_index = max(nu, ny, nfb) − 1, the first sample with a full history. Heading channels must
be unwrapped by the caller: the regressors are plain numbers and a ±π jump would look like a
2π step of the vessel.

Body frame (``PredictorParams.regressor_frame`` 'body', issue 13 hypothesis 3): a relative
network (``network.NnarmaxSpec.relative``) sees y(t−i) − y(t), fb(t−i) − y(t) and forces u
rotated to north/east with each sample's heading, u(t−i) = R(ψ(t−i))τ(t−i). With
``body_frame`` it also rotates the (north, east) pair of every lag block by R(ψ(t))ᵀ, ψ(t) the
newest measured heading of the row: positions become offsets in the body frame of the newest
heading and forces R(ψ(t))ᵀR(ψ(t−i))τ(t−i), the body-frame forces turned by the relative
heading. The heading channel stays relative yaw. The network's output (the step ŷLF(t + 1) −
y(t)) is in the same body frame and is turned back with R(ψ(t)). `rotate_blocks` is that
rotation (numpy; ``network`` has the torch twin).
"""
from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

# Polynomial orders of the ramp-invariant frame (``network.ramp_fit_weights``): 1 a line
# (constant velocity), 2 a parabola (constant acceleration).
RAMP_ORDERS = (1, 2)


class RegressorLags(Protocol):
    """The part of a network spec that defines its regressors (``NnarmaxSpec`` satisfies it)."""

    @property
    def n_outputs(self) -> int:
        """Number of position channels in y and in the feedback (1 or 3)."""
        ...

    @property
    def n_inputs_u(self) -> int:
        """Number of force channels in u (1 or 3)."""
        ...

    @property
    def nu(self) -> int:
        """Number of delayed force samples u(t), …, u(t − nu + 1)."""
        ...

    @property
    def ny(self) -> int:
        """Number of delayed measured positions y(t), …, y(t − ny + 1)."""
        ...

    @property
    def nfb(self) -> int:
        """Number of delayed feedback values ŷLF(t), …, ŷLF(t − nfb + 1)."""
        ...


def first_index(lags: RegressorLags) -> int:
    """Index of the first sample that has a full regressor history: max(nu, ny, nfb) − 1."""
    return max(lags.nu, lags.ny, lags.nfb, 1) - 1


def n_regressors(lags: RegressorLags) -> int:
    """Length of one regressor row: nu·n_u + (ny + nfb)·n_y."""
    return lags.nu * lags.n_inputs_u + (lags.ny + lags.nfb) * lags.n_outputs


def n_static_regressors(lags: RegressorLags) -> int:
    """Number of leading columns that do not depend on the feedback (force and position blocks)."""
    return lags.nu * lags.n_inputs_u + lags.ny * lags.n_outputs


def as_series(values: ArrayLike, channels: int, name: str) -> FloatArray:
    """Return ``values`` as a float64 (n, channels) series; a 1-D array is one channel."""
    series = np.asarray(values, dtype=np.float64)
    if series.ndim == 1 and channels == 1:
        series = series[:, np.newaxis]
    if series.ndim != 2 or series.shape[1] != channels:
        raise ValueError(
            f'{name} must have shape (n, {channels}) (time × channel, oldest first), got '
            f'{series.shape}: slice the pose/force columns the network was built for'
        )
    return series


def _lagged(series: FloatArray, rows: NDArray[np.intp], lags: int) -> FloatArray:
    """Block [x(t), x(t−1), …, x(t−lags+1)] for every t in ``rows``, shape (len(rows), lags·ch)."""
    if lags == 0:
        return np.empty((rows.size, 0), dtype=np.float64)
    index = rows[:, np.newaxis] - np.arange(lags)[np.newaxis, :]
    block: FloatArray = series[index].reshape(rows.size, lags * series.shape[1])
    return block


def build_regressors(
    u: ArrayLike, y: ArrayLike, yfb: ArrayLike, lags: RegressorLags
) -> tuple[FloatArray, int]:
    """Regressor rows for a whole window, vectorized (no loop over samples).

    ``u`` (n, n_inputs_u) forces, ``y`` (n, n_outputs) measured positions, ``yfb`` (n, n_outputs)
    feedback values (the LF targets for series-parallel training, or any LF series). Returns
    ``(X, first)``: X has shape (n − first, n_regressors) and row k is the regressor at time
    t = first + k, i.e. the input that predicts ŷLF(first + k + 1). The inputs are not modified.
    """
    u_series = as_series(u, lags.n_inputs_u, 'u')
    y_series = as_series(y, lags.n_outputs, 'y')
    fb_series = as_series(yfb, lags.n_outputs, 'yfb')
    n = y_series.shape[0]
    if u_series.shape[0] != n or fb_series.shape[0] != n:
        raise ValueError(
            f'u, y and yfb must have the same length, got {u_series.shape[0]}, {n}, '
            f'{fb_series.shape[0]}: align the series on one time base first'
        )
    first = first_index(lags)
    if n <= first:
        raise ValueError(
            f'need more than max(nu, ny, nfb) − 1 = {first} samples to build a regressor, got {n}'
        )
    rows = np.arange(first, n)
    blocks = (
        _lagged(u_series, rows, lags.nu),
        _lagged(y_series, rows, lags.ny),
        _lagged(fb_series, rows, lags.nfb),
    )
    return np.concatenate(blocks, axis=1), first


def _newest_first(history: FloatArray, lags: int, channels: int, name: str) -> FloatArray:
    """Flatten the newest ``lags`` rows of a history, newest first (one regressor block)."""
    if lags == 0:
        return np.empty(0, dtype=np.float64)
    if history.ndim == 1 and channels == 1:
        history = history[:, np.newaxis]
    if history.ndim != 2 or history.shape[1] != channels or history.shape[0] < lags:
        raise ValueError(
            f'{name} must have shape (k, {channels}) with k ≥ {lags} rows (oldest first, newest '
            f'last), got {history.shape}'
        )
    block: FloatArray = np.asarray(history[: -lags - 1 : -1], dtype=np.float64)
    return block.reshape(lags * channels)


def regressor_vector(
    u_hist: FloatArray, y_hist: FloatArray, fb_hist: FloatArray, lags: RegressorLags
) -> FloatArray:
    """One regressor row from histories (oldest first, newest last, at least nu/ny/nfb rows).

    Equal to the row of ``build_regressors`` at the newest sample of the histories.
    """
    return np.concatenate(
        (
            _newest_first(u_hist, lags.nu, lags.n_inputs_u, 'u_hist'),
            _newest_first(y_hist, lags.ny, lags.n_outputs, 'y_hist'),
            _newest_first(fb_hist, lags.nfb, lags.n_outputs, 'fb_hist'),
        )
    )


def rotate_blocks(values: ArrayLike, cos: ArrayLike, sin: ArrayLike) -> FloatArray:
    """Rotate the (north, east) pair of every 3-channel block of each row by R(angle).

    ``values`` (rows, 3·blocks) or (3·blocks,): blocks of (north, east, yaw) (or (X, Y, N))
    channels, e.g. a 3-DOF regressor row; ``cos``, ``sin`` (rows,) or scalars: of the angle of
    each row. North' = c·north − s·east, east' = s·north + c·east; the third channel of each
    block is unchanged. R(ψ)ᵀ (into the body frame of heading ψ) is ``rotate_blocks(v, cos ψ,
    −sin ψ)``. Returns a new array.
    """
    array = np.asarray(values, dtype=np.float64)
    if array.shape[-1] % 3:
        raise ValueError(f'rotate_blocks needs rows of 3-channel blocks, got width '
                         f'{array.shape[-1]}: the body frame needs ndof 3')
    blocks = array.reshape(array.shape[:-1] + (array.shape[-1] // 3, 3))
    c = np.asarray(cos, dtype=np.float64)[..., np.newaxis]
    s = np.asarray(sin, dtype=np.float64)[..., np.newaxis]
    north, east = blocks[..., 0], blocks[..., 1]
    # written into a copy (the third channels stay): c·north − s·east and s·north + c·east,
    # each product rounded, then the sum, as the expressions compute them (no np.stack)
    result: FloatArray = array.copy()
    rotated = result.reshape(blocks.shape)
    np.multiply(c, north, out=rotated[..., 0])
    rotated[..., 0] -= s * east
    np.multiply(s, north, out=rotated[..., 1])
    rotated[..., 1] += c * east
    return result
