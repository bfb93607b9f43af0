"""ROS parameters from a frozen, validated dataclass: declare, load once, reject bad updates.

A node keeps its configuration in a frozen dataclass whose fields have defaults and whose
``__post_init__`` raises ``ValueError`` for invalid values. Documentation goes in the field's
metadata::

    @dataclass(frozen=True)
    class ControllerConfig:
        bandwidth: float = field(default=0.1, metadata={'doc': 'closed-loop bandwidth',
                                                         'unit': 'rad/s'})
        seed: int = field(default=0, metadata={'doc': 'RNG seed', 'read_only': True})

``declare_and_load(node, ControllerConfig)`` declares one parameter per field (default value,
``ParameterDescriptor`` with the description ``'closed-loop bandwidth [rad/s]'``) and returns the
validated instance; ``validated_update`` checks a runtime change for an
``add_on_set_parameters_callback``; ``LiveParameters`` wires both together.

Supported field types: ``float``, ``int``, ``bool``, ``str`` and ``list[...]`` / ``tuple[...,
...]`` of them. Parameters are declared with dynamic typing and converted here, so
``-p speed_factor:=2`` (an INTEGER on the command line) sets a ``float`` field instead of failing
with ROS's "expecting type DOUBLE"; anything that cannot be converted is rejected with a message
naming the parameter. Read-only fields (``metadata={'read_only': True}``) are enforced by ROS.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
import dataclasses
from typing import TYPE_CHECKING, Any, Generic, TypeVar, get_args, get_origin, get_type_hints

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

ConfigT = TypeVar('ConfigT', bound='DataclassInstance')

_SCALARS: dict[type, str] = {float: 'double', int: 'integer', bool: 'bool', str: 'string'}


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """How one dataclass field maps to a ROS parameter."""

    field: str
    element: type  # float, int, bool or str
    container: type | None  # None (scalar), list or tuple
    default: Any
    description: str
    read_only: bool


def param_meta(doc: str, unit: str = '', read_only: bool = False) -> dict[str, Any]:
    """Field metadata for a node's config dataclass: description, unit, read-only flag.

    `declare_and_load` turns it into the parameter's descriptor:
    ``field(default=1.0, metadata=param_meta('command timeout', 's'))``.
    """
    meta: dict[str, Any] = {'doc': doc, 'read_only': read_only}
    if unit:
        meta['unit'] = unit
    return meta


def _parse_type(hint: Any, owner: str, name: str) -> tuple[type, type | None]:
    """Return (element type, container) of a supported annotation, or raise TypeError."""
    if hint in _SCALARS:
        return hint, None
    origin, args = get_origin(hint), get_args(hint)
    if origin is list and len(args) == 1 and args[0] in _SCALARS:
        return args[0], list
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis and args[0] in _SCALARS:
        return args[0], tuple
    raise TypeError(
        f'{owner}.{name}: type {hint!r} cannot be a ROS parameter; use float, int, bool, str, '
        'list[T] or tuple[T, ...] of those')


def _default_of(field: dataclasses.Field[Any], owner: str) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    raise TypeError(f'{owner}.{field.name} needs a default value to be declared as a parameter')


def field_specs(cls: type[Any]) -> list[FieldSpec]:
    """Describe the init fields of a dataclass type as ROS parameters."""
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f'{cls!r} is not a dataclass type')
    hints = get_type_hints(cls)
    specs = []
    for field in dataclasses.fields(cls):
        if not field.init:
            continue
        element, container = _parse_type(hints[field.name], cls.__name__, field.name)
        doc = str(field.metadata.get('doc', field.name.replace('_', ' ')))
        unit = field.metadata.get('unit')
        specs.append(FieldSpec(
            field=field.name,
            element=element,
            container=container,
            default=_default_of(field, cls.__name__),
            description=f'{doc} [{unit}]' if unit else doc,
            read_only=bool(field.metadata.get('read_only', False)),
        ))
    return specs


def _full_name(prefix: str, field: str) -> str:
    if not prefix:
        return field
    return f'{prefix}{field}' if prefix.endswith('.') else f'{prefix}.{field}'


def _convert_scalar(value: Any, element: type, name: str) -> Any:
    if element is float and isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if element is int and isinstance(value, int) and not isinstance(value, bool):
        return int(value)
    if element is bool and isinstance(value, bool):
        return value
    if element is str and isinstance(value, str):
        return value
    raise ValueError(
        f"parameter '{name}' must be of type {_SCALARS[element]}, got {value!r} "
        f'({type(value).__name__}); set it with the right type, e.g. 1.0 rather than "1.0"')


def convert_value(value: Any, spec: FieldSpec, name: str) -> Any:
    """Convert a ROS parameter value to the field's Python type, or raise ValueError."""
    if spec.container is None:
        return _convert_scalar(value, spec.element, name)
    if value is None or isinstance(value, str | bytes) or not isinstance(value, Iterable):
        raise ValueError(
            f"parameter '{name}' must be of type {_SCALARS[spec.element]} array, got {value!r}")
    items = [_convert_scalar(item, spec.element, f'{name}[{i}]') for i, item in enumerate(value)]
    return spec.container(items)


