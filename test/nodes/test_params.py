"""declare_and_load / validated_update / LiveParameters on a real rclpy node (no DDS traffic).

The tests share one context whose participant lives for the whole module (`params_context`):
each test's node is created and destroyed within milliseconds, and a participant deleted that
young can meet Fast DDS 2.14's busy-wait for an in-flight discovery callback in
``DomainParticipant::set_listener`` (eProsima/Fast-DDS#6513). A fresh-clone run spun there for
good in the second test of this file (gdb: inside ``rcl_node_fini``, with the GIL held, where no
pytest timeout can end it), and CI later hung at the same test (docs/BENCHMARKS.md,
twenty-fourth and thirtieth sessions).
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter

from lf_predictor_ros.nodes.params import (
    LiveParameters,
    declare_and_load,
    field_specs,
    validated_update,
)


@dataclass(frozen=True)
class ExampleConfig:
    """A config with every supported field type."""

    bandwidth: float = field(default=0.1, metadata={'doc': 'closed-loop bandwidth',
                                                     'unit': 'rad/s'})
    seed: int = field(default=3, metadata={'doc': 'RNG seed', 'read_only': True})
    lockstep: bool = False
    scenario: str = 'supply_closed_loop'
    setpoint: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    topics: list[str] = field(default_factory=list)
    mass_diag: tuple[float, ...] = (6.7644e6, 1.1341e7, 4.4524e9)

    def __post_init__(self) -> None:
        if not self.bandwidth > 0.0:
            raise ValueError(f'bandwidth must be > 0 rad/s, got {self.bandwidth}; use e.g. 0.1')
        if len(self.setpoint) != 3:
            raise ValueError('setpoint must have 3 elements [north, east, yaw]')


def _node(context: object, overrides: list[Parameter] | None = None) -> Node:
    return Node('params_test', context=context, parameter_overrides=overrides or [],
                start_parameter_services=False)


@pytest.fixture(scope='module')
def params_context(ros_module_context: object) -> Iterator[object]:
    """The module's rclpy context; an idle node keeps its one DDS participant alive.

    rmw_fastrtps deletes a context's participant with its last node, so without the anchor
    every test's short-lived node would create and delete a participant (module docstring).
    """
    anchor = Node('params_test_anchor', context=ros_module_context,
                  start_parameter_services=False)
    try:
        yield ros_module_context
    finally:
        anchor.destroy_node()


@pytest.fixture
def node(params_context: object) -> Iterator[Node]:
    n = _node(params_context)
    yield n
    n.destroy_node()


def test_defaults_are_declared_with_descriptions(node: Node) -> None:
    config = declare_and_load(node, ExampleConfig)
    assert config == ExampleConfig()
    assert node.get_parameter('bandwidth').value == 0.1
    assert list(node.get_parameter('mass_diag').value) == [6.7644e6, 1.1341e7, 4.4524e9]
    descriptor = node.describe_parameter('bandwidth')
    assert descriptor.description == 'closed-loop bandwidth [rad/s]'
    assert node.describe_parameter('seed').read_only
    assert node.describe_parameter('lockstep').description == 'lockstep'


def test_overrides_are_loaded_and_converted(params_context: object) -> None:
    overrides = [
        Parameter('ctl.bandwidth', value=2),  # an INTEGER on the command line -> float
        Parameter('ctl.setpoint', value=[10, -5, 1]),
        Parameter('ctl.topics', value=['a', 'b']),
        Parameter('ctl.mass_diag', value=[1.0, 2.0, 3.0]),
        Parameter('ctl.lockstep', value=True),
    ]
    n = _node(params_context, overrides)
    try:
        config = declare_and_load(n, ExampleConfig, prefix='ctl')
    finally:
        n.destroy_node()
    assert config.bandwidth == 2.0 and isinstance(config.bandwidth, float)
    assert config.setpoint == [10.0, -5.0, 1.0]
    assert all(isinstance(v, float) for v in config.setpoint)
    assert config.topics == ['a', 'b']
    assert config.mass_diag == (1.0, 2.0, 3.0)
    assert config.lockstep is True
    assert config.seed == 3


def test_invalid_startup_value_raises_the_dataclass_message(params_context: object) -> None:
    n = _node(params_context, [Parameter('bandwidth', value=-0.5)])
    try:
        with pytest.raises(ValueError, match=r'bandwidth must be > 0 rad/s, got -0\.5'):
            declare_and_load(n, ExampleConfig)
    finally:
        n.destroy_node()


def test_wrong_type_names_the_parameter(params_context: object) -> None:
    n = _node(params_context, [Parameter('seed', value='seven')])
    try:
        with pytest.raises(ValueError, match="parameter 'seed' must be of type integer"):
            declare_and_load(n, ExampleConfig)
    finally:
        n.destroy_node()


def test_validated_update_accepts_and_rejects() -> None:
    current = ExampleConfig()
    new, reason = validated_update(current, [Parameter('bandwidth', value=0.25),
                                             Parameter('unrelated', value=1)])
    assert new is not None and reason == ''
    assert new.bandwidth == 0.25 and current.bandwidth == 0.1
    same, reason = validated_update(current, [Parameter('other.bandwidth', value=-1.0)])
    assert same is current and reason == ''
    bad, reason = validated_update(current, [Parameter('bandwidth', value=0.0)])
    assert bad is None and 'bandwidth must be > 0 rad/s' in reason
    bad, reason = validated_update(current, [Parameter('setpoint', value=[1.0, 2.0])])
    assert bad is None and 'setpoint must have 3 elements' in reason
    bad, reason = validated_update(current, [Parameter('lockstep', value=1)])
    assert bad is None and "'lockstep' must be of type bool" in reason


def test_runtime_set_is_validated_by_live_parameters(node: Node) -> None:
    seen: list[float] = []
    live = LiveParameters(node, ExampleConfig, on_change=lambda c: seen.append(c.bandwidth))
    result = node.set_parameters([Parameter('bandwidth', value=-1.0)])[0]
    assert not result.successful
    assert 'bandwidth must be > 0 rad/s, got -1.0' in result.reason
    assert live.value.bandwidth == 0.1 and node.get_parameter('bandwidth').value == 0.1
    result = node.set_parameters([Parameter('bandwidth', value=0.3)])[0]
    assert result.successful
    assert live.value.bandwidth == 0.3 and seen == [0.3]
    result = node.set_parameters([Parameter('seed', value=9)])[0]
    assert not result.successful and 'read-only' in result.reason
    assert live.value.seed == 3


def test_unsupported_field_type_is_a_type_error() -> None:
    @dataclass(frozen=True)
    class Bad:
        gains: dict[str, float] = field(default_factory=dict)

    with pytest.raises(TypeError, match='cannot be a ROS parameter'):
        field_specs(Bad)


def test_runtime_defaults_replace_dataclass_defaults_not_overrides(params_context: object) -> None:
    n = _node(params_context, [Parameter('setpoint', value=[1.0, 2.0, 3.0])])
    try:
        config = declare_and_load(n, ExampleConfig, defaults={'bandwidth': 0.7,
                                                              'setpoint': [9.0, 9.0, 9.0]})
        assert config.bandwidth == 0.7  # from defaults
        assert config.setpoint == [1.0, 2.0, 3.0]  # the override wins
        assert n.get_parameter('bandwidth').value == 0.7
        with pytest.raises(ValueError, match='unknown fields'):
            declare_and_load(n, ExampleConfig, prefix='x', defaults={'bandwith': 0.7})
    finally:
        n.destroy_node()
