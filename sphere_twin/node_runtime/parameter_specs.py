"""A node's parameters as data, and their one declaration: every check of a value is here.

:class:`ParameterSpec` says what a parameter is (name, type, default, range, choices,
description) without ROS, so ``sphere_twin.nodes.parameters`` can list every node's parameters
and the tests can read them without rclpy. :func:`declare_node_parameters` declares a node's
specs on the node, refuses a parameter the node does not have, and checks each value (type,
finite, range, choices, length, rule), raising :class:`~sphere_twin.node_runtime.ros_env.
StartupError` with the one line the node prints. :func:`parameters_help` is what an
executable's ``--help`` prints.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rcl_interfaces.msg import ParameterDescriptor


class StartupError(ValueError):
    """A node cannot start with the parameters or files it was given."""


class ParameterType(enum.Enum):
    """The ROS type of a parameter (the names of ``rclpy.parameter.Parameter.Type``)."""

    BOOL = 'bool'
    INTEGER = 'integer'
    DOUBLE = 'double'
    STRING = 'string'
    DOUBLE_ARRAY = 'double_array'
    STRING_ARRAY = 'string_array'


# Why most parameters are read-only: the node builds its plant, tables or files from them once.
READ_AT_START = 'read once at start-up (what it builds cannot change under a running node)'
SETTABLE = 'can be set while the node runs (ros2 param set), checked as at start-up'

# What a parameter's default may be; arrays are tuples here and lists once declared.
ParameterValue = bool | int | float | str | tuple[float, ...] | tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class ParameterSpec:
    """One parameter of a node, without ROS: what :func:`declare_node_parameters` declares.

    Attributes
    ----------
    name : str
    type : ParameterType
    default : bool, int, float, str, tuple or None
        None declares the parameter by its type alone (its value is None until it is set).
    description : str
    range : (low, high), optional
        Inclusive bounds of an integer or double parameter.
    choices : tuple of str, optional
        The values a string parameter takes (said in ``description``; checked when declared).
    read_only : bool
        False for a parameter the node takes again at run time (``ros2 param set``), checked
        as at start-up; a read-only one says why in ``fixed_because``.
    fixed_because : str
        Why a read-only parameter cannot change while the node runs (its descriptor's
        ``additional_constraints``, which ``ros2 param describe`` shows).
    length : int, optional
        How many values an array parameter holds (checked when declared).
    rule : callable, optional
        ``rule(value) -> str or None``: a further condition the declared value meets, for what
        a range cannot say (a point inside the unit disk); returns what is wrong with
        ``value``, after ``parameter <name> = <value>``, or None.
    """

    name: str
    type: ParameterType
    default: ParameterValue | None
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None
    read_only: bool = True
    fixed_because: str = READ_AT_START
    length: int | None = None
    rule: Callable[[Any], str | None] | None = None


def spec_descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    """The ``ParameterDescriptor`` of ``spec``: description, range, read-only and why."""
    bounds = spec.range
    descriptor = parameter_descriptor(
        spec.description,
        float_range=bounds if spec.type is ParameterType.DOUBLE else None,
        int_range=((int(bounds[0]), int(bounds[1]))
                   if bounds is not None and spec.type is ParameterType.INTEGER else None),
        read_only=spec.read_only)
    descriptor.additional_constraints = (f'read-only: {spec.fixed_because}' if spec.read_only
                                         else SETTABLE)
    return descriptor


def accept_parameter_changes(node: Any, specs: Iterable[ParameterSpec],
                             apply: Callable[[str, Any], None],
                             refuse: Mapping[str, Callable[[Any], str | None]] | None = None
                             ) -> None:
    """Let ``ros2 param set`` change ``node``'s parameters that are not read-only.

    A new value is checked as at start-up (:func:`value_problem`; refused with that line) and
    then handed to ``apply(name, value)``, doubles as floats. rclpy itself refuses the
    read-only ones ("Trying to set a read-only parameter"); their descriptors say why.
    ``refuse`` holds rules for parameters that rclpy declares, not the specs (``use_sim_time``):
    ``rule(value)`` says why the node refuses ``value`` (after ``parameter <name> = <value>``),
    or None; a value the node refused at start-up is refused at run time too, where it would
    otherwise be taken silently.
    """
    from rcl_interfaces.msg import SetParametersResult

    settable = {spec.name: spec for spec in specs if not spec.read_only}
    rules = dict(refuse or {})

    def check(parameters: list[Any]) -> SetParametersResult:
        for parameter in parameters:
            spec = settable.get(parameter.name)
            problem = None if spec is None else value_problem(spec, parameter.value)
            rule = rules.get(parameter.name)
            reason = None if rule is None else rule(parameter.value)
            if reason is not None:
                problem = f'parameter {parameter.name} = {parameter.value!r} {reason}'
            if problem is not None:
                return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True)

    def applied(parameters: list[Any]) -> None:
        for parameter in parameters:
            spec = settable.get(parameter.name)
            if spec is not None:
                apply(spec.name, _as_declared(spec, parameter.value))

    node.add_on_set_parameters_callback(check)
    node.add_post_set_parameters_callback(applied)


def _as_declared(spec: ParameterSpec, value: Any) -> Any:
    """``value`` in the spec's own type: a double given as an integer becomes a float."""
    if spec.type is ParameterType.DOUBLE:
        return float(value)
    if spec.type is ParameterType.DOUBLE_ARRAY:
        return [float(v) for v in value]
    return value


