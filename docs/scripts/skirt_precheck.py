"""Exploratory: the targets' notch skirt undone in the LF band (a zero-phase gain 1/|H|²).

    OMP_NUM_THREADS=1 python docs/scripts/skirt_precheck.py --scenarios rao_supply \
        --seeds 361 362 363 364 --closed-loop --loops-only --variant "skirt="

`method_probe.py` with `retraining.zero_phase` patched in this process only (nothing in the
package changes): after the zero-phase notch + low-pass, the filtered window (minus its
least-squares line, reflected by half its length at both ends) is multiplied in frequency by
1 + (1/max(|H|², 0.2) − 1) · taper, |H|² the filter's power response and the taper 1 below
``SKIRT_LOW`` × the notch frequency (the first minimum of |H|), 0 above ``SKIRT_HIGH`` × it,
sin² between; the line is added back. So the targets (and everything else `retraining`
filters zero-phase) keep the LF motion the notch's skirt takes between the DP loops' band and
0.3–0.4 ω0 (docs/BENCHMARKS.md, thirty-fourth session: 14–44 % of the power at 0.1–0.2 rad/s
with ζ 1.3 and ω0 0.63 rad/s). Every variant of the run gets the patch (run the default rows
from another process). Development seeds only, as `method_probe.py`.
"""
from __future__ import annotations

from pathlib import Path
import sys
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.core.filters import frequency_response  # noqa: E402
import lf_predictor_ros.core.retraining as retraining  # noqa: E402

FloatArray = NDArray[np.float64]
SKIRT_LOW = 0.3  # × the notch frequency: full compensation below
SKIRT_HIGH = 0.4  # × the notch frequency: none above
MIN_POWER = 0.2  # |H|² floor of the compensation (at most 5× in power)
_zero_phase = getattr(retraining, 'zero_phase')  # noqa: B009 - the function it imported


def _notch_frequency(sos: FloatArray) -> float:
    """The first local minimum of |H| [rad/sample] (the notch; the low-pass has none)."""
    grid = np.linspace(1e-3, 0.99 * np.pi, 4000)
    response = frequency_response(sos, grid, 1.0)
    minima = signal.argrelmin(np.abs(response))[0]
    return float(grid[minima[0]] if minima.size else grid[np.argmin(np.abs(response))])


def compensated(y: Any, sos: FloatArray) -> FloatArray:
    """`filters.zero_phase` with the notch's skirt undone below SKIRT_LOW × the notch."""
    out = np.asarray(_zero_phase(y, sos), dtype=np.float64)
    n = out.shape[0]
    if n < 16:
        return out
    data = out.reshape(n, -1)
    design = np.column_stack([np.ones(n), np.arange(n, dtype=np.float64)])
    line = design @ np.linalg.lstsq(design, data, rcond=None)[0]
    pad = n // 2
    extended = np.pad(data - line, ((pad, pad), (0, 0)), mode='reflect')
    size = extended.shape[0]
    omega = 2.0 * np.pi * np.fft.rfftfreq(size)  # [rad/sample]
    response = frequency_response(sos, omega, 1.0)  # h = 1 sample: omega in rad/sample
    notch = _notch_frequency(sos)
    taper = np.clip((SKIRT_HIGH * notch - omega) / ((SKIRT_HIGH - SKIRT_LOW) * notch), 0.0, 1.0)
    gain = 1.0 + (1.0 / np.maximum(np.abs(response) ** 2, MIN_POWER) - 1.0) * \
        np.sin(0.5 * np.pi * taper) ** 2
    spectrum = np.fft.rfft(extended, axis=0) * gain[:, None]
    back = np.fft.irfft(spectrum, n=size, axis=0)[pad:pad + n]
    return np.asarray((back + line).reshape(out.shape), dtype=np.float64)


if __name__ == '__main__':
    setattr(retraining, 'zero_phase', compensated)  # noqa: B010 - the patch is the point
    sys.exit(method_probe.main(sys.argv[1:]))
