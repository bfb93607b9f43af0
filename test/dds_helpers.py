"""Helpers of the DDS tests that feed nodes sample by sample (``import dds_helpers``).

``conftest.py`` puts this directory on ``sys.path``: with ``--import-mode=importlib`` the test
directories are not, and ``test`` itself would resolve to the standard library's package.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
import contextlib
import time
from typing import Any

import numpy as np
from rclpy import init
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.utilities import try_shutdown

WAIT = 20.0  # [s wall] bound of every wait (a loaded 2-core machine)


def spin_until(executor: SingleThreadedExecutor, done: Callable[[], bool], what: str,
               wait: float = WAIT) -> None:
    """Spin until ``done()``; fail naming ``what`` after ``wait`` seconds of wall time."""
    end = time.monotonic() + wait
    while not done():
        assert time.monotonic() < end, f'timed out after {wait} s waiting for {what}'
        executor.spin_once(timeout_sec=0.01)


def last_is(seen: list[float], t: float) -> bool:
    """The newest stamp seen is ``t`` (for ``functools.partial`` in a feeding loop)."""
    return bool(seen) and seen[-1] == t


def longer_than(messages: list[Any], count: int) -> bool:
    """More than ``count`` messages have arrived."""
    return len(messages) > count


@contextlib.contextmanager
def own_executor() -> Iterator[tuple[Context, SingleThreadedExecutor]]:
    """A fresh rclpy Context and its executor; every node on it is destroyed afterwards.

    For module-scoped runs (the function-scoped ``ros_context`` / ``executor`` fixtures of
    ``conftest.py`` are the same for one test).
    """
    context = Context()
    init(context=context)
    executor = SingleThreadedExecutor(context=context)
    try:
        yield context, executor
    finally:
        for node in list(executor.get_nodes()):
            executor.remove_node(node)
            node.destroy_node()
        executor.shutdown()
        try_shutdown(context=context)


def poses_fed_to(estimator: Any) -> list[Any]:
    """Record every pose ``estimator.update(t, pose, force)`` is called with (a copy each).

    The node tests wrap a node's estimator with it to see what got past the reference checks.
    """
    fed: list[Any] = []
    update = estimator.update

    def spy(t: float, pose: Any, force: Any) -> Any:
        fed.append(np.array(pose))
        return update(t, pose, force)

    estimator.update = spy
    return fed
