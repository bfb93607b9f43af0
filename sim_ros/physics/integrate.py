"""Fixed-step classical Runge–Kutta (RK4) for small ODEs on plain float lists.

The vessel state has 6 entries; numpy call overhead would dominate such a small system, so the
stepper works on Python lists (about 10× faster than numpy here, see `sim_ros.bench`). Inputs are
given at the three RK4 stage times (start, midpoint, end) so that a known input trajectory (e.g.
shaft speeds solved exactly) is honoured; a zero-order-held input passes the same tuple three
times. Butcher tableau: Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.1 (RK4).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

State = list[float]
RatesFn = Callable[[Sequence[float], Sequence[float]], State]


def rk4_step(
    rates: RatesFn,
    state: Sequence[float],
    step: float,
    input_start: Sequence[float],
    input_mid: Sequence[float],
    input_end: Sequence[float],
) -> State:
    """One RK4 step of ẋ = f(x, u(t)) of length `step` [s]; returns a new list."""
    half = 0.5 * step
    k1 = rates(state, input_start)
    k2 = rates([x + half * k for x, k in zip(state, k1, strict=True)], input_mid)
    k3 = rates([x + half * k for x, k in zip(state, k2, strict=True)], input_mid)
    k4 = rates([x + step * k for x, k in zip(state, k3, strict=True)], input_end)
    sixth = step / 6.0
    return [
        x + sixth * (a + 2.0 * b + 2.0 * c + d)
        for x, a, b, c, d in zip(state, k1, k2, k3, k4, strict=True)
    ]
