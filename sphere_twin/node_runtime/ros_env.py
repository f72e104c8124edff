"""ROS environment hygiene shared by every executable, the CLI and the test fixtures.

DDS discovery must never leave this machine, so every entry point limits it to localhost
unless the user chose a range explicitly.
"""

from __future__ import annotations

import faulthandler
import importlib
import os
import re
import signal
import sys
from collections.abc import Callable, MutableMapping, Sequence
from types import FrameType
from typing import TYPE_CHECKING, Any

from sphere_twin.node_runtime.parameter_specs import ParameterSpec, parameters_help

if TYPE_CHECKING:
    pass

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
    # Only the first signal interrupts. Ctrl-C in a terminal reaches every process of the
    # group and `ros2 launch` sends its own SIGINT on top: a second KeyboardInterrupt would cut
    # the clean shutdown the first one started (destroy_node, closing a bag) and escape main.
    first = not _shutdown_signal
    _shutdown_signal.append(signal.Signals(signum).name)
    if first:
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


def startup_error_line(node_name: str, error: BaseException) -> str:
    """The one line a node prints when it cannot start, naming what to fix."""
    if isinstance(error, ModuleNotFoundError):
        module = (error.name or '').split('.')[0]
        remedy = MODULE_TO_ROSDEP.get(module, f'pip install {module}')
        return (f'{node_name}: error: the Python module {module!r} is missing: install '
                f'{remedy} (on a ROS install: rosdep install --from-paths src -y)')
    if isinstance(error, OSError) and error.strerror:
        # An OSError's args[0] is its number: the line says the file and the reason instead.
        where = f'{error.filename}: ' if error.filename is not None else ''
        return f'{node_name}: error: {where}{error.strerror}'
    # args[0], not str(error): str() of a KeyError (or an exception of several args) is a repr.
    text = str(error.args[0]) if error.args else ''
    return f'{node_name}: error: {text.splitlines()[0] if text.strip() else repr(error)}'


# rcl ends its messages with where in its C sources it failed (', at /project/src/...').
_RCL_SOURCE_SUFFIX = re.compile(r',? at /\S+\.c:\d+.*$', re.DOTALL)
_RCL_PARAMS_FILE = re.compile(r"Couldn't parse params file: '--params-file (?P<path>.*?)'\. "
                              r'Error: (?P<reason>[^\n]*)')


def ros_arguments_error_line(node_name: str, error: BaseException) -> str:
    """The one line for ROS arguments that ``rclpy.init`` refused (an ``RCLError``): a
    ``--params-file`` that is missing or not a parameters YAML, or a malformed ``-p``/``-r``."""
    text = str(error).removeprefix('failed to initialize rcl: ')
    params_file = _RCL_PARAMS_FILE.search(text)
    if params_file is not None:
        path = params_file['path']
        reason = (_RCL_SOURCE_SUFFIX.sub('', params_file['reason']).strip()
                  if os.path.isfile(path) else 'no such file')
        return (f'{node_name}: error: cannot read --params-file {path}: {reason} (a YAML file '
                'of <node>: {ros__parameters: {name: value}} sections)')
    detail = ' '.join(_RCL_SOURCE_SUFFIX.sub('', text).split())
    return (f'{node_name}: error: invalid ROS arguments: {detail} (parameters are given as '
            '--ros-args -p name:=value)')


def _startup_errors() -> tuple[type[BaseException], ...]:
    """What a node's start-up raises for a bad parameter, file or installation (not a bug)."""
    from rclpy.exceptions import ParameterException

    return (ValueError, OSError, ModuleNotFoundError, ParameterException)


