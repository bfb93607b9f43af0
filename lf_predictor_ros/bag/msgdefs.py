"""Full `ros2msg` message definition text, exactly as rosbag2 stores it in an MCAP schema.

ROS-free: reads the `.msg` files installed under `share/<pkg>/msg/` of every prefix on
`AMENT_PREFIX_PATH` (the same place `ament_index` looks).

The text is the root type's `.msg` file followed, for every dependency in depth-first order
(each package's dependencies sorted by name, every type once), by a newline, a line of 80 `=`,
a line `MSG: pkg/Type` and that type's `.msg` file. This is rosbag2's
`LocalMessageDefinitionSource::get_full_text` (rosbag2_cpp, Jazzy) and the layout MCAP's
`ros2msg` schema encoding documents, so Foxglove, `ros2 bag` and `rosbags` parse it.

Type references inside a `.msg` file resolve like rosidl does: a bare name (`Pose`) lives in the
same package, `Header` is `std_msgs/Header`, and the ROS 1 builtins `time` / `duration` are
`builtin_interfaces/Time` / `Duration`.
"""
from __future__ import annotations

from collections.abc import Sequence
import functools
import os
from pathlib import Path
import re

DELIMITER = '=' * 80 + '\n'

# Builtin field types of the ROS 2 .msg format (rosidl_adapter), never a dependency.
PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring',
})

# Names that resolve to a fixed type whatever package mentions them (rosidl_adapter rules).
_SPECIAL_TYPES = {
    'Header': 'std_msgs/Header',
    'time': 'builtin_interfaces/Time',
    'duration': 'builtin_interfaces/Duration',
}

# A field type at the start of a line: "pkg/Type[] name", "Type name", "uint8[<=3] name".
# Same pattern as rosbag2's MSG_FIELD_TYPE_REGEX.
_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_ROS_NAME = r'[a-zA-Z][a-zA-Z0-9_]*'
_TYPE_NAME = re.compile(rf'^({_ROS_NAME})/(?:({_ROS_NAME})/)?({_ROS_NAME})$')

# Bound on dependency nesting, as rosbag2 (ROS2_CPP_..._MAX_RECURSION_DEPTH = 50).
_MAX_DEPTH = 50


class MessageDefinitionError(ValueError):
    """A message type's definition cannot be found or resolved."""


def split_type_name(type_name: str) -> tuple[str, str, str]:
    """Split `pkg/msg/Type` (or `pkg/Type`) into `(pkg, 'msg', Type)`."""
    match = _TYPE_NAME.match(type_name)
    if match is None:
        raise MessageDefinitionError(
            f'message type name {type_name!r} is not of the form pkg/msg/Type or pkg/Type; '
            'write it like geometry_msgs/msg/PoseStamped')
    package, interface, name = match.group(1), match.group(2) or 'msg', match.group(3)
    return package, interface, name


def ament_prefixes() -> tuple[str, ...]:
    """Install prefixes from `AMENT_PREFIX_PATH`, in search order."""
    return tuple(p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p)


def find_msg_file(type_name: str, prefixes: Sequence[str]) -> Path:
    """Path of the `.msg` file of `type_name` in the first prefix that has it."""
    package, interface, name = split_type_name(type_name)
    for prefix in prefixes:
        candidate = Path(prefix) / 'share' / package / interface / f'{name}.msg'
        if candidate.is_file():
            return candidate
    raise MessageDefinitionError(
        f'no {package}/{interface}/{name}.msg under share/ of any AMENT_PREFIX_PATH entry '
        f'({list(prefixes)}); install the message package or source its setup file')


def msg_dependencies(text: str, package: str) -> list[str]:
    """Sorted non-primitive types (`pkg/Type`) that the fields of a `.msg` text use."""
    found: set[str] = set()
    for match in _FIELD_TYPE.finditer(text):
        field_type = match.group(1)
        if field_type in PRIMITIVE_TYPES:
            continue
        if field_type in _SPECIAL_TYPES:
            found.add(_SPECIAL_TYPES[field_type])
        elif '/' in field_type:
            found.add(field_type)
        else:
            found.add(f'{package}/{field_type}')
    return sorted(found)


def full_definition(type_name: str, prefixes: Sequence[str] | None = None) -> str:
    """The complete `ros2msg` schema text of `type_name` (e.g. `geometry_msgs/msg/PoseStamped`).

    `prefixes` defaults to `AMENT_PREFIX_PATH`. Results are cached per (type, prefixes).
    Raises MessageDefinitionError (a ValueError) when a type or a dependency is not installed.
    """
    search = tuple(prefixes) if prefixes is not None else ament_prefixes()
    return _full_definition_cached(type_name, search)


@functools.lru_cache(maxsize=256)
def _full_definition_cached(type_name: str, prefixes: tuple[str, ...]) -> str:
    seen: set[str] = set()

    def append_recursive(name: str, depth: int) -> str:
        if depth <= 0:
            raise MessageDefinitionError(
                f'dependencies of {type_name} nest deeper than {_MAX_DEPTH}; '
                'check the .msg files for a cycle')
        text = find_msg_file(name, prefixes).read_text(encoding='utf-8')
        result = text
        for dependency in msg_dependencies(text, split_type_name(name)[0]):
            if dependency in seen:
                continue
            seen.add(dependency)
            result += '\n' + DELIMITER + f'MSG: {dependency}\n'
            result += append_recursive(dependency, depth - 1)
        return result

    return append_recursive(type_name, _MAX_DEPTH)
