"""rosbag2-compatible bags: the on-disk layout, a writer and a small reader, without DDS.

A bag is a directory holding ``metadata.yaml`` (rosbag2 metadata version 9, as ROS 2 Jazzy
writes it) and one MCAP file ``<name>_0.mcap`` of CDR-serialized messages with ``ros2msg``
schemas, in zstd-compressed chunks. ``ros2 bag info``/``play``, Foxglove and the ``rosbags``
library read it. :mod:`sphere_twin.nodes.recorder_node` records one from the live topics.

Modules
-------
format
    The layout: metadata.yaml text, QoS profiles as rosbag2 writes them, message definitions.
writer
    :class:`~sphere_twin.bag.writer.BagWriter`, which writes serialized messages to a bag.
reader
    :func:`~sphere_twin.bag.reader.read_metadata` and
    :func:`~sphere_twin.bag.reader.read_messages`, which also read the completed chunks of a
    file whose recorder was killed (:func:`~sphere_twin.bag.reader.scan_mcap`).
repair
    :func:`~sphere_twin.bag.repair.repair_bag`: such a bag rewritten into a complete one
    (``sphere-twin bag repair``).
"""