def declare_node_parameters(node: Any, specs: Iterable[ParameterSpec]) -> dict[str, Any]:
    """Declare every parameter of ``specs`` on ``node``; returns {name: value}.

    Every check of a parameter's value is here, driven by its spec: type, finite, range,
    choices, length, rule. A double (or an array of doubles) also takes integers
    (``-p publish_rate_hz:=50``, what a ROS user writes), returned as floats.

    Raises
    ------
    StartupError
        For a parameter the node does not have (naming those it has), or a value of the
        wrong type, out of range or not among the choices (naming what is allowed).
    """
    specs = tuple(specs)
    _refuse_unknown_overrides(node, specs)
    return {spec.name: _declare(node, spec) for spec in specs}


def _refuse_unknown_overrides(node: Any, specs: Sequence[ParameterSpec]) -> None:
    """A ``-p`` or params-file value for a parameter the node does not have would be ignored
    without a word (a misspelt name runs the defaults): refused instead. rclpy's own
    parameters (``use_sim_time``, declared when the Node was made) are allowed; sections of a
    params file for other nodes are not this node's overrides."""
    declared = {spec.name for spec in specs}
    # rclpy keeps this node's overrides (command line, matching params-file sections and the
    # constructor's parameter_overrides) in a private dict: it has no public accessor.
    overrides: dict[str, Any] = node._parameter_overrides
    unknown = sorted(name for name in overrides
                     if name not in declared and not node.has_parameter(name))
    if unknown:
        guesses = difflib.get_close_matches(unknown[0], declared, n=1)
        raise StartupError(
            f'unknown parameter {", ".join(unknown)}'
            + (f' (did you mean {guesses[0]}?)' if guesses else '')
            + f'; the {node.get_name()} takes: {", ".join(spec.name for spec in specs)}')


def _declare(node: Any, spec: ParameterSpec) -> Any:
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    from rclpy.parameter import Parameter

    descriptor = spec_descriptor(spec)
    default: Any = spec.default
    if default is None:
        default = Parameter.Type[spec.type.name]
    elif isinstance(default, tuple):
        default = list(default)
    # Doubles also take integers: ROS would refuse [0, 0] for a double array.
    descriptor.dynamic_typing = spec.default is not None and spec.type in (
        ParameterType.DOUBLE, ParameterType.DOUBLE_ARRAY)
    try:
        value = node.declare_parameter(spec.name, default, descriptor).value
    except (InvalidParameterTypeException, InvalidParameterValueException) as error:
        # rclpy's words name neither the allowed values nor the spelling to use: say ours.
        given = node._parameter_overrides.get(spec.name)
        problem = None if given is None else value_problem(spec, given.value)
        raise StartupError(problem or str(error.args[0])) from None
    if value is None:  # declared by its type alone and not given
        return None
    problem = value_problem(spec, value)
    if problem is not None:
        raise StartupError(problem)
    return _as_declared(spec, value)


