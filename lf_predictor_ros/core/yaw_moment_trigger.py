"""The motion gate's heading gain from the applied yaw moment: a turn is known before it shows.

In a DP turn the controller's yaw moment jumps from its station-keeping level (about 1 MN·m on
the RAO supply vessel) to its limit (16–19 MN·m) in the turn's first second, while the learned
holding network's heading lags the turn by 0.1–0.15 rad and the gate's velocity gain
(`core.motion_gate`) opens late or on swell yaw (docs/BENCHMARKS.md, forty-fourth session). This
trigger gives the gate's heading gain from the moment instead (issue 13):

    m_k = LP_{T_m}(|N_k|),      L_k = running mean of |N| for the first T_L, then LP_{T_L}(|N|)
    g_k = 1                     while m_k > ρ · max(L_k, 1 N·m), and ``hold`` s after,
    g_k = 1 − (τ − hold)/T_f    for τ s since then, down to 0,

LP_T a first-order low-pass of time constant T (weight min(1, h/T) per sample h). No gain
before ``warmup`` s have passed (T_L by default): the level is not yet a measure of station
keeping. Only the moment's size
against its own level is used; nothing about the vessel is assumed. The constants are those of
the probe that passed the adoption test on development seeds
(`docs/scripts/yaw_moment_gate_probe.py` up to commit fd2c469; docs/BENCHMARKS.md, forty-fourth
and forty-fifth sessions); ρ and ``hold`` are `PredictorParams` fields
(``motion_gate_yaw_moment_ratio``, ``motion_gate_yaw_hold``, ``motion_gate_yaw_warmup``).
"""
from __future__ import annotations

import math

# T_m: time constant of the low-pass on |yaw moment| [s].
MOMENT_TIME = 2.0
# T_L: time constant of the level's low-pass, and the default warm-up before any gain [s].
LEVEL_TIME = 600.0
# T_f: after the hold, the gain falls linearly from 1 to 0 over this time [s].
FADE_TIME = 10.0
# The level's floor in the ratio test: a vessel with no yaw moment at all is not turning [N·m].
LEVEL_FLOOR = 1.0


class YawMomentTrigger:
    """The heading gain g of the module docstring, updated once per predictor sample."""

    def __init__(self, sample_time: float, ratio: float, hold: float,
                 warmup: float = LEVEL_TIME) -> None:
        """Create for samples ``sample_time`` [s] apart; ``ratio`` ρ [-] > 0, ``hold`` [s] ≥ 0.

        ``warmup`` [s] ≥ 0: no gain until the level has seen this much time of moments.
        """
        for name, value in (('sample_time', sample_time), ('ratio', ratio)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'YawMomentTrigger {name} must be finite and > 0, got '
                                 f'{value!r}')
        for name, value in (('hold', hold), ('warmup', warmup)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'YawMomentTrigger {name} must be finite and ≥ 0, got '
                                 f'{value!r}')
        self.sample_time = sample_time
        self.ratio = ratio
        self.hold = hold
        self.warmup = warmup
        self.reset()

    def reset(self) -> None:
        """Forget the moment, its level and the last trigger (a new vessel or sea)."""
        self._moment = math.nan  # LP(|N|); NaN: no sample yet
        self._level = math.nan
        self._samples = 0
        self._since = math.inf  # s since the ratio last exceeded ρ

    @property
    def warm(self) -> bool:
        """Whether the level has seen ``warmup`` s of moments (no gain before)."""
        return self._samples * self.sample_time >= self.warmup

    def update(self, moment: float) -> float:
        """Add the yaw moment N [N·m] applied at this sample; return the heading gain in [0, 1].

        A non-finite moment is no evidence of a turn: it is skipped (the hold and fade go on).
        """
        h = self.sample_time
        size = abs(moment)
        if not math.isfinite(size):
            self._since += h
            return self._gain()
        if self._samples == 0:
            self._moment = self._level = size
        self._samples += 1
        self._moment += min(1.0, h / MOMENT_TIME) * (size - self._moment)
        # the level: the running mean of |N| until LEVEL_TIME has passed, then its low-pass
        self._level += max(h / LEVEL_TIME, 1.0 / self._samples) * (size - self._level)
        if self.warm and self._moment > self.ratio * max(self._level, LEVEL_FLOOR):
            self._since = 0.0
        else:
            self._since += h
        return self._gain()

    def _gain(self) -> float:
        if self._since <= self.hold:
            return 1.0
        return max(0.0, 1.0 - (self._since - self.hold) / FADE_TIME)
