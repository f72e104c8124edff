"""Every node's parameters, written once: name, type, default, range, description, read-only.

Each node declares its parameters from its tuple here (through
:func:`sphere_twin.node_runtime.parameter_specs.declare_node_parameters`); ``config/twin.yaml`` and
the arguments of ``launch/twin.launch.py`` are checked against these tuples by
``test/test_node_parameters.py``. This module imports no rclpy and no physics, so tests and
docs can read it without ROS and a node can import it before it installs its signal handlers.
"""

import math
from collections.abc import Sequence

from msg_defs.device import SENSOR_RATE_HZ
from msg_defs.topics import ALL_TOPICS, CLOCK, SURFACE_NORMAL
from sphere_sim.integrate.tolerances import CHECK_RTOL
from sphere_sim.twin.plant_setup import FIDELITIES, LIVE_FIDELITY, PLANT_KINDS
from sphere_twin.node_runtime.parameter_specs import ParameterSpec, ParameterType

BOOL = ParameterType.BOOL
INTEGER = ParameterType.INTEGER
DOUBLE = ParameterType.DOUBLE
STRING = ParameterType.STRING
DOUBLE_ARRAY = ParameterType.DOUBLE_ARRAY
STRING_ARRAY = ParameterType.STRING_ARRAY

# ROS integer parameters are int64; this bound only keeps a descriptor's range finite.
MAX_INT32 = 2**31 - 1

# --- simulator ---------------------------------------------------------------------------
MAX_PUBLISH_RATE_HZ = 1000.0

SIMULATOR_PARAMETERS = (
    ParameterSpec('plant', STRING, '',
                  'Plant to run: continuous (the physics of §3) or discrete (the lookup table '
                  'of kicks: it starts faster; its sphere and beams rest between kicks); "" '
                  'for the one fidelity names (continuous where both are "").',
                  choices=('', *PLANT_KINDS)),
    ParameterSpec('fidelity', STRING, '',
                  'Rung of the ladder of models the plant serves kicks from: full (the '
                  'paper\'s model), sliding (leaves out stiction and presliding: cheaper, outside '
                  'the live error budget) or table (the discrete plant); "" for the plant\'s own '
                  f'({LIVE_FIDELITY} on the continuous plant, the live default).',
                  choices=('', *FIDELITIES)),
    ParameterSpec('scene', STRING, 'rest', 'Scene (shipped name or YAML path): parameters, '
                  'beams, sphere and initial state.'),
    ParameterSpec('params', STRING, '',
                  'Parameter set (shipped name or YAML file with base: and overrides:) instead '
                  'of the scene\'s; "" keeps the scene\'s.'),
    ParameterSpec('tables', STRING_ARRAY, ('',),
                  'Kick tables (.npz) of the discrete plant, their actions combined (the '
                  'diagonal and the axis-parallel tables give 8 directions); [""] for the '
                  'shipped default.'),
    ParameterSpec('publish_rate_hz', DOUBLE, SENSOR_RATE_HZ,
                  'Samples per simulated second (Hz).', range=(1.0, MAX_PUBLISH_RATE_HZ),
                  read_only=False),
    ParameterSpec('real_time_factor', DOUBLE, 1.0,
                  'Simulated seconds per wall second; 0 runs as fast as possible.',
                  range=(0.0, 1000.0), read_only=False),
    ParameterSpec('seed', INTEGER, 0, 'Seed of the measurement noise.', range=(0, MAX_INT32),
                  fixed_because='a run is reproducible only from its one seed'),
    ParameterSpec('noise_std_rad', DOUBLE, 0.0,
                  'Standard deviation of the measured normal per tangential axis (rad).',
                  range=(0.0, 0.1), read_only=False),
    ParameterSpec('wait_for_subscribers', INTEGER, 0,
                  f'Hold simulated time at 0 until {SURFACE_NORMAL.name} has this many '
                  'subscribers (DDS discovery takes seconds; a scenario should not start before '
                  'its controller listens).', range=(0, 100)),
    ParameterSpec('wait_for_clock_subscribers', INTEGER, 0,
                  f'Hold simulated time at 0 until {CLOCK.name} has this many subscribers (the '
                  'nodes on use_sim_time, and a recorder, which counts too: a reference that has '
                  'not yet heard the clock when a short run ends never moves).',
                  range=(0, 100)),
    ParameterSpec('lockstep', BOOL, False,
                  'Advance simulated time only while a command is in effect: runs are then '
                  'identical whatever the wall-clock timing.'),
    ParameterSpec('check_fidelity', BOOL, False,
                  f'Run the full model (rtol {CHECK_RTOL:g}) beside the plant, in a process of '
                  'its own, on every programme the plant starts, and publish how far the '
                  'landings diverge on /diagnostics (docs/numerics.md, the ladder of models).'),
)

