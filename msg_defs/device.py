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
# The sensor's sample rate: a kick cycle is its settle period (50 ms for the shipped kicks) plus
# the one sample between a decision and the kick's start, so the sample period must divide the
# settle period for the deciding sample to fall where the kick is over: 100 Hz gives a 60 ms
# cycle (50 Hz gave 80 ms). A magnetic angle sensor of §6 (3D Hall sensors) reads at hundreds
# of Hz to kHz, so the rate is the device's, not a twin's luxury; publishing costs about 1 ms
# of wall time per sample.
SENSOR_RATE_HZ = 100.0
