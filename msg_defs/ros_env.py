"""ROS environment hygiene shared by every executable, the CLI and the test fixtures.

DDS discovery must never leave this machine, so every entry point limits it to localhost
unless the user chose a range explicitly.
"""

import os

DISCOVERY_RANGE_VAR = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
DEFAULT_DISCOVERY_RANGE = 'LOCALHOST'


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