# --- controller --------------------------------------------------------------------------
# What sphere_control.controllers accepts (CONTROLLER_KINDS) and its DEFAULT_PHI_MIN_RAD in
# degrees, written out because that module loads numba and scipy: a node imports this one
# before it installs its signal handlers. test_node_parameters checks both against the code.
CONTROLLER_CHOICES = ('basic', 'extended')
DEFAULT_PHI_MIN_DEG = 0.05

CONTROLLER_PARAMETERS = (
    ParameterSpec('controller', STRING, 'extended',
                  f'Control law: {" or ".join(CONTROLLER_CHOICES)} (§4.2).',
                  choices=CONTROLLER_CHOICES),
    ParameterSpec('phi_min_deg', DOUBLE, DEFAULT_PHI_MIN_DEG,
                  'Resting band Phi_min (deg): no kick while the error is below it.',
                  range=(0.0, 10.0)),
    ParameterSpec('tables', STRING_ARRAY, ('',),
                  'Kick tables (.npz): the kicks it may send and its initial model of them; '
                  '[""] for the shipped default (4 diagonal kicks).'),
    ParameterSpec('stale_timeout_s', DOUBLE, 1.0,
                  'Wall time without a sample after which the state is stale (s).',
                  range=(0.05, 60.0)),
    ParameterSpec('kick_period_s', DOUBLE, 0.0,
                  'Time from a kick\'s reported start until it is over and the next is '
                  'decided (s); 0: the settle time of the tables\' full kick, rounded up to '
                  '10 ms (40 ms for the shipped table), as in the offline loop.',
                  range=(0.0, 10.0)),
    ParameterSpec('preview', BOOL, True,
                  'Aim where the reference will be when the kick has settled, estimated '
                  'from its recent samples (a jump is not extrapolated), not at its newest '
                  'sample (the paper; docs/control.md).', read_only=False),
    ParameterSpec('hold_each_sample', BOOL, False,
                  'While resting, send 0 V for every sample decided on, as a lockstep '
                  'simulator needs (it advances one sample per command); otherwise one 0 V '
                  'command when a rest begins.'),
)

# --- reference ---------------------------------------------------------------------------
DEFAULT_PUBLISH_RATE_HZ = 10.0
NEVER = -1.0


def inside_unit_disk(xy: Sequence[float]) -> str | None:
    """Why ``xy`` cannot be the x-y part of a unit normal (|(x, y)| >= 1), or None."""
    norm = math.hypot(*xy)
    if norm < 1.0:
        return None
    return f'is not the x-y part of a unit normal: |(x, y)| = {norm:.4g} must be below 1'


REFERENCE_PARAMETERS = (
    ParameterSpec('setpoint_xy', DOUBLE_ARRAY, (0.01, 0.02),
                  'x and y of the setpoint normal (Fig. 13: [0.01, 0.02]).', length=2,
                  rule=inside_unit_disk),
    ParameterSpec('trajectory_start_s', DOUBLE, NEVER,
                  'Time (s) from which eq. (64) replaces the setpoint; -1 never.',
                  range=(NEVER, 1e6)),
    ParameterSpec('trajectory_offset_s', DOUBLE, 0.0,
                  'Time (s) into eq. (64) at which it is entered: 0 starts at [A_max, 0], '
                  '1/(4 f1) at the centre.', range=(0.0, 1e6)),
    ParameterSpec('amplitude', DOUBLE, 0.44, 'A_max of eq. (64).', range=(0.0, 1.0)),
    ParameterSpec('frequency_hz', DOUBLE, 0.02, 'f1 of eq. (64) (Hz).', range=(0.0, 10.0)),
    ParameterSpec('publish_rate_hz', DOUBLE, DEFAULT_PUBLISH_RATE_HZ,
                  'Publications per second of the node clock (Hz).', range=(0.1, 1000.0),
                  read_only=False),
)

