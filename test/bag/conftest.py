"""Shared fixtures of the bag tests."""
from __future__ import annotations

from collections.abc import Callable
import subprocess
import time
from typing import Any

import pytest

MATCH_TIMEOUT = 15.0  # [s] recorder start-up + discovery on a loaded machine
SUBSCRIBER_SETTLE = 1.0  # [s] after the publisher sees the subscription


def _wait_until_subscribed(publisher: Any, recorder: subprocess.Popen[str]) -> None:
    """Block until ``recorder`` subscribed to ``publisher``'s topic (it must not die meanwhile)."""
    deadline = time.monotonic() + MATCH_TIMEOUT
    while publisher.get_subscription_count() == 0:
        assert recorder.poll() is None, recorder.communicate()
        assert time.monotonic() < deadline, 'recorder never subscribed'
        time.sleep(0.02)
    # the subscriber's side of the match completes a little later; 0.2 s lost the first 37
    # poses once in six loaded runs (test_signal_finishes_the_file)
    time.sleep(SUBSCRIBER_SETTLE)


@pytest.fixture
def wait_until_subscribed() -> Callable[[Any, subprocess.Popen[str]], None]:
    """``wait_until_subscribed(publisher, recorder_process)``: see `_wait_until_subscribed`."""
    return _wait_until_subscribed
