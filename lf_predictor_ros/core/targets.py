"""Training targets by appending filtered windows (thesis §4.2.2, Algorithm 4.1 lines 30–35).

Every retraining (every Δ samples) the newest α measured samples are filtered zero-phase. That
filtered window y_f(t) is wrong in its first and last ε samples (filter transients, thesis
Fig. 4.9), so only its middle is trusted. The target series y_T is built by overlapping:

1. delete the newest β − Δ values of the old targets y_T(t − Δ) (their end transient),
2. delete the oldest Δ values of y_T(t − Δ) (the window slides by Δ),
3. append the newest β values of y_f(t) (skipping its start transient because β < α − ε).

With α ≥ Δ + 2ε (eq. 4.4) and Δ + ε ≤ β < α − ε (eq. 4.5) every target except the newest ε ones
lies at least ε samples away from both ends of the window it came from. The newest ε targets are
still transient: ``training_mask`` leaves them out of the loss (Algorithm 4.1 line 38).

Start-up: before the first target series exists, the targets are the filtered window without its
leading ε-sample transient (α − ε samples). Until the target series reaches N samples the oldest
values are kept (the window grows by Δ per retraining), afterwards exactly Δ are dropped, as in
the thesis. All lengths here are in SAMPLES (see ``PredictorParams.*_samples``).
All functions are pure: inputs are never modified, results are new arrays.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lf_predictor_ros.core.readonly import ReadOnlyArrays

_FloatArray = NDArray[np.float64]


def start_targets(filtered: ArrayLike, transient_len: int) -> _FloatArray:
    """First target series: the filtered window without its first ``transient_len`` samples."""
    window = np.array(filtered, dtype=np.float64)  # copy
    if transient_len < 0 or transient_len >= window.shape[0]:
        raise ValueError(f'transient_len must lie in [0, {window.shape[0]}) for a filtered window '
                         f'of {window.shape[0]} samples, got {transient_len}: lengthen the filter '
                         'window (α > ε)')
    return window[transient_len:]


def append_targets(old_targets: ArrayLike | None, filtered: ArrayLike, retrain_every: int,
                   append_len: int, *, transient_len: int = 0,
                   max_len: int | None = None) -> _FloatArray:
    """New targets y_T(t) from the old ones y_T(t − Δ) and the filtered window y_f(t).

    Args:
        old_targets: y_T(t − Δ), shape (m,) or (m, k), newest last; None at start-up.
        filtered: y_f(t), the zero-phase filtered newest α samples, shape (α,) or (α, k).
        retrain_every: Δ [samples] between the end of ``old_targets`` and the end of ``filtered``.
        append_len: β [samples] taken from the end of ``filtered``.
        transient_len: ε [samples], only used at start-up (``old_targets`` None).
        max_len: N [samples]: if given, the oldest values are dropped only as far as needed to
            keep at most N targets (start-up growth); None drops exactly Δ (thesis line 32).

    Returns:
        y_T(t), a new array.

    """
    if old_targets is None:
        return start_targets(filtered, transient_len)
    old = np.asarray(old_targets, dtype=np.float64)
    new = np.asarray(filtered, dtype=np.float64)
    _check_lengths(old, new, retrain_every, append_len)
    kept = old[:old.shape[0] - (append_len - retrain_every)]  # line 31: drop newest β − Δ
    if max_len is None:
        kept = kept[retrain_every:]  # line 32: drop oldest Δ
    else:
        if max_len < append_len:
            raise ValueError(f'max_len N = {max_len} must be ≥ append_len β = {append_len}')
        kept = kept[max(0, kept.shape[0] + append_len - max_len):]
    return np.concatenate([kept, new[new.shape[0] - append_len:]], axis=0)  # line 33


def training_mask(n_samples: int, transient_len: int) -> NDArray[np.bool_]:
    """Boolean mask over ``n_samples`` targets: False for the newest ``transient_len`` ones.

    Algorithm 4.1 line 38: the error of the last ε samples is neglected in training.
    """
    if n_samples < 0 or transient_len < 0:
        raise ValueError(f'n_samples and transient_len must be ≥ 0, got {n_samples}, '
                         f'{transient_len}')
    mask = np.ones(n_samples, dtype=bool)
    mask[max(0, n_samples - transient_len):] = False
    return mask


@dataclass(frozen=True, eq=False)
class TargetWindow(ReadOnlyArrays):
    """Target series with the sample index of every target (index = t / sample_time).

    Attributes:
        values: targets, shape (m,) or (m, k), newest last (read-only).
        end_index: sample index of the newest target.

    """

    values: _FloatArray
    end_index: int

    def __post_init__(self) -> None:
        """Store a read-only copy of the values."""
        values = np.array(self.values, dtype=np.float64)
        values.setflags(write=False)
        object.__setattr__(self, 'values', values)
        object.__setattr__(self, 'end_index', int(self.end_index))

    @classmethod
    def start(cls, filtered: ArrayLike, end_index: int, transient_len: int) -> TargetWindow:
        """First targets from a filtered window whose newest sample has index ``end_index``."""
        return cls(start_targets(filtered, transient_len), end_index)

    def __len__(self) -> int:
        """Number of targets."""
        return int(self.values.shape[0])

    @property
    def start_index(self) -> int:
        """Sample index of the oldest target."""
        return self.end_index - len(self) + 1

    def indices(self) -> NDArray[np.int64]:
        """Sample index of every target, oldest first."""
        return np.arange(self.start_index, self.end_index + 1, dtype=np.int64)

    def times(self, sample_time: float, time_offset: float = 0.0) -> _FloatArray:
        """Time [s] of every target: time_offset + index · sample_time."""
        return time_offset + self.indices().astype(np.float64) * sample_time

    def append(self, filtered: ArrayLike, end_index: int, append_len: int, *,
               max_len: int | None = None) -> TargetWindow:
        """Append a filtered window ending at sample ``end_index`` (Algorithm 4.1 lines 30–35).

        The shift Δ = end_index − self.end_index may differ from the nominal retrain period (a
        late training); it must satisfy 0 < Δ ≤ β so no gap opens in the targets.
        """
        shift = int(end_index) - self.end_index
        values = append_targets(self.values, filtered, shift, append_len, max_len=max_len)
        return TargetWindow(values, end_index)


def _check_lengths(old: _FloatArray, new: _FloatArray, retrain_every: int,
                   append_len: int) -> None:
    """Raise ValueError when the appending cannot produce a gap-free target series."""
    if old.shape[1:] != new.shape[1:]:
        raise ValueError(f'old targets {old.shape} and filtered window {new.shape} differ in DOFs')
    if retrain_every < 1:
        raise ValueError(f'retrain_every Δ must be ≥ 1 sample, got {retrain_every}: the '
                         'filtered window must end after the old targets')
    if not retrain_every <= append_len <= new.shape[0]:
        raise ValueError(
            f'need Δ ≤ β ≤ α (thesis eq. 4.5), got Δ = {retrain_every}, β = {append_len}, '
            f'α = {new.shape[0]} samples: a shift larger than β leaves a gap; restart the '
            'targets with start_targets')
    if append_len - retrain_every > old.shape[0]:
        raise ValueError(f'old targets hold {old.shape[0]} samples, fewer than β − Δ = '
                         f'{append_len - retrain_every} to replace: restart with start_targets')