# --- recorder ----------------------------------------------------------------------------
DEFAULT_BAG_PARENT = 'bags'
DEFAULT_FLUSH_PERIOD_S = 1.0
MAX_FLUSH_PERIOD_S = 3600.0
# sphere_twin.bag.writer's COMPRESSIONS and DEFAULT_CHUNK_SIZE_BYTES, written out because that
# module loads mcap; test_node_parameters checks both against it.
COMPRESSION_CHOICES = ('zstd', 'lz4', 'none')
DEFAULT_CHUNK_SIZE_BYTES = 768 * 1024

RECORDER_PARAMETERS = (
    ParameterSpec('output_dir', STRING, '',
                  'Bag directory to create (must not exist or be empty); "" for '
                  f'{DEFAULT_BAG_PARENT}/run_<UTC time>.'),
    ParameterSpec('topics', STRING_ARRAY, tuple(t.name for t in ALL_TOPICS),
                  'Topics to record, by name; each must be in the topic contract. All of them '
                  'by default.'),
    ParameterSpec('compression', STRING, 'zstd',
                  f'Compression of the MCAP chunks: {", ".join(COMPRESSION_CHOICES)}.',
                  choices=COMPRESSION_CHOICES),
    ParameterSpec('chunk_size_bytes', INTEGER, DEFAULT_CHUNK_SIZE_BYTES,
                  'Uncompressed size (bytes) at which an MCAP chunk is completed.',
                  range=(1024, MAX_INT32)),
    ParameterSpec('flush_period_s', DOUBLE, DEFAULT_FLUSH_PERIOD_S,
                  'Complete the current chunk and write it to disk this often (s), bounding '
                  'what a crash can lose; 0 writes chunks only when full.',
                  range=(0.0, MAX_FLUSH_PERIOD_S)),
)

# --- player ------------------------------------------------------------------------------
MAX_RATE = 1000.0
MIN_RATE = 0.001
MAX_WAIT_S = 3600.0

PLAYER_PARAMETERS = (
    ParameterSpec('bag', STRING, '',
                  'Bag to play: its directory, one of its .mcap files, a bare .mcap file, or '
                  'the name of a bag installed with the package (example).'),
    ParameterSpec('rate', DOUBLE, 1.0, 'Playback speed: 2 plays twice as fast as recorded.',
                  range=(MIN_RATE, MAX_RATE)),
    ParameterSpec('start_offset_s', DOUBLE, 0.0,
                  'Skip this much of the bag (s of recorded time from its first message).',
                  range=(0.0, 1e9)),
    ParameterSpec('topics', STRING_ARRAY, None,
                  'Topics to play, by name; every topic of the bag if unset.'),
    ParameterSpec('loop', BOOL, False, 'Start over at the end, until stopped.'),
    ParameterSpec('publish_clock', BOOL, True,
                  'Publish /clock from the log times when the bag has no /clock messages.'),
    ParameterSpec('wait_for_subscribers_s', DOUBLE, 0.0,
                  'Before playing, wait up to this long (s) until every topic played has a '
                  'subscriber; 0 starts at once.', range=(0.0, MAX_WAIT_S)),
    ParameterSpec('delay_s', DOUBLE, 0.0,
                  'Then wait this long (s) before the first message: a publisher sees a '
                  'subscriber slightly before that subscriber accepts its messages.',
                  range=(0.0, MAX_WAIT_S)),
)

# --- monitor -----------------------------------------------------------------------------
MAX_MESSAGES_LIMIT = MAX_INT32

MONITOR_PARAMETERS = (
    ParameterSpec('max_messages', INTEGER, 0,
                  'Exit after this many messages; 0 runs until stopped.',
                  range=(0, MAX_MESSAGES_LIMIT)),
)

# Each node's parameters, by node name (the section of config/twin.yaml).
NODE_PARAMETERS: dict[str, tuple[ParameterSpec, ...]] = {
    'simulator': SIMULATOR_PARAMETERS,
    'controller': CONTROLLER_PARAMETERS,
    'reference': REFERENCE_PARAMETERS,
    'recorder': RECORDER_PARAMETERS,
    'player': PLAYER_PARAMETERS,
    'monitor': MONITOR_PARAMETERS,
}
