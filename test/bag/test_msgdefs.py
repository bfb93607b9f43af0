"""msgdefs: full ros2msg definition text as rosbag2 builds it."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from lf_predictor_ros.bag.msgdefs import (
    DELIMITER,
    MessageDefinitionError,
    full_definition,
    msg_dependencies,
    split_type_name,
)

pytestmark = pytest.mark.filterwarnings('ignore::DeprecationWarning:lark.*')


def _share(type_name: str) -> Path:
    package, interface, name = split_type_name(type_name)
    for prefix in os.environ['AMENT_PREFIX_PATH'].split(os.pathsep):
        path = Path(prefix) / 'share' / package / interface / f'{name}.msg'
        if path.is_file():
            return path
    raise AssertionError(f'{type_name} not installed')


def _sections(text: str) -> list[str]:
    """Type names of the appended dependency sections, in order."""
    return [part.split('\n', 1)[0].removeprefix('MSG: ')
            for part in text.split('\n' + DELIMITER)[1:]]


def test_pose_stamped_layout_matches_rosbag2_depth_first_sorted_order() -> None:
    text = full_definition('geometry_msgs/msg/PoseStamped')
    root = _share('geometry_msgs/msg/PoseStamped').read_text()
    assert text.startswith(root)
    # rosbag2: dependencies of each type sorted by name, depth first, every type once.
    assert _sections(text) == ['geometry_msgs/Pose', 'geometry_msgs/Point',
                               'geometry_msgs/Quaternion', 'std_msgs/Header',
                               'builtin_interfaces/Time']
    assert '\n' + '=' * 80 + '\nMSG: std_msgs/Header\n' in text
    header_section = text.split('MSG: std_msgs/Header\n', 1)[1].split('\n' + DELIMITER)[0]
    assert header_section == _share('std_msgs/msg/Header').read_text()


def test_rosbags_parses_the_text_into_the_jazzy_field_definitions() -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    for type_name in ('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/WrenchStamped',
                      'diagnostic_msgs/msg/DiagnosticArray', 'rosgraph_msgs/msg/Clock',
                      'nav_msgs/msg/Odometry'):
        parsed = get_types_from_msg(full_definition(type_name), type_name)
        assert type_name in parsed
        for name, definition in parsed.items():
            assert store.fielddefs[name] == definition, name


def test_each_dependency_appears_once_for_nested_arrays() -> None:
    text = full_definition('diagnostic_msgs/msg/DiagnosticArray')
    sections = _sections(text)
    assert sections == ['diagnostic_msgs/DiagnosticStatus', 'diagnostic_msgs/KeyValue',
                        'std_msgs/Header', 'builtin_interfaces/Time']
    assert len(sections) == len(set(sections))


def test_short_type_name_and_cache() -> None:
    long_form = full_definition('std_msgs/msg/Float64')
    assert full_definition('std_msgs/Float64') == long_form
    assert long_form == _share('std_msgs/msg/Float64').read_text()  # no dependencies
    assert long_form.endswith('float64 data\n') and DELIMITER not in long_form
    assert full_definition('std_msgs/msg/Float64') is long_form


def test_relative_header_time_and_bounded_types_resolve(tmp_path: Path) -> None:
    msg_dir = tmp_path / 'share' / 'my_pkg' / 'msg'
    msg_dir.mkdir(parents=True)
    (msg_dir / 'Thing.msg').write_text(
        '# comment line with Words in it\n'
        'Header header\n'
        'time stamp\n'
        'Other[] others\n'
        'Other[<=3] bounded_others\n'
        'string<=5 short_name\n'
        'int32[4] fixed\n'
        'uint8 MODE_A=1\n')
    (msg_dir / 'Other.msg').write_text('float64 value\n')
    assert msg_dependencies((msg_dir / 'Thing.msg').read_text(), 'my_pkg') == [
        'builtin_interfaces/Time', 'my_pkg/Other', 'std_msgs/Header']
    prefixes = [str(tmp_path), *os.environ['AMENT_PREFIX_PATH'].split(os.pathsep)]
    text = full_definition('my_pkg/msg/Thing', prefixes)
    assert _sections(text) == ['builtin_interfaces/Time', 'my_pkg/Other', 'std_msgs/Header']
    assert text.count('MSG: builtin_interfaces/Time') == 1  # Header's Time is not repeated


def test_missing_type_and_bad_names_raise_value_errors(tmp_path: Path) -> None:
    with pytest.raises(MessageDefinitionError, match='no nonexistent_msgs/msg/Nope.msg'):
        full_definition('nonexistent_msgs/msg/Nope')
    with pytest.raises(ValueError, match='pkg/msg/Type'):
        full_definition('PoseStamped')
    msg_dir = tmp_path / 'share' / 'broken_pkg' / 'msg'
    msg_dir.mkdir(parents=True)
    (msg_dir / 'Broken.msg').write_text('Missing field\n')
    with pytest.raises(MessageDefinitionError, match='broken_pkg/msg/Missing.msg'):
        full_definition('broken_pkg/msg/Broken', [str(tmp_path)])
