"""Whether the few entries of small arrays are all finite, without numpy's per-call overhead.

`np.all(np.isfinite(x))` costs a few microseconds per call whatever the size; the predict path
and the odometry check arrays of three to a dozen entries every sample, where `math.isfinite`
over the entries as Python floats is several times cheaper. One helper for all of them.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike


def all_finite(*arrays: ArrayLike) -> bool:
    """True when every entry of every array is finite (no NaN, no ±inf); True for none."""
    return all(all(map(math.isfinite, np.asarray(a, dtype=np.float64).ravel().tolist()))
               for a in arrays)
