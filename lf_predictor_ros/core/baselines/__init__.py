"""Classical LF estimators to compare the learned predictor with (anchors §4).

- `cascade.CascadeFilter`: causal notch + low-pass (Fossen 2011 §11.3; MSS ``notchFilter.m``).
- `observer.PassiveObserver`: nonlinear passive observer (Fossen & Strand 1999).
- `smoother.ZeroPhaseSmoother`: non-causal forward-backward reference (thesis §4.2.2).
"""
from lf_predictor_ros.core.baselines.cascade import CascadeFilter
from lf_predictor_ros.core.baselines.observer import (
    ObserverGains,
    PassiveObserver,
    bias_gains,
    observer_gains,
)
from lf_predictor_ros.core.baselines.smoother import ZeroPhaseSmoother, smooth_poses

__all__ = [
    'CascadeFilter',
    'ObserverGains',
    'PassiveObserver',
    'ZeroPhaseSmoother',
    'bias_gains',
    'observer_gains',
    'smooth_poses',
]
