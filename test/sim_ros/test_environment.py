"""LF environment Markov processes and open-loop excitation signals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sim_ros.physics import excitation
from sim_ros.physics.environment import (
    EnvironmentConfig,
    EnvironmentGenerator,
    MarkovBias,
    MarkovGenerator,
    markov_step,
)


@pytest.mark.parametrize('step', [0.1, 1.0])
def test_markov_stationary_std_and_correlation_independent_of_step(step: float) -> None:
    """Std and the autocorrelation e^{−τ/T} at τ = T do not depend on the step.

    200 000 s = 5000 T: the std estimate scatters by ≈ 1 %, the mean by ≈ 0.03, the lag-T
    autocorrelation by ≈ 0.013, so the tolerances below are ≈ 4–5σ.
    """
    bias = MarkovBias((5.0, 0.0, 0.0), (2.0, 1.0, 0.0), 20.0)
    gen = MarkovGenerator(bias, step, np.random.default_rng(7))
    x = gen.next_block(int(200000 / step))[int(200 / step):]
    assert x[:, 0].mean() == pytest.approx(5.0, abs=0.15)
    assert x[:, 0].std() == pytest.approx(2.0, rel=0.05)
    assert x[:, 1].std() == pytest.approx(1.0, rel=0.05)
    np.testing.assert_array_equal(x[:, 2], 0.0)
    lag = int(round(20.0 / step))
    d = x[:, 0] - x[:, 0].mean()
    rho = np.dot(d[:-lag], d[lag:]) / np.dot(d, d)
    assert rho == pytest.approx(math.exp(-1.0), abs=0.05)


def test_markov_step_pure_and_blocks_continue() -> None:
    """Zero noise: exact exponential decay to the mean; blocks continue the same process."""
    bias = MarkovBias((1.0,), (0.5,), 10.0)
    value = np.array([3.0])
    new = markov_step(value, bias, 10.0, np.zeros(1))
    assert new[0] == pytest.approx(1.0 + 2.0 * math.exp(-1.0))
    assert value[0] == 3.0
    one = MarkovGenerator(bias, 1.0, np.random.default_rng(3)).next_block(100)
    gen = MarkovGenerator(bias, 1.0, np.random.default_rng(3))
    two = np.vstack([gen.next_block(40), gen.next_block(60)])
    np.testing.assert_allclose(one, two, rtol=1e-12)


def test_constant_current() -> None:
    """Constant current 0.5 m/s at 20°: north 0.470, east 0.171 m/s."""
    cfg = EnvironmentConfig(current_speed=0.5, current_direction=math.radians(20.0))
    rngs = tuple(np.random.default_rng(i) for i in range(3))
    current, force = EnvironmentGenerator(cfg, 0.1, rngs).next_block(10)  # type: ignore[arg-type]
    np.testing.assert_allclose(current, [[0.469846, 0.171010]] * 10, atol=1e-6)
    np.testing.assert_array_equal(force, 0.0)
    with pytest.raises(ValueError, match='current speed'):
        EnvironmentConfig(current_speed=-1.0)


def test_prbs_multisine_steps() -> None:
    """PRBS ±A switching only on its clock; multisine RMS A; steps piecewise constant."""
    sig = excitation.prbs([5.0, 0.0, 1.0], 10.0, 1000.0, np.random.default_rng(1))
    values = np.array([sig(t) for t in np.arange(0.0, 1000.0, 0.5)])
    assert set(np.unique(values[:, 0])) == {-5.0, 5.0}
    changes = np.nonzero(np.diff(values[:, 0]))[0] + 1
    assert np.all((np.arange(0.0, 1000.0, 0.5)[changes] % 10.0) == 0.0)
    assert 25 < changes.size < 75  # ≈ 50 expected switches of 100 clock ticks
    ms = excitation.multisine([2.0, 0.0, 0.0], [0.01, 0.02, 0.05], np.random.default_rng(2))
    grid = np.arange(0.0, 2 * math.pi / 0.01 * 10, 1.0)
    rms = math.sqrt(np.mean([ms(t)[0] ** 2 for t in grid]))
    assert rms == pytest.approx(2.0, rel=0.02)
    st = excitation.steps([[10.0, 1.0, 2.0, 3.0], [20.0, -1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(st(5.0), 0.0)
    np.testing.assert_array_equal(st(10.0), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(st(25.0), [-1.0, 0.0, 0.0])
