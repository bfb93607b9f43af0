"""Tests of the regressor and output range clip (``NumpyNnarmax.with_range``, regressor_clip)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from lf_predictor_ros.core.network import (
    NnarmaxNet,
    NnarmaxSpec,
    NumpyNnarmax,
    network_frame_regressors,
)
from lf_predictor_ros.core.params import PredictorParams
from lf_predictor_ros.core.regressors import build_regressors, rotate_blocks

LINEAR_1DOF = NnarmaxSpec(n_outputs=1, n_inputs_u=1, nu=1, ny=2, nfb=0, hidden_units=1,
                          hidden_layers=1, relative=True)
SPEC_3DOF = NnarmaxSpec(n_outputs=3, n_inputs_u=3, nu=2, ny=4, nfb=0, hidden_units=4,
                        hidden_layers=1, relative=True)


def _linear_net(bypass: list[float]) -> NumpyNnarmax:
    """A relative 1-DOF network ŷ(t + 1) = y(t) + b_u u(t) + b_0 · 0 + b_1 (y(t−1) − y(t)).

    Standardization mean 0 / std 1 and a zero tanh output, so the weights act on raw values.
    """
    net = NnarmaxNet(LINEAR_1DOF)
    with torch.no_grad():
        net.bypass.weight.copy_(torch.tensor([bypass], dtype=torch.float64))  # type: ignore[union-attr]
    return NumpyNnarmax.from_module(net)


def _window_rows() -> np.ndarray:
    """Raw rows [u(t), y(t), y(t−1)] with u ∈ [−1, 1] and y(t−1) − y(t) ∈ [−0.1, 0.2]."""
    return np.array([[-1.0, 5.0, 4.9], [1.0, 3.0, 3.2], [0.5, -2.0, -2.05], [0.0, 0.0, 0.0]])


def test_the_range_is_taken_in_the_network_frame() -> None:
    net = _linear_net([2.0, 0.0, 1.0]).with_range(_window_rows())
    assert net.regressor_range is not None and net.output_range is not None
    low, high = net.regressor_range
    # u, y(t) − y(t) (always 0), y(t−1) − y(t)
    np.testing.assert_allclose(low, [-1.0, 0.0, -0.1], atol=1e-12)
    np.testing.assert_allclose(high, [1.0, 0.0, 0.2], atol=1e-12)
    # the steps 2 u + (y(t−1) − y(t)) over the window: −2.1, 2.2, 0.95, 0
    np.testing.assert_allclose(net.output_range[0], [-2.1], atol=1e-12)
    np.testing.assert_allclose(net.output_range[1], [2.2], atol=1e-12)
    with pytest.raises(ValueError, match='read-only'):
        low[0] = 0.0


def test_the_clips_are_np_clip_value_for_value_nan_included() -> None:
    # the predict path clips with np.minimum(np.maximum(·)) (cheaper): np.clip's numbers
    net = NumpyNnarmax.from_module(NnarmaxNet(SPEC_3DOF, seed=2))
    rng = np.random.default_rng(6)
    clipped = net.with_range(rng.normal(size=(30, SPEC_3DOF.nu * 3 + SPEC_3DOF.ny * 3)))
    assert clipped.regressor_range is not None and clipped.output_range is not None
    rows = 4.0 * rng.normal(size=(40, clipped.regressor_range[0].size))  # far outside, too
    rows[3, 1] = np.nan
    plain = replace(clipped, regressor_range=None, output_range=None)
    expected = np.clip(plain._forward_absolute(np.clip(rows, *clipped.regressor_range)),
                       *clipped.output_range)
    np.testing.assert_array_equal(clipped._forward_absolute(rows), expected)  # NaN row too
    assert np.isnan(expected[3]).all() and np.isfinite(np.delete(expected, 3, axis=0)).all()


def test_rows_of_the_window_are_predicted_exactly_as_without_the_clip() -> None:
    plain = _linear_net([2.0, 0.0, 1.0])
    rows = _window_rows()
    np.testing.assert_array_equal(plain.with_range(rows).forward(rows), plain.forward(rows))


def test_a_row_beyond_the_window_reaches_the_network_as_the_window_edge() -> None:
    net = _linear_net([2.0, 0.0, 1.0]).with_range(_window_rows())
    # a 'turn': y(t−1) − y(t) = 3 (window at most 0.2) and a force of 40 (window at most 1)
    row = np.array([40.0, 10.0, 13.0])
    # clipped regressors: u 1, relative 0.2 → step 2 · 1 + 0.2 = 2.2 (inside the output range)
    assert net.forward(row)[0] == pytest.approx(10.0 + 2.2, abs=1e-12)
    assert _linear_net([2.0, 0.0, 1.0]).forward(row)[0] == pytest.approx(10.0 + 83.0, abs=1e-12)
    # u −1 with relative −0.1 → step −2.1, the window's lowest: still inside
    assert net.forward(np.array([-7.0, 1.0, -4.0]))[0] == pytest.approx(1.0 - 2.1, abs=1e-12)


def test_the_output_clip_bounds_corners_the_window_never_showed() -> None:
    # b_1 = −10: the window's steps are 2u − 10 r = −1, 0, 1.5, 0 → range [−1, 1.5]
    rows = _window_rows()
    net = _linear_net([2.0, 0.0, -10.0]).with_range(rows)
    assert net.output_range is not None
    np.testing.assert_allclose([net.output_range[0][0], net.output_range[1][0]], [-1.0, 1.5],
                               atol=1e-12)
    # u 1 with r −0.1 is a corner of the box no window row had: 2 + 1 = 3 → clipped to 1.5
    assert net.forward(np.array([1.0, 0.0, -0.1]))[0] == pytest.approx(1.5, abs=1e-12)
    assert net.forward(np.array([-1.0, 0.0, 0.2]))[0] == pytest.approx(-1.0, abs=1e-12)


def test_with_range_refuses_rows_it_cannot_bound() -> None:
    net = _linear_net([2.0, 0.0, 1.0])
    with pytest.raises(ValueError, match='finite regressor rows'):
        net.with_range(np.empty((0, 3)))
    with pytest.raises(ValueError, match='finite regressor rows'):
        net.with_range(np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ValueError, match='finite regressor rows'):
        net.with_range(np.zeros(3))


def _series(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = rng.normal(scale=[2e5, 1e5, 3e6], size=(n, 3))
    y = np.cumsum(rng.normal(scale=[0.2, 0.2, 0.01], size=(n, 3)), axis=0) + [12.0, -4.0, 0.3]
    return u, y


def _random_net(spec: NnarmaxSpec, seed: int) -> NumpyNnarmax:
    net = NnarmaxNet(spec, seed=seed)
    u, y = _series(300, seed)
    net.set_standardization(u, y, preserve_function=False)
    generator = torch.Generator().manual_seed(seed + 100)
    with torch.no_grad():
        for param in net.parameters():
            param.add_(0.1 * torch.randn(param.shape, generator=generator, dtype=param.dtype))
    return NumpyNnarmax.from_module(net)


def test_body_frame_clip_keeps_the_rotation_invariance() -> None:
    spec = replace(SPEC_3DOF, body_frame=True)
    net = _random_net(spec, 3)
    u, y = _series(200, 4)
    x, _ = build_regressors(u, y, y, spec)
    clipped = net.with_range(x)
    # a turn far beyond the window: heading 1 rad in 4 samples, forces ×20
    u_turn = 20.0 * u[:4]
    y_turn = y[:4] + np.array([[0.0, 0.0, 0.25 * k] for k in range(4)])
    row = build_regressors(u_turn, y_turn, y_turn, spec)[0][-1]
    angle = 0.7
    c, s = np.cos(angle), np.sin(angle)
    turned_u = rotate_blocks(u_turn, c, s)
    turned_y = rotate_blocks(y_turn, c, s) + [0.0, 0.0, angle]
    turned_row = build_regressors(turned_u, turned_y, turned_y, spec)[0][-1]
    expected = rotate_blocks(clipped.forward(row)[None, :], c, s)[0] + [0.0, 0.0, angle]
    np.testing.assert_allclose(clipped.forward(turned_row), expected, atol=1e-9)
    # and the clip acted: the unclipped network extrapolates elsewhere
    assert np.abs(net.forward(row) - clipped.forward(row)).max() > 1e-3
    frame = network_frame_regressors(spec, row[None, :])[0]
    assert clipped.regressor_range is not None
    assert np.any(frame > clipped.regressor_range[1]) or np.any(frame < clipped.regressor_range[0])


def test_widen_scales_each_range_about_its_centre() -> None:
    net = _linear_net([2.0, 0.0, 1.0]).with_range(_window_rows(), widen=3.0)
    assert net.regressor_range is not None and net.output_range is not None
    # u [−1, 1] → [−3, 3]; y(t−1) − y(t) [−0.1, 0.2] → centre 0.05, half 0.45;
    # the step [−2.1, 2.2] → [−6.4, 6.5]
    np.testing.assert_allclose(net.regressor_range[0], [-3.0, 0.0, -0.4], atol=1e-12)
    np.testing.assert_allclose(net.regressor_range[1], [3.0, 0.0, 0.5], atol=1e-12)
    np.testing.assert_allclose([net.output_range[0][0], net.output_range[1][0]], [-6.4, 6.5],
                               atol=1e-12)
    # a force of 2 and a relative 0.4 now pass: 2 · 2 + 0.4
    assert net.forward(np.array([2.0, 0.0, 0.4]))[0] == pytest.approx(4.4, abs=1e-12)
    with pytest.raises(ValueError, match='widen must be ≥ 1'):
        _linear_net([2.0, 0.0, 1.0]).with_range(_window_rows(), widen=0.5)


def test_regressor_clip_is_off_or_at_least_one() -> None:
    assert PredictorParams().regressor_clip == 0.0
    assert PredictorParams(regressor_clip=2.0).regressor_clip == 2.0
    for bad in (0.5, -1.0, 0.999):
        with pytest.raises(ValueError, match='regressor_clip must be 0'):
            PredictorParams(regressor_clip=bad)


def test_the_ranges_round_trip_through_checkpoint_meta_and_a_misfit_is_dropped() -> None:
    clipped = _linear_net([2.0, 0.0, 1.0]).with_range(_window_rows())
    meta = clipped.range_meta()
    restored = _linear_net([2.0, 0.0, 1.0]).with_saved_ranges(meta)
    assert restored.regressor_range is not None and restored.output_range is not None
    for a, b in zip(restored.regressor_range + restored.output_range,
                    clipped.regressor_range + clipped.output_range, strict=True):  # type: ignore[operator]
        np.testing.assert_array_equal(a, b)
    assert _linear_net([2.0, 0.0, 1.0]).range_meta() == {}
    for bad in ({}, {**meta, 'output_range': [[0.0, 1.0], [1.0, 2.0]]},
                {**meta, 'regressor_range': [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]}):
        assert _linear_net([2.0, 0.0, 1.0]).with_saved_ranges(bad).regressor_range is None