_TYPE_WORDS = {ParameterType.BOOL: 'true or false', ParameterType.INTEGER: 'an integer',
               ParameterType.DOUBLE: 'a number', ParameterType.STRING: 'a string',
               ParameterType.DOUBLE_ARRAY: 'a list of numbers, e.g. [0.1, 0.2]',
               ParameterType.STRING_ARRAY: "a list of strings, e.g. ['a', 'b']"}


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _has_type(spec: ParameterSpec, value: Any) -> bool:
    if spec.type is ParameterType.BOOL:
        return isinstance(value, bool)
    if spec.type is ParameterType.INTEGER:
        return isinstance(value, int) and not isinstance(value, bool)
    if spec.type is ParameterType.DOUBLE:
        return _is_number(value)
    if spec.type is ParameterType.STRING:
        return isinstance(value, str)
    element = _is_number if spec.type is ParameterType.DOUBLE_ARRAY else (
        lambda v: isinstance(v, str))
    return isinstance(value, list | tuple) and all(element(v) for v in value)


def _number_text(value: float) -> str:
    """A bound or value as a user writes it: 2147483647, not 2.14748e+09."""
    if float(value).is_integer() and abs(value) < 1e16:
        return str(int(value))
    return f'{value:g}'


def value_problem(spec: ParameterSpec, value: Any) -> str | None:
    """What is wrong with ``value`` for ``spec`` (type, finite, range, choices, length, rule),
    said with what is allowed; None if nothing is."""
    name = spec.name
    if not _has_type(spec, value):
        return f'parameter {name} must be {_TYPE_WORDS[spec.type]}, got {value!r}'
    numbers = [value] if _is_number(value) else (
        list(value) if spec.type is ParameterType.DOUBLE_ARRAY else [])
    allowed = ('' if spec.range is None
               else f' [{_number_text(spec.range[0])}, {_number_text(spec.range[1])}]')
    if not all(math.isfinite(v) for v in numbers):
        return (f'parameter {name} = {value!r} is not finite: give a finite number'
                + (f' in{allowed}' if allowed else ''))
    if spec.range is not None and _is_number(value) \
            and not spec.range[0] <= value <= spec.range[1]:
        return f'parameter {name} = {_number_text(value)} is outside{allowed}'
    if spec.choices is not None and value not in spec.choices:
        # The empty choice ("leave it to another parameter") is written as a YAML file has it.
        choices = ', '.join(choice or '""' for choice in spec.choices)
        return f'parameter {name} = {value!r} is not one of: {choices}'
    if spec.length is not None and len(value) != spec.length:
        return f'parameter {name} needs {spec.length} values, got {list(value)}'
    reason = spec.rule(value) if spec.rule is not None else None
    shown = list(value) if isinstance(value, list | tuple) else value
    return None if reason is None else f'parameter {name} = {shown!r} {reason}'


def parameter_descriptor(description: str, float_range: tuple[float, float] | None = None,
                         int_range: tuple[int, int] | None = None,
                         read_only: bool = True) -> ParameterDescriptor:
    """A ``ParameterDescriptor`` with a description, an optional range, read-only by default.

    Parameters
    ----------
    description : str
    float_range, int_range : (low, high), optional
        Inclusive bounds that ROS enforces when the parameter is set.
    read_only : bool
    """
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    d = ParameterDescriptor(description=description, read_only=read_only)
    if float_range is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(float_range[0]),
                                                     to_value=float(float_range[1]), step=0.0)]
    if int_range is not None:
        d.integer_range = [IntegerRange(from_value=int(int_range[0]),
                                        to_value=int(int_range[1]), step=1)]
    return d


def parameters_help(executable: str, specs: Sequence[ParameterSpec]) -> str:
    """What ``<executable> --help`` prints: how to set a parameter, then each one's type,
    default, range or choices and description."""
    lines = [f'usage: {executable} [--ros-args -p NAME:=VALUE ... | --params-file FILE]', '',
             'parameters:']
    for spec in specs:
        allowed = (f', one of {", ".join(spec.choices)}' if spec.choices
                   else f', in [{_number_text(spec.range[0])}, {_number_text(spec.range[1])}]'
                   if spec.range is not None else '')
        default = ('none' if spec.default is None
                   else list(spec.default) if isinstance(spec.default, tuple) else spec.default)
        settable = '' if spec.read_only else ', settable at run time'
        lines.append(f'  {spec.name} ({spec.type.value}, default {default!r}{allowed}{settable})')
        lines.append(f'      {spec.description}')
    return '\n'.join(lines)
