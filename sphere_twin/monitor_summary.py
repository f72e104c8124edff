"""The monitor's final line, written by the monitor node and read by the demo and the tests.

Kept apart from :mod:`sphere_twin.nodes.monitor_node` so that readers need no rclpy.
"""

import re

_SUMMARY_RE = re.compile(r'^received (\d+) messages on (\S+)$', re.MULTILINE)


def summary_line(count: int, topic_name: str) -> str:
    """``received N messages on TOPIC``."""
    return f'received {count} messages on {topic_name}'


def parse_summaries(text: str) -> dict[str, int]:
    """Message counts per topic found in a monitor's output.

    Parameters
    ----------
    text : str
        The monitor's standard output.

    Returns
    -------
    dict of str to int
        Topic name to count, from the last summary line of each topic; empty if none.
    """
    return {topic: int(count) for count, topic in _SUMMARY_RE.findall(text)}
