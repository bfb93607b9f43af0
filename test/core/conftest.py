"""Shared fixtures of the core tests."""
from __future__ import annotations

import pytest
import torch


@pytest.fixture(autouse=True)
def _one_thread() -> None:
    """Trainings in these tests run on one core (the machine is shared)."""
    torch.set_num_threads(1)
