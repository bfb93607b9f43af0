"""Exploratory upper bound: the motion gate's twin replaced by a passive observer on a given model.

    OMP_NUM_THREADS=1 MODEL_TWIN=true python docs/scripts/model_twin_probe.py \
        --scenarios rao_swell --seeds 771 772 --closed-loop --loops-only --variant "mt="

`method_probe.py` with, in this process only (nothing in the package changes), every adaptive
loop's motion-gate twin (the ramp-invariant network that follows moves and turns from past
positions) replaced by the tuned passive observer of the benchmark (`baseline_tuning.
make_observer`, the scenario's `config/baselines` gains) on the simulator's **true** model
(``MODEL_TWIN=true``) or on the model `observer_mistuned` uses (``MODEL_TWIN=mistuned``: M ×1.3,
D ×0.7), retuned to the predictor's own ω0 estimate (not the true ω0; the wave band's centre
until the first estimate, as the cascade fallback). The gate itself (its gains, the low-pass
of the offset, the yaw-moment heading gain) is unchanged: it still blends the holding network
with the twin only in moves and turns; a variant's ``motion_gate_smoothing: 0`` takes the
offset's low-pass away, as it does in the package.

Why (docs/BENCHMARKS.md, forty-sixth session): the learned filter loses its remaining position
to the observer in the manoeuvres, where a model turns the thrust into motion at once, and an
observer with a 30 % wrong model beats it by 1.6× in the RAO loops. This asks how much of that a
model twin could bring, before anyone builds one on the learned vessel memory. It uses the true
model: an upper bound for that direction, never a candidate. Development seeds only.

``MODEL_TWIN=none`` keeps the package's twin. ``ORACLE_TIMING=1`` also gives the gate the
schedule: within ``ORACLE_WINDOW`` s after each setpoint event of the (delayed) schedule the
north and east gains are 1 (the heading's stays the yaw moment's), elsewhere the gate's own
(the offset as the gate filters it). Another upper bound: a gate that knew when every
manoeuvre starts and how long it lasts. The forty-sixth session ran every combination on
rao_supply and rao_swell 771–786 (docs/BENCHMARKS.md).
"""
from __future__ import annotations

import math
import os
from pathlib import Path
import sys
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import method_probe  # noqa: E402 - the sibling script

from lf_predictor_ros.benchmark import baseline_tuning, estimators, suite  # noqa: E402
from lf_predictor_ros.core.motion_gate import shifted  # noqa: E402
from lf_predictor_ros.core.predictor import AdaptivePredictor  # noqa: E402

MODELS = ('true', 'mistuned', 'none')
ORACLE_WINDOW = 200.0  # [s] a manoeuvre's length after its setpoint event (ORACLE_TIMING)


class ModelTwin:
    """Stands in for the twin predictor: a passive observer, retuned to the predictor's ω0."""

    using_network = True  # the gate acts on it from the first sample (its warm-up still holds)
    checkpoint_path: str | None = None
    model = None

    def __init__(self, observer: Any, predictor: AdaptivePredictor) -> None:
        """Wrap ``observer``; ω0 is read from ``predictor`` at every sample."""
        self.observer = observer
        self.predictor = predictor
        self._omega = math.nan

    def update(self, t: float, pose: np.ndarray, force: np.ndarray) -> np.ndarray:
        """The observer's LF pose for this sample, after retuning to a new ω0."""
        omega = self.predictor._fallback_freq()  # its ω0, the band centre before the first
        if omega != self._omega:
            self.observer.set_wave_peak_freq(omega)
            self._omega = omega
        return np.asarray(self.observer.update(t, pose, force), dtype=np.float64)

    @property
    def counters(self) -> dict[str, int]:
        """No trainings, no guard."""
        return {}

    def wait_for_training(self, timeout: float | None = None) -> bool:
        """Nothing trains."""
        return True

    def reset(self) -> None:
        """Forget the observer's state."""
        self.observer.reset()

    def restart_segment(self) -> None:
        """Nothing to restart."""

    def discard_running_job(self) -> None:
        """No job."""

    def request_retrain(self) -> None:
        """No training."""

    def close(self) -> None:
        """Nothing to stop."""


def oracle_timed(predictor: AdaptivePredictor, starts: list[float]) -> None:
    """Make the predictor's gate serve north and east fully in each manoeuvre window."""
    gated = predictor._gated

    def timed(t: float, out: np.ndarray, pose: np.ndarray, force: np.ndarray) -> np.ndarray:
        result: np.ndarray = gated(t, out, pose, force)
        offset = predictor._scaled_offset
        if offset is not None and any(a <= t < a + ORACLE_WINDOW for a in starts):
            gains = np.array(predictor._gain, dtype=np.float64)
            gains[:2] = 1.0
            result = shifted(out, gains * offset, predictor.ndof)
        return result

    setattr(predictor, '_gated', timed)  # noqa: B010 - the patch, this instance only


def with_model_twin(make: Any, which: str, timing: bool) -> Any:
    """`estimators.make_estimator`, each adaptive predictor's twin a `ModelTwin` (and timed)."""

    def make_estimator(name: str, setup: Any) -> Any:
        stream = make(name, setup)
        predictor = stream.estimator
        if name != 'adaptive' or not isinstance(predictor, AdaptivePredictor) or \
                predictor._moving is None:
            return stream
        if which != 'none':
            predictor._moving.close()
            observer = baseline_tuning.make_observer(
                setup.baselines.get('observer', {}), setup.model, setup.ndof, setup.sample_time,
                predictor._fallback_freq(), mistuned=which == 'mistuned')
            predictor._moving = ModelTwin(observer, predictor)  # type: ignore[assignment]
        if timing:
            oracle_timed(predictor, [float(row[0]) for row in
                                     setup.scenario.controller.setpoint_schedule])
        return stream

    return make_estimator


if __name__ == '__main__':
    which = os.environ.get('MODEL_TWIN', '')
    if which not in MODELS:
        sys.exit(f'set MODEL_TWIN to one of {MODELS}')
    oracle_timing = os.environ.get('ORACLE_TIMING', '') == '1'
    patched = with_model_twin(estimators.make_estimator, which, oracle_timing)
    setattr(suite, 'make_estimator', patched)  # noqa: B010 - the patch
    print(f'# the motion gate twin: {which} model (none: the package twin); oracle timing '
          f'{oracle_timing}', flush=True)
    sys.exit(method_probe.main(sys.argv[1:]))
