"""Shared fixtures of the core tests."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import torch

from lf_predictor_ros.core.network import NnarmaxNet, NnarmaxSpec

# (spec, net, u, y, x, mask) of ``one_layer_case``
OneLayerCase = Callable[[int], tuple[NnarmaxSpec, NnarmaxNet, np.ndarray, np.ndarray, np.ndarray,
                                     np.ndarray]]


@pytest.fixture(autouse=True)
def _one_thread() -> None:
    """Trainings in these tests run on one core (the machine is shared)."""
    torch.set_num_threads(1)


def _one_layer_case(seed: int) -> tuple[NnarmaxSpec, NnarmaxNet, np.ndarray, np.ndarray,
                                        np.ndarray, np.ndarray]:
    """A default-shaped (one tanh layer + bypass, earth frame, relative) 3-output net and data."""
    spec = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=3, ny=4, nfb=0, hidden_units=2,
                       relative=True)
    rng = np.random.default_rng(seed)
    n = 150
    u = rng.normal(size=(n, 3))
    # steps driven by the previous input (learnable) + a little noise, far from the origin
    steps = 0.05 * np.tanh(np.roll(u, 1, axis=0)) + rng.normal(scale=0.005, size=(n, 3))
    x = np.cumsum(steps, axis=0) + np.array([40.0, -25.0, 1.0])
    y = x + rng.normal(scale=0.002, size=(n, 3))
    net = NnarmaxNet(spec, seed=seed + 1)
    net.set_standardization(u, y)
    return spec, net, u, y, x, np.arange(n) % 9 != 4


@pytest.fixture
def one_layer_case() -> OneLayerCase:
    """``_one_layer_case`` by seed (the LM Jacobian's and the trainer's tests)."""
    return _one_layer_case