def _ros_default(spec: FieldSpec) -> Any:
    """Default as ROS wants it: sequences as lists."""
    return list(spec.default) if spec.container is not None else spec.default


def _descriptor(spec: FieldSpec, name: str, note: str = '') -> ParameterDescriptor:
    return ParameterDescriptor(
        name=name,
        description=spec.description + note,
        read_only=spec.read_only,
        dynamic_typing=True,  # converted and checked by convert_value
    )


def _with_defaults(specs: list[FieldSpec], defaults: Mapping[str, Any] | None) -> list[FieldSpec]:
    """Replace the dataclass defaults by ``defaults`` (e.g. values taken from a scenario)."""
    if not defaults:
        return specs
    unknown = set(defaults) - {spec.field for spec in specs}
    if unknown:
        raise ValueError(f'defaults for unknown fields {sorted(unknown)}; known: '
                         f'{[spec.field for spec in specs]}')
    return [dataclasses.replace(spec, default=convert_value(defaults[spec.field], spec,
                                                            spec.field))
            if spec.field in defaults else spec for spec in specs]


def declare_and_load(
    node: Node, cls: type[ConfigT], prefix: str = '', defaults: Mapping[str, Any] | None = None,
    note: Callable[[str], str] | None = None,
) -> ConfigT:
    """Declare every field of ``cls`` on ``node`` and return the validated instance.

    ``defaults`` (field name → value) replaces dataclass defaults, e.g. with values computed at
    start-up; ``note(field)`` is appended to a parameter's description (e.g. what a run-time
    change does). Overrides (``-p``, ``--params-file``, ``parameter_overrides``) are applied by ROS
    at declaration. Raises ``ValueError`` with the dataclass's own message when the loaded values
    are invalid; the node should log it and exit non-zero.
    """
    values: dict[str, Any] = {}
    for spec in _with_defaults(field_specs(cls), defaults):
        name = _full_name(prefix, spec.field)
        parameter = node.declare_parameter(
            name, _ros_default(spec), _descriptor(spec, name, note(spec.field) if note else ''))
        values[spec.field] = convert_value(parameter.value, spec, name)
    return cls(**values)


def parameter_table(classes: Sequence[type[Any]]) -> str:
    """One line per ROS parameter of ``classes``: name, default, description [unit] (--help).

    Float lists are shown with 6 significant digits (defaults computed from physics are long).
    """
    lines = []
    for cls in classes:
        for spec in field_specs(cls):
            default = spec.default
            if spec.container is not None:
                default = [float(f'{v:.6g}') for v in default] if spec.element is float \
                    else list(default)
            flag = ' (read-only)' if spec.read_only else ''
            lines.append(f'  {spec.field:<24} {default!r:<18} {spec.description}{flag}')
    return '\n'.join(lines)


def validated_update(
    current: ConfigT, params: Sequence[Parameter], prefix: str = '',
) -> tuple[ConfigT | None, str]:
    """Apply a runtime parameter change to ``current`` if the result is valid.

    Returns ``(new_instance, '')`` (``current`` itself when no parameter belongs to it) or
    ``(None, reason)``, the reason being the conversion or ``__post_init__`` error message.
    """
    by_name = {_full_name(prefix, spec.field): spec for spec in field_specs(type(current))}
    changes: dict[str, Any] = {}
    for parameter in params:
        spec = by_name.get(parameter.name)
        if spec is None:
            continue
        try:
            changes[spec.field] = convert_value(parameter.value, spec, parameter.name)
        except ValueError as error:
            return None, str(error)
    if not changes:
        return current, ''
    try:
        return dataclasses.replace(current, **changes), ''
    except ValueError as error:
        return None, str(error)


class LiveParameters(Generic[ConfigT]):
    """A node's validated configuration that follows accepted runtime parameter changes.

    Declares and loads ``cls`` (``ValueError`` on invalid startup values; ``defaults`` as in
    ``declare_and_load``), then registers an
    on-set-parameters callback that rejects invalid changes with the reason and otherwise
    replaces ``value`` and calls ``on_change(new_value)``.
    """

    def __init__(
        self,
        node: Node,
        cls: type[ConfigT],
        prefix: str = '',
        on_change: Callable[[ConfigT], None] | None = None,
        defaults: Mapping[str, Any] | None = None,
    ) -> None:
        self._prefix = prefix
        self._on_change = on_change
        self._value = declare_and_load(node, cls, prefix, defaults)
        node.add_on_set_parameters_callback(self._on_set_parameters)

    @property
    def value(self) -> ConfigT:
        """The current validated configuration."""
        return self._value

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        new_value, reason = validated_update(self._value, params, self._prefix)
        if new_value is None:
            return SetParametersResult(successful=False, reason=reason)
        if new_value is not self._value:
            self._value = new_value
            if self._on_change is not None:
                self._on_change(new_value)
        return SetParametersResult(successful=True, reason='')
