"""Measurement: how long one full garbage collection stalls the predictor node's process.

    python docs/scripts/gc_pause_probe.py [--repeats 3]

Builds the `predictor` node in-process (shipped defaults, 3-DOF), times `gc.collect()` (a full
collection: it holds the GIL, so every callback and the training thread wait for it), then
freezes the heap as the node executables do after building the node
(`nodes.runner.freeze_startup_heap`) and times it again. Prints the objects the collector
tracks and the collection times [ms] before and after.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
import gc
import sys
import time

import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from rclpy.utilities import try_shutdown

from lf_predictor_ros.nodes.predictor_node import PredictorNode
from lf_predictor_ros.nodes.runner import freeze_startup_heap


def full_collection_ms() -> float:
    """Wall time of one full collection [ms]."""
    start = time.perf_counter()
    gc.collect()
    return (time.perf_counter() - start) * 1e3


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--repeats', type=int, default=3, help='collections timed per state')
    args = parser.parse_args(argv)
    context = Context()
    rclpy.init(context=context)
    ndof = Parameter('ndof', value=3)  # type: ignore[no-untyped-call]  # rclpy: unannotated
    node = PredictorNode(context=context, parameter_overrides=[ndof])
    try:
        tracked = len(gc.get_objects())
        before = [full_collection_ms() for _ in range(args.repeats)]
        freeze_startup_heap()
        after = [full_collection_ms() for _ in range(args.repeats)]
        print(f'tracked objects {tracked}; full collection {", ".join(f"{m:.1f}" for m in before)}'
              f' ms; frozen {gc.get_freeze_count()}, tracked {len(gc.get_objects())}; full '
              f'collection {", ".join(f"{m:.3f}" for m in after)} ms')
    finally:
        gc.unfreeze()
        node.destroy_node()
        try_shutdown(context=context)
    return 0


if __name__ == '__main__':
    sys.exit(main())
