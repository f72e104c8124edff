"""ROS environment hygiene shared by every executable, the CLI and the test fixtures.

DDS discovery must never leave this machine, so every entry point limits it to localhost
unless the user chose a range explicitly.
"""

from __future__ import annotations

import dataclasses
import enum
import os
import signal
import sys
from collections.abc import Callable, Iterable, MutableMapping
from types import FrameType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rcl_interfaces.msg import ParameterDescriptor

DISCOVERY_RANGE_VAR = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
DEFAULT_DISCOVERY_RANGE = 'LOCALHOST'
DOMAIN_ID_VAR = 'ROS_DOMAIN_ID'
# What the RMW uses when ROS_DOMAIN_ID is unset.
DEFAULT_DOMAIN_ID = 0


def ensure_localhost_discovery(environ: MutableMapping[str, str] | None = None) -> str:
    """Set ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless already set.

    Must run before ``rclpy.init()``: the RMW reads the variable when the context starts.

    Parameters
    ----------
    environ : MutableMapping, optional
        Environment to update; ``os.environ`` by default (which also updates the C environment
        inherited by child processes).

    Returns
    -------
    str
        The discovery range in force afterwards.
    """
    env = os.environ if environ is None else environ
    env.setdefault(DISCOVERY_RANGE_VAR, DEFAULT_DISCOVERY_RANGE)
    return env[DISCOVERY_RANGE_VAR]


# Set by the signal handlers below: a shutdown was asked for. The KeyboardInterrupt they raise
# can land inside a C extension's call (rclpy's take_message, a numba kernel), which then
# reports it as its own error (RuntimeError "Unable to convert call argument", SystemError);
# after a shutdown signal such an error is the shutdown, not a bug.
_shutdown_signal: list[str] = []


def _raise_keyboard_interrupt(signum: int, frame: FrameType | None) -> None:
    _shutdown_signal.append(signal.Signals(signum).name)
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _unraisable_after_shutdown(unraisable: Any) -> None:
    """``sys.unraisablehook``: an error in a finaliser (``__del__``) after a shutdown signal is
    an object the KeyboardInterrupt cut mid-construction being collected (rclpy's
    ``Task.__init__`` interrupted before it set ``_exception``, whose ``__del__`` then fails),
    not a bug: dropped. Before a shutdown signal, Python's own hook reports it."""
    if _shutdown_signal:
        return
    sys.__unraisablehook__(unraisable)


def shutdown_requested() -> bool:
    """True once SIGINT or SIGTERM reached a process that installed the handlers below."""
    return bool(_shutdown_signal)


def install_shutdown_signal_handlers() -> None:
    """Make SIGINT and SIGTERM both end a node with ``KeyboardInterrupt``.

    A process started in the background by a non-interactive shell inherits SIGINT as
    ignored, and SIGTERM's default action kills without cleanup; either way a supervisor that
    signals the node's PID would not get a clean exit. Call this before ``rclpy.init()``:
    rclpy then installs its own handlers on top, which wake the executor and chain to these,
    so ``rclpy.spin`` ends with ``KeyboardInterrupt`` or ``ExternalShutdownException``, both
    of which a node's ``main`` treats as a normal shutdown.
    """
    signal.signal(signal.SIGINT, _raise_keyboard_interrupt)
    signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    sys.unraisablehook = _unraisable_after_shutdown


# What a missing Python module is called where a ROS user installs it (rosdep keys of
# package.xml); the rest are pip names.
MODULE_TO_ROSDEP = {'scipy': 'python3-scipy', 'numpy': 'python3-numpy', 'yaml': 'python3-yaml',
                    'matplotlib': 'python3-matplotlib', 'mcap': 'python3-mcap (or pip install '
                    'mcap)', 'numba': 'python3-numba (or pip install numba)',
                    'zstandard': 'python3-zstandard', 'tqdm': 'python3-tqdm'}


class StartupError(ValueError):
    """A node cannot start with the parameters or files it was given."""


def startup_error_line(node_name: str, error: BaseException) -> str:
    """The one line a node prints when it cannot start, naming what to fix."""
    if isinstance(error, ModuleNotFoundError):
        module = (error.name or '').split('.')[0]
        remedy = MODULE_TO_ROSDEP.get(module, f'pip install {module}')
        return (f'{node_name}: error: the Python module {module!r} is missing: install '
                f'{remedy} (on a ROS install: rosdep install --from-paths src -y)')
    return f'{node_name}: error: {str(error).splitlines()[0] if str(error) else error!r}'


