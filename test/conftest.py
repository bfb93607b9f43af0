"""Test harness: DDS isolation per test process and an rclpy Context per test.

Every pytest process gets its own ROS_DOMAIN_ID (range 1..100, derived from the PID; under
pytest-xdist from the controller's PID plus the worker's index, so the workers of one run never
share a domain) and discovery limited to localhost, set before anything imports rclpy, so parallel
CI jobs, the workers of one run and a developer's running demo never see each other's topics.
"""
from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
import os
import sys

import pytest

_REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if _REPO not in sys.path:
    sys.path.insert(0, _REPO)
_TESTS = os.path.dirname(os.path.abspath(__file__))  # dds_helpers, shared by the DDS tests
if _TESTS not in sys.path:
    sys.path.append(_TESTS)


def _isolated_domain_id(pid: int, worker: str | None = None, parent: int = 0) -> int:
    """A ROS_DOMAIN_ID for this test process, 1..100.

    ``worker``: pytest-xdist's ``PYTEST_XDIST_WORKER`` ('gw0', 'gw1', …; None outside xdist);
    the workers are children of the run's controller (``parent``): consecutive domains from its
    PID, so two workers of one run never collide (PIDs modulo 100 could).
    """
    # 1..100: stays inside the range every RMW maps to valid ports; 0 is the default domain.
    if worker is None or not worker.startswith('gw') or not worker[2:].isdigit():
        return 1 + pid % 100
    return 1 + (parent + int(worker[2:])) % 100


os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_DOMAIN_ID'] = str(_isolated_domain_id(
    os.getpid(), os.environ.get('PYTEST_XDIST_WORKER'), os.getppid()))
os.environ.setdefault('RCUTILS_LOGGING_BUFFERED_STREAM', '1')
os.environ.setdefault('MPLBACKEND', 'Agg')


@contextmanager
def _initialized_context() -> Iterator[object]:
    """An initialized rclpy Context, shut down afterwards whatever happens."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


@pytest.fixture
def ros_context() -> Iterator[object]:
    """An initialized rclpy Context for one test, shut down afterwards whatever happens."""
    with _initialized_context() as context:
        yield context


@pytest.fixture(scope='module')
def ros_module_context() -> Iterator[object]:
    """One initialized rclpy Context shared by a module's tests, shut down after the last."""
    with _initialized_context() as context:
        yield context


@pytest.fixture
def executor(ros_context: object) -> Iterator[object]:
    """A SingleThreadedExecutor on ``ros_context``; its nodes are destroyed afterwards."""
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=ros_context)
    yield ex
    for node in list(ex.get_nodes()):
        ex.remove_node(node)
        node.destroy_node()
    ex.shutdown()


@pytest.fixture
def dds_env() -> dict[str, str]:
    """Environment for child processes: same isolated domain as this test process."""
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['ROS_DOMAIN_ID'] = os.environ['ROS_DOMAIN_ID']
    env['PYTHONUNBUFFERED'] = '1'
    return env
