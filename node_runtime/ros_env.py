"""ROS environment hygiene shared by every executable, the CLI and the test fixtures.

DDS discovery must never leave this machine, so every entry point limits it to localhost
unless the user chose a range explicitly.
"""

import os
import signal

DISCOVERY_RANGE_VAR = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
DEFAULT_DISCOVERY_RANGE = 'LOCALHOST'
DOMAIN_ID_VAR = 'ROS_DOMAIN_ID'
# What the RMW uses when ROS_DOMAIN_ID is unset.
DEFAULT_DOMAIN_ID = 0


def ensure_localhost_discovery(environ=None):
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
_shutdown_signal = []


def _raise_keyboard_interrupt(signum, frame):
    _shutdown_signal.append(signal.Signals(signum).name)
    raise KeyboardInterrupt(signal.Signals(signum).name)


def shutdown_requested():
    """True once SIGINT or SIGTERM reached a process that installed the handlers below."""
    return bool(_shutdown_signal)


def install_shutdown_signal_handlers():
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


def run_node(build, args=None, spin=None, farewell=None):
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
        node = build()
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


def parameter_descriptor(description, float_range=None, int_range=None, read_only=True):
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