def _startup_errors() -> tuple[type[BaseException], ...]:
    """What a node's start-up raises for a bad parameter, file or installation (not a bug)."""
    from rclpy.exceptions import ParameterException

    return (ValueError, OSError, ModuleNotFoundError, ParameterException)


class ParameterType(enum.Enum):
    """The ROS type of a parameter (the names of ``rclpy.parameter.Parameter.Type``)."""

    BOOL = 'bool'
    INTEGER = 'integer'
    DOUBLE = 'double'
    STRING = 'string'
    DOUBLE_ARRAY = 'double_array'
    STRING_ARRAY = 'string_array'


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
        The values a string parameter takes (said in ``description``; the node checks them).
    read_only : bool
    """

    name: str
    type: ParameterType
    default: ParameterValue | None
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None
    read_only: bool = True


def spec_descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    """The ``ParameterDescriptor`` of ``spec``: description, range, read-only."""
    bounds = spec.range
    return parameter_descriptor(
        spec.description,
        float_range=bounds if spec.type is ParameterType.DOUBLE else None,
        int_range=((int(bounds[0]), int(bounds[1]))
                   if bounds is not None and spec.type is ParameterType.INTEGER else None),
        read_only=spec.read_only)


def declare_node_parameters(node: Any, specs: Iterable[ParameterSpec]) -> dict[str, Any]:
    """Declare every parameter of ``specs`` on ``node``; returns {name: value}.

    A parameter whose default is a float also takes an integer (``-p publish_rate_hz:=50``,
    what a ROS user writes), returned as a float and checked against the descriptor's range
    here, since ROS checks the range of a double only.

    Raises
    ------
    StartupError
        For a value of the wrong type or out of range, naming the parameter.
    """
    from rclpy.parameter import Parameter

    values = {}
    for spec in specs:
        descriptor = spec_descriptor(spec)
        default: Any = spec.default
        if default is None:
            default = Parameter.Type[spec.type.name]
        elif isinstance(default, tuple):
            default = list(default)
        if isinstance(default, float):
            descriptor.dynamic_typing = True
        value = node.declare_parameter(spec.name, default, descriptor).value
        if isinstance(default, float):
            value = _as_float(spec.name, value, descriptor)
        values[spec.name] = value
    return values


def _as_float(name: str, value: Any, descriptor: ParameterDescriptor) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise StartupError(f'parameter {name} must be a number, got {value!r}')
    value = float(value)
    for bounds in descriptor.floating_point_range:
        if not bounds.from_value <= value <= bounds.to_value:
            raise StartupError(f'parameter {name} = {value:g} is outside '
                               f'[{bounds.from_value:g}, {bounds.to_value:g}]')
    return value


def run_node(build: Callable[[], Any], args: list[str] | None = None,
             spin: Callable[[Any], object] | None = None,
             farewell: Callable[[Any], str] | None = None, name: str | None = None) -> int:
    """The ``main()`` of every executable: hygiene, init, build, spin, clean shutdown.

    Follows ros2/demos: the node is built inside the ``try`` so that a signal during start-up
    is a clean shutdown too, and ``KeyboardInterrupt`` or ``ExternalShutdownException`` end
    the spin normally.

    Parameters
    ----------
    build : callable
        ``build() -> rclpy.node.Node``.
    args : list of str, optional
        Command-line arguments for ``rclpy.init``.
    spin : callable, optional
        ``spin(node)``; ``rclpy.spin`` by default.
    farewell : callable, optional
        ``farewell(node) -> str``, printed (not logged: the context may already be shut down
        by the signal) before the node is destroyed.
    name : str, optional
        The executable's name, for the one line of a start-up error.

    Returns
    -------
    int
        The exit status: 0, or 2 when the node could not start (a bad parameter, a missing
        file or module: one line on stderr, ``<name>: error: ...``, no traceback).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    ensure_localhost_discovery()
    install_shutdown_signal_handlers()
    rclpy.init(args=args)
    node = None
    try:
        # The executor that rclpy.spin uses exists before the node announces itself: a signal
        # that interrupts Executor.__init__ before it sets _sigint_gc makes Executor.__del__
        # print an AttributeError traceback (seen once: a SIGTERM sent right after the
        # simulator's ready line, while rclpy.spin was still creating its executor; the exit
        # code was still 0).
        rclpy.get_global_executor()
        try:
            node = build()
        except _startup_errors() as error:
            print(startup_error_line(name or 'node', error), file=sys.stderr, flush=True)
            return 2
        (spin or rclpy.spin)(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if not shutdown_requested():
            raise
    finally:
        if node is not None:
            if farewell is not None:
                print(farewell(node), flush=True)
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


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
