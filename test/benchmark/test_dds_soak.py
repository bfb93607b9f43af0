"""DDS soak benchmark: its counting helpers, the canary method, and a short real run."""
# rclpy is partly untyped.
# mypy: disable-error-code="no-untyped-call"
from __future__ import annotations

import dataclasses
import json
import math
import mmap
import os
import resource
import subprocess
import sys
from typing import Any

import pytest

from lf_predictor_ros.benchmark import dds_soak
from lf_predictor_ros.benchmark.dds_soak import (
    SoakConfig,
    SoakResult,
    canary_message,
    cpu_seconds,
    expected_grid_samples,
    format_table,
    json_line,
    missing_in_sequence,
    rss_bytes,
    run_soak,
    split_loss,
)
from lf_predictor_ros.nodes.conversions import pose_to_msg, sec_to_stamp

# Smoke run: 1 simulated minute at 25 Hz, 4× real time = 15 s of feed (+ node start-up): 100
# poses and 100 thrusts per second of wall time, the message rate of the contract's 100 Hz in
# real time, compressed in simulated time.
SMOKE_MINUTES = 1.0  # [min simulated]
SMOKE_SPEED = 4.0  # [× real time]
SMOKE_RATE = 25.0  # [Hz]
BLOCK_BYTES = 64 * 2**20  # [bytes] fresh anonymous mapping whose pages must show up in VmRSS
# Every required SoakResult field as 0 / False (a result to format, not a measurement).
_ZERO_RESULT: dict[str, Any] = {
    f.name: (False if f.type == 'bool' else 0) for f in dataclasses.fields(SoakResult)
    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING}
# The smoke run once fed 100 Hz at 4× real time (840 msg/s) into the contract's keep_last 5
# sensor-QoS queues: whether the node keeps up with four times the contract's rate is the
# machine's speed and state, not the code's: CI machines lost 2.2 % to 21 % of the poses, and
# this one 10–13 % and an hour later 0.03 % (2026-12-03; 0 % at 25 Hz, 0.3 % at 2×). The
# loss at and above the contract's rate is a benchmark figure (docs/RELIABILITY.md, "Load and
# soak"); this bound only catches a broken pipeline (no delivery, a wrong QoS, double counting).
MAX_SMOKE_POSE_LOSS = 0.10


def test_missing_in_sequence_counts_the_holes() -> None:
    period = 10_000_000  # [ns] 100 Hz
    assert missing_in_sequence([0, period, 2 * period], period) == 0
    assert missing_in_sequence([0, period, 4 * period, 5 * period, 8 * period], period) == 4
    assert missing_in_sequence([], period) == 0


def test_expected_grid_samples_counts_grid_instants_in_the_span() -> None:
    assert expected_grid_samples(0.0, 59.99, 1.0) == 60  # 0, 1, …, 59
    assert expected_grid_samples(0.5, 3.0, 1.0) == 3  # 1, 2, 3
    assert expected_grid_samples(0.2, 0.9, 1.0) == 0


def test_split_loss_separates_warm_up_from_training_time() -> None:
    # (canaries sent, canaries seen, trainings) per diagnostics message
    timeline = [(10, 10, 0), (20, 18, 0), (40, 30, 1), (60, 38, 2)]
    before, after = split_loss(timeline)
    assert before == pytest.approx(1 - 18 / 20) and after == pytest.approx(1 - 20 / 40)
    before, after = split_loss([(10, 9, 0)])
    assert before == pytest.approx(0.1) and math.isnan(after)
    assert all(math.isnan(x) for x in split_loss([]))


def test_json_line_is_strict_json() -> None:
    result = SoakResult(**{**_ZERO_RESULT, 'node_pose_loss': math.nan, 'rss_growth_pct': 1.5})
    parsed = json.loads(json_line(result))
    assert parsed['node_pose_loss'] is None and parsed['rss_growth_pct'] == 1.5
    assert 'pose loss ≈ n/a' in format_table(result)


def test_proc_readers_agree_with_the_kernel_for_this_process() -> None:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    rusage_cpu = usage.ru_utime + usage.ru_stime
    assert cpu_seconds(os.getpid()) == pytest.approx(rusage_cpu, abs=0.05)  # tick = 10 ms
    # a mapping of its own, not the allocator's: np.ones may be served from pages this worker
    # process already holds (the full suite once measured 0 bytes of growth that way)
    block = mmap.mmap(-1, BLOCK_BYTES)
    try:
        before = rss_bytes(os.getpid())
        for offset in range(0, BLOCK_BYTES, mmap.PAGESIZE):  # every page touched: resident
            block[offset] = 1
        grown = rss_bytes(os.getpid()) - before
    finally:
        block.close()
    assert grown == pytest.approx(BLOCK_BYTES, rel=0.1)


