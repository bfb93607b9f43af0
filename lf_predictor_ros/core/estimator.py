"""The LF estimator contract shared by the adaptive predictor and the classical baselines.

Every estimator consumes one measured pose and the applied generalized force per sample and
returns its low-frequency (LF) pose estimate, so nodes, replay and evaluation can treat the learned
predictor (thesis Alg. 4.1) and the baselines (cascade filter, passive observer, smoother) alike.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

EstimatorState = Literal['warming_up', 'trained', 'fallback', 'error', 'ok']
ESTIMATOR_STATES: tuple[str, ...] = ('warming_up', 'trained', 'fallback', 'error', 'ok')


@dataclass(frozen=True)
class EstimatorStatus:
    """Health of an estimator, as published on /diagnostics.

    Attributes:
        state: 'warming_up' (collecting data, output not yet trustworthy), 'trained' (learned
            model in use), 'fallback' (a classical filter stands in), 'error', or 'ok' (a
            classical estimator running normally).
        wave_peak_freq: current wave peak frequency ω0 [rad/s], None if unknown.
        message: one human-readable line.
        last_loss: loss of the last accepted training [-], None if never trained.
        train_seconds: wall time of the last training [s].
        model_age: time since the model in use was trained [s].
        buffer_fill: fill level of the data buffer, 0–1.
        trainings: number of accepted trainings.
        rejected_trainings: number of trainings rejected by validation.
    """

    state: EstimatorState
    wave_peak_freq: float | None = None
    message: str = ''
    last_loss: float | None = None
    train_seconds: float | None = None
    model_age: float | None = None
    buffer_fill: float | None = None
    trainings: int = 0
    rejected_trainings: int = 0

    def __post_init__(self) -> None:
        """Validate the state name and the ranges of the optional fields."""
        if self.state not in ESTIMATOR_STATES:
            raise ValueError(f'state must be one of {ESTIMATOR_STATES}, got {self.state!r}')
        if self.buffer_fill is not None and not 0.0 <= self.buffer_fill <= 1.0:
            raise ValueError(f'buffer_fill must be in [0, 1], got {self.buffer_fill}')
        if self.trainings < 0 or self.rejected_trainings < 0:
            raise ValueError('trainings and rejected_trainings must be >= 0')

    def to_dict(self) -> dict[str, object]:
        """Plain dict for JSON and diagnostics key/value pairs."""
        return asdict(self)


@runtime_checkable
class LfEstimator(Protocol):
    """An online LF pose estimator fed one sample at a time.

    `update` returns the LF pose estimate `[north m, east m, yaw rad]` with yaw wrapped to
    (−π, π]; for the learned predictor it is valid at t + sample_time, for the baselines at t.
    Components beyond `ndof` are 0.
    """

    ndof: int
    sample_time: float

    def update(self, t: float, pose: NDArray[np.float64], force: NDArray[np.float64]) -> (
        NDArray[np.float64]
    ):
        """Consume the measured pose (3,) and applied force (3,) at time t [s]; return (3,)."""
        ...

    def reset(self) -> None:
        """Forget all state, as after construction."""
        ...

    def status(self) -> EstimatorStatus:
        """Current health of the estimator."""
        ...


def check_ndof(ndof: int) -> int:
    """Return ndof if it is 1 or 3, else raise ValueError."""
    if ndof not in (1, 3):
        raise ValueError(f'ndof must be 1 (surge only) or 3 (surge, sway, yaw), got {ndof}')
    return ndof
