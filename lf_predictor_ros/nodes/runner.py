"""The Jazzy `main()` pattern shared by every node executable (ros2/examples, jazzy branch).

    rclpy.init(args=args)
    return spin_node(lambda: MyNode(), config_errors=(ValueError,), logger_name='my_node')

A node whose constructor rejects its configuration logs FATAL with the reason and the process
exits 1; Ctrl-C and an external shutdown end the spin quietly; the node is always destroyed and
the context shut down (`try_shutdown`, safe when a signal already did it). A node that ends by
itself (``until``'s future, e.g. the simulator at the end of its scenario) first waits up to
``FLUSH_TIMEOUT`` for its subscribers to acknowledge what its reliable publishers sent, so the
last messages of a run are not lost with the publisher.

Once the node is built, the heap is frozen (`freeze_startup_heap`): the objects of the imports
and the node itself (343 000 in the predictor node, with torch and rclpy) leave the garbage
collector's generations, so a full collection no longer walks them. Such a collection holds the
GIL, and with it every callback, for 0.1–0.26 s (measured: docs/BENCHMARKS.md, forty-eighth
session). The math libraries' thread pools are then limited to one thread
(`core.math_threads`): the node and its child process share the cores with each other and the
DP stack.
"""
from __future__ import annotations

from collections.abc import Callable
import gc
import time

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.task import Future
from rclpy.utilities import ok, try_shutdown

from lf_predictor_ros.core.math_threads import use_one_math_thread

FLUSH_TIMEOUT = 2.0  # [s] longest wait for the subscribers' acknowledgements at a normal end


def spin_node(make_node: Callable[[], Node], *,
              config_errors: tuple[type[BaseException], ...], logger_name: str,
              until: Callable[[Node], Future | None] | None = None) -> int:
    """Create the node, spin it until shutdown (or until ``until``'s future); exit code 0/1."""
    try:
        node = make_node()
    except config_errors as error:
        if not ok():  # Ctrl-C while starting: the context went away under the node
            return 0
        rclpy.logging.get_logger(logger_name).fatal(f'invalid configuration: {error}')
        try_shutdown()
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        try_shutdown()
        return 0
    use_one_math_thread()
    freeze_startup_heap()
    spin_until_shutdown(node, until)
    return 0


def freeze_startup_heap() -> None:
    """Collect once, then move every object alive to the collector's permanent generation.

    For a long-running process after its start: what the imports and the node's construction
    made lives as long as the process, and a full collection no longer visits it. Objects made
    later are collected as before. Undone by `gc.unfreeze`.
    """
    gc.collect()
    gc.freeze()


def spin_until_shutdown(node: Node, until: Callable[[Node], Future | None] | None = None) -> None:
    """Spin ``node`` until Ctrl-C, an external shutdown or ``until``'s future; then destroy it.

    The context is shut down afterwards (`try_shutdown`, safe when a signal already did it).
    """
    try:
        done = until(node) if until is not None else None
        if done is not None:
            rclpy.spin_until_future_complete(node, done)
            if done.done() and ok():
                flush(node)
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # noqa: BLE001 - only swallowed when it is the shutdown race
        if ok():
            raise
        # a signal shut the context down while the executor was in rcl_wait, which rcl reports
        # as an error ('failed to wait on wait set'): an ordinary shutdown
    finally:
        node.destroy_node()
        try_shutdown()


def flush(node: Node, timeout: float = FLUSH_TIMEOUT) -> bool:
    """Wait until the subscribers have acknowledged every reliable publisher's messages.

    At most ``timeout`` [s] in all (best-effort publishers return at once); True if all did.
    """
    deadline = time.monotonic() + timeout
    acked = True
    for publisher in node.publishers:
        remaining = max(0.0, deadline - time.monotonic())
        acked = publisher.wait_for_all_acked(Duration(seconds=remaining)) and acked
    return acked
