"""Convergence of the friction regularisations: kick outcomes as each one shrinks.

The viscous onset ramp and the epsilon of eq. (51) smooth the friction law for the solver;
as they shrink, the outcome of a kick must converge, and at two tolerances agree. Computes and
returns rows; ``sphere-twin bench regularisation`` writes them.
"""

import math
from collections.abc import Callable, Mapping, Sequence

from msg_defs.device import KICK_WINDOW_S
from sphere_sim.integrate.solve import simulate
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.scene import load_scene

ONSET_VALUES_M = (1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 1e-11, 0.0)
EPSILON_VALUES_M2_PER_S2 = (1e-6, 1e-8, 1e-10, 1e-12, 1e-14, 1e-16)
STUDIES = (('friction.viscous_onset_m', ONSET_VALUES_M),
           ('friction.epsilon_m2_per_s2', EPSILON_VALUES_M2_PER_S2))
STUDY_RTOLS = (1e-7, 1e-9)  # each value run at two tolerances: the numerics must agree
SAMPLE_PERIOD_S = 1e-3


def regularisation_rows(programmes: Mapping[str, PulseProgramme], direction_rad: float,
                        rtols: Sequence[float] = STUDY_RTOLS,
                        progress: Callable[[], object] | None = None,
                        ) -> list[dict[str, str | float | int]]:
    """One row per (parameter, value, kick, rtol): the final normal after the kick window
    and its projection on ``direction_rad`` (deg), with the steps and wall time.

    ``programmes`` maps a kick's name to its PulseProgramme; ``progress()`` is called after
    each run.
    """
    scene = load_scene('rest')
    base = scene.parameters()
    rows = []
    for path, values in STUDIES:
        for value in values:
            model = assemble(scene, base.replace(**{path: value}))
            x0 = rest_state(model)
            for kick, programme in programmes.items():
                for rtol in rtols:
                    traj = simulate(model, x0, KICK_WINDOW_S, programme, rtol=rtol,
                                    method='fast', sample_period_s=SAMPLE_PERIOD_S)
                    n = model.surface_normal(traj.final_state)
                    along = n[0] * math.cos(direction_rad) + n[1] * math.sin(direction_rad)
                    rows.append({'parameter': path, 'value': value, 'kick': kick,
                                 'rtol': rtol, 'along_deg': math.degrees(along),
                                 'normal_x': n[0], 'normal_y': n[1],
                                 'steps': traj.stats.n_steps,
                                 'wall_s': traj.stats.wall_time_s})
                    if progress is not None:
                        progress()
    return rows
