"""The topic contract: names unique, encodings as documented, QoS as rclpy profiles."""

import pytest
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from msg_defs.topics import (
    ALL_TOPICS,
    BEAM_NAMES,
    BEAM_STATE_JOINT_NAMES,
    CLOCK,
    COMMAND_BURST_LIMIT,
    PULSE_PROGRAM,
    SPHERE_REFERENCE,
    SURFACE_NORMAL,
    VOLTAGE_COMMAND,
    WORLD_FRAME,
    topic_by_name,
)


def test_topic_names_are_unique_and_absolute():
    names = [t.name for t in ALL_TOPICS]
    assert len(set(names)) == len(names)
    # Every topic the issue asks for is in the contract.
    assert {'/sphere/state', '/sphere/surface_normal', '/beams/state', '/beams/voltage',
            '/beams/voltage_command', '/beams/pulse_program', '/sphere/reference',
            '/controller/status', '/clock'} <= set(names)
    assert all(name.startswith('/') for name in names)


def test_beam_joint_names_encode_two_dofs_per_beam_beam_major():
    assert BEAM_NAMES == ('beam_1', 'beam_2', 'beam_3', 'beam_4')
    assert BEAM_STATE_JOINT_NAMES[:4] == ('beam_1_z', 'beam_1_phi', 'beam_2_z', 'beam_2_phi')
    assert len(BEAM_STATE_JOINT_NAMES) == 8


def test_lookup_by_name_and_unknown_name():
    assert topic_by_name('/sphere/surface_normal') is SURFACE_NORMAL
    assert SURFACE_NORMAL.frame_id == WORLD_FRAME
    with pytest.raises(KeyError, match='/no/such'):
        topic_by_name('/no/such')


def test_qos_specs_become_the_intended_profiles():
    command = VOLTAGE_COMMAND.qos.to_profile()
    assert command.reliability == ReliabilityPolicy.RELIABLE
    assert command.durability == DurabilityPolicy.VOLATILE
    # Deep enough that a burst of commands within a sample is counted, not lost in the queue.
    assert command.depth == COMMAND_BURST_LIMIT == 10_000
    # A programme is a one-off kick: never replayed to a late joiner.
    programme = PULSE_PROGRAM.qos.to_profile()
    assert programme.durability == DurabilityPolicy.VOLATILE
    assert programme.depth == COMMAND_BURST_LIMIT
    reference = SPHERE_REFERENCE.qos.to_profile()
    assert reference.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert reference.depth == 1
    assert CLOCK.qos.to_profile().reliability == ReliabilityPolicy.BEST_EFFORT