def run_node(build: Callable[[], Any], args: list[str] | None = None,
             spin: Callable[[Any], object] | None = None,
             farewell: Callable[[Any], str] | None = None, name: str | None = None,
             own_signal_handling: Callable[[], object] | None = None,
             parameters: Sequence[ParameterSpec] = ()) -> int:
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
    parameters : sequence of ParameterSpec
        The node's parameters: ``--help`` (or ``-h``) before any ROS argument prints them
        and exits 0 without starting the node.
    own_signal_handling : callable, optional
        Installs the node's own SIGINT and SIGTERM handling instead of the KeyboardInterrupt
        handlers and rclpy's (the recorder's: a flag its spin polls, so no write is cut).

    Returns
    -------
    int
        The exit status: 0; 2 when the node could not start (bad ROS arguments or params
        file, a bad parameter, a missing file or module: one line on stderr,
        ``<name>: error: ...``, no traceback); 1 when the system failed it while it ran (an
        ``OSError``, such as a full disk: one line too).
    """
    if _printed_help(sys.argv[1:] if args is None else args, name or 'node', parameters):
        return 0
    try:
        return _run(build, args, spin, farewell, name or 'node', own_signal_handling)
    except KeyboardInterrupt:
        # The first signal's interrupt ends the spin inside _run; one that still reaches here
        # came on top of a shutdown already under way (signals in a burst, as a terminal's
        # Ctrl-C and launch's own SIGINT): the node is leaving anyway, and a traceback with
        # exit status -2 would report a clean stop as a crash.
        import rclpy

        _ignore_late_signals()
        rclpy.try_shutdown()  # where the interrupted shutdown did not get to it
        return 0


def run_node_module(module_name: str, args: list[str] | None = None) -> int:
    """An executable's entry point: SIGINT and SIGTERM end it cleanly from its first moment,
    then the ``main()`` of its node's module.

    Importing a node's module takes from half a second to seconds (rclpy, numpy, numba), and
    a console script imports it before it calls anything: a Ctrl-C in that time (``ros2
    launch`` stopped in its first second) would raise ``KeyboardInterrupt`` inside an import,
    print its traceback and end the node with -2, which launch reports as a death. Here the
    shutdown handlers are installed first; a signal during the import ends the node with
    status 0 and nothing printed (whatever the interrupted import raised: it can land inside a
    C extension, which reports it as its own error), as a signal during start-up does.
    """
    install_shutdown_signal_handlers()
    # A crash in a C extension (the RMW, rclpy, a compiled kernel) kills the node with no word
    # of where: with this, it prints every thread's Python stack on stderr first, which is
    # all that a supervisor (launch, a test) keeps of a rare crash.
    faulthandler.enable()
    main = None
    try:
        main = importlib.import_module(module_name).main
    except BaseException:
        if not shutdown_requested():
            raise
    if main is None or shutdown_requested():
        _ignore_late_signals()
        return 0
    return main(args)


def _run(build: Callable[[], Any], args: list[str] | None,
         spin: Callable[[Any], object] | None, farewell: Callable[[Any], str] | None,
         node_name: str, own_signal_handling: Callable[[], object] | None) -> int:
    """:func:`run_node` after ``--help``: init, build, spin, and the clean shutdown."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    ensure_localhost_discovery()
    (own_signal_handling or install_shutdown_signal_handlers)()
    if not _init_rclpy(node_name, args, rclpy_signal_handlers=own_signal_handling is None):
        return 2
    node = None
    status = 0
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
            print(startup_error_line(node_name, error), file=sys.stderr, flush=True)
            return 2
        (spin or rclpy.spin)(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except OSError as error:
        if not shutdown_requested():
            print(f'{node_name}: error: {error}', file=sys.stderr, flush=True)
            status = 1
    except Exception:
        if not shutdown_requested():
            raise
    finally:
        _leave(node, farewell)
    return status


def _leave(node: Any, farewell: Callable[[Any], str] | None) -> None:
    """The node's farewell, its destruction and rclpy's shutdown, whatever ended it."""
    import rclpy

    if node is not None:
        if farewell is not None:
            print(farewell(node), flush=True)
        node.destroy_node()
    rclpy.try_shutdown()
    _ignore_late_signals()


def _printed_help(command_line: Sequence[str], node_name: str,
                  parameters: Sequence[ParameterSpec]) -> bool:
    """Print the node's parameters if ``--help`` or ``-h`` comes before any ROS argument."""
    own = command_line[:list(command_line).index('--ros-args')] if '--ros-args' in \
        command_line else command_line
    if '--help' not in own and '-h' not in own:
        return False
    try:
        print(parameters_help(node_name, parameters), flush=True)
    except BrokenPipeError:  # `simulator --help | head`: the reader has what it wanted
        sys.stdout = None  # nothing more to flush at exit
    return True


def _ignore_late_signals() -> None:
    """From here on the node is leaving: SIGINT and SIGTERM are ignored. Python restores their
    default action while it finalises, so a late Ctrl-C (a terminal's reaching the whole group
    on top of launch's own SIGINT) would otherwise kill a node that had shut down cleanly,
    and its exit status would read -2. An ignored signal stays ignored through finalisation."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _init_rclpy(node_name: str, args: list[str] | None, rclpy_signal_handlers: bool) -> bool:
    """``rclpy.init`` (with or without rclpy's SIGINT and SIGTERM handlers); False, after the
    one line on stderr, when it refuses the ROS arguments.

    rcl also logs its own lines about refused arguments ('Failed to parse global arguments')
    straight to file descriptor 2, so stderr is held in a file during the call: on success
    what it caught is passed on, on failure the one line replaces it.
    """
    import tempfile

    import rclpy
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.signals import SignalHandlerOptions

    handlers = SignalHandlerOptions.ALL if rclpy_signal_handlers else SignalHandlerOptions.NO
    refused: BaseException | None = None
    sys.stderr.flush()
    saved_fd = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            rclpy.init(args=args, signal_handler_options=handlers)
        except rclpy_implementation.RCLError as error:
            refused = error
        finally:
            os.dup2(saved_fd, 2)
            os.close(saved_fd)
        if refused is None:
            held.seek(0)
            sys.stderr.write(held.read().decode(errors='replace'))
            sys.stderr.flush()
    if refused is not None:
        print(ros_arguments_error_line(node_name, refused), file=sys.stderr, flush=True)
        return False
    return True
