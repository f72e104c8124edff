"""What happened to a pulse programme, as its sender learns it (no ROS).

The simulator (or a device's driver) echoes every programme it receives on the programme
status topic (:data:`msg_defs.topics.PROGRAMME_STATUS`): when it started, when its segments
ended, when a later command cut it, or why it was refused. A controller times its kick cycle
from these reports, never from the start it asked for, which a late command does not get.
"""

import enum
import typing


class ProgrammeState(enum.Enum):
    STARTED = 'started'  # its first segment is on the beams (``time_s``: the actual start)
    ENDED = 'ended'  # its last segment has run (``time_s``: the actual end)
    CUT = 'cut'  # a later voltage command or programme replaced it before it ended
    REFUSED = 'refused'  # it never ran


class ProgrammeEvent(typing.NamedTuple):
    """One report on one programme.

    Attributes
    ----------
    state : ProgrammeState
    asked_s : float
        The start its sender asked for (the programme's stamp, 0 for at once): how the sender
        recognises its own programme.
    number : int
        The receiver's count of programmes received, from 1.
    time_s : float
        When it happened (simulated s).
    text : str
        A line for people (why it was refused or cut, ...); the status topic does not carry
        it since it moved to action_msgs, so a report read from the topic has '' (one read
        from an older bag has the recorded line).
    """

    state: ProgrammeState
    asked_s: float
    number: int
    time_s: float
    text: str = ''