def test_rss_falls_back_to_vmrss_without_smaps_rollup_and_a_gone_process_raises(
        monkeypatch: pytest.MonkeyPatch) -> None:
    exact = rss_bytes(os.getpid())
    real = dds_soak._proc_kb

    def without_rollup(path: str, key: str) -> int:
        if path.endswith('smaps_rollup'):
            raise FileNotFoundError(path)  # a kernel before 4.14
        return real(path, key)

    monkeypatch.setattr(dds_soak, '_proc_kb', without_rollup)
    assert rss_bytes(os.getpid()) == pytest.approx(exact, rel=0.1)  # VmRSS: close, not exact
    monkeypatch.undo()
    gone = subprocess.Popen([sys.executable, '-c', 'pass'])
    gone.wait()
    with pytest.raises(FileNotFoundError):
        rss_bytes(gone.pid)


@pytest.mark.dds
def test_canary_is_counted_invalid_and_leaves_the_data_alone(ros_context: object) -> None:
    """The premise of the node-side loss estimate: a canary bumps `invalid` and nothing else."""
    from rclpy.parameter import Parameter

    from lf_predictor_ros.nodes.predictor_node import PredictorNode

    node = PredictorNode(context=ros_context, parameter_overrides=[Parameter('ndof', value=3)])
    try:
        for k in range(350):  # 3.5 s at 100 Hz: grid samples 0, 1, 2, 3
            msg = pose_to_msg([1.0 + 0.01 * k, 2.0, 0.1], k / 100.0)
            node.on_pose(msg)
            if k % 10 == 9:
                node.on_pose(canary_message(msg.header.stamp))
        _, _, values = node.diagnostic_values()
    finally:
        node.destroy_node()
    assert values['invalid'] == 35 and values['dropped'] == 35
    assert values['out_of_order'] == 0 and values['samples'] == 4 and values['gaps'] == 0
    assert values['callback_errors'] == 0


def test_config_rejects_nonsense() -> None:
    with pytest.raises(ValueError, match='speed must be a positive'):
        SoakConfig(speed=0.0)
    with pytest.raises(ValueError, match='canary_every must be >= 0'):
        SoakConfig(canary_every=-1)
    assert canary_message(sec_to_stamp(1.0)).pose.orientation.w == 1.0


@pytest.mark.dds
@pytest.mark.slow
def test_short_soak_through_dds_delivers_and_accounts_for_everything() -> None:
    result = run_soak(SoakConfig(minutes=SMOKE_MINUTES, speed=SMOKE_SPEED, rate=SMOKE_RATE))
    assert result.node_exit_code == 0
    assert result.poses_sent == 1498 and result.canaries_sent == 149  # t = 0 … 59.88 s
    assert result.achieved_speed == pytest.approx(SMOKE_SPEED, rel=0.05)
    # The node saw (nearly) every pose: canaries it did not count are the only losses.
    assert result.canaries_received <= result.canaries_sent
    assert result.node_pose_loss <= MAX_SMOKE_POSE_LOSS, result
    # The exact count agrees: every pose the node took was a real one, none twice.
    assert 0 < result.poses_accepted <= result.poses_sent
    assert result.pose_loss_exact == pytest.approx(1.0 - result.poses_accepted / 1498)
    assert result.pose_loss_exact <= MAX_SMOKE_POSE_LOSS, result
    # The real stream is clean: nothing dropped as out-of-order or outlier, no gap, no staleness.
    assert result.node_dropped == 0 and result.node_gaps == 0 and result.node_stale_thrust == 0
    assert result.node_callback_errors == 0
    # One prediction per grid sample the poses span, each received once, all finite.
    assert result.outputs == result.expected_outputs == result.node_samples == 59
    assert result.output_gaps == 0 and result.outputs_finite
    assert 100.0 < result.rss_start_mb <= result.rss_peak_mb  # torch is loaded: > 100 MB
    assert math.isfinite(result.cpu_s_per_sim_hour) and result.cpu_s_per_sim_hour > 0.0
