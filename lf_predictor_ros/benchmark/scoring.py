"""Statistics over seeds: means with 95 % intervals, per-seed ratios, target verdicts.

A benchmark number is the mean over the held-out seeds with a two-sided 95 % confidence interval
of that mean from Student's t distribution (mean ± t₀.₉₇₅,ₙ₋₁ · s/√n, s the sample standard
deviation). Ratios (estimator A / estimator B) are formed per seed first, so the interval
reflects how consistently A beats B, not how the two means happen to fall.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
import math

import numpy as np
from scipy import stats

CONFIDENCE = 0.95


@dataclass(frozen=True)
class Interval:
    """Mean of n values and its confidence interval [low, high] (nan when undefined)."""

    mean: float
    low: float
    high: float
    n: int

    def cell(self, fmt: Callable[[float], str]) -> str:
        """'mean [low, high]' (just the mean for n < 2)."""
        if self.n == 0 or not math.isfinite(self.mean):
            return '–' if self.n == 0 else fmt(self.mean)
        if self.n < 2 or not math.isfinite(self.low):
            return fmt(self.mean)
        return f'{fmt(self.mean)} [{fmt(self.low)}, {fmt(self.high)}]'


def interval(values: Iterable[float], confidence: float = CONFIDENCE) -> Interval:
    """Student-t interval of the mean of the finite ``values`` (non-finite ones dropped)."""
    data = np.array([v for v in values if math.isfinite(v)], dtype=np.float64)
    n = int(data.size)
    if n == 0:
        return Interval(math.nan, math.nan, math.nan, 0)
    mean = float(np.mean(data))
    if n < 2:
        return Interval(mean, math.nan, math.nan, 1)
    half = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1) * np.std(data, ddof=1) / math.sqrt(n))
    return Interval(mean, mean - half, mean + half, n)


def ratios(numerators: Sequence[float], denominators: Sequence[float]) -> list[float]:
    """Per-seed ratios a/b (inf where b ≤ 0, nan where either is nan)."""
    out = []
    for a, b in zip(numerators, denominators, strict=True):
        if not (math.isfinite(a) and math.isfinite(b)):
            out.append(math.nan)
        else:
            out.append(a / b if b > 0.0 else math.inf)
    return out


def verdict(ok: bool) -> str:
    """'met' or 'MISSED' (never hidden)."""
    return 'met' if ok else 'MISSED'


def fmt_number(value: float) -> str:
    """Three significant digits; inf/nan as text."""
    return f'{value:.3g}' if math.isfinite(value) else str(value)


__all__ = ['CONFIDENCE', 'Interval', 'fmt_number', 'interval', 'ratios', 'verdict']
