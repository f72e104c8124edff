"""The device's constants and the project's defaults: one home each, no ROS.

Every package reads these from here (the topic contract re-exports them), so a value that the
hardware or the paper fixes is written once.
"""

BEAM_COUNT = 4  # four lever beams around the sphere (Fig. 1)
BEAM_IDS = tuple(range(1, BEAM_COUNT + 1))  # numbered 1..4 as in the paper's Fig. 7
VOLTAGE_LIMIT_V = 80.0  # hardware limit of the actuators (§4.1): beyond it rejected, not clipped
KICK_WINDOW_S = 0.06  # a kick and its settling: the paper's kicks settle in about 50 ms (Fig. 5)
DEFAULT_PARAMETER_SET = 'calibrated'  # the set every command and node uses unless told otherwise
NS_PER_S = 1_000_000_000  # ROS time is integer nanoseconds
