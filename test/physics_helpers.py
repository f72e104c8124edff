"""Shared builders for the physics tests: scenes in code, so each test states what it needs."""

import dataclasses

from sphere_sim.model.scene import Effects, load_scene


def scene_with(base='rest', beams=None, sphere=None, programme=None, duration_s=None,
               parameter_set=None, capacitance=None, initial=None, **effects):
    """A shipped scene with some fields and effects replaced."""
    scene = load_scene(base)
    changes = {}
    if beams is not None:
        changes['beams'] = tuple(beams)
    if sphere is not None:
        changes['sphere'] = sphere
    if programme is not None:
        changes['programme'] = programme
    if duration_s is not None:
        changes['duration_s'] = duration_s
    if parameter_set is not None:
        changes['parameter_set'] = parameter_set
    if capacitance is not None:
        changes['capacitance'] = capacitance
    if initial is not None:
        changes['initial'] = initial
    if effects:
        changes['effects'] = dataclasses.replace(scene.effects, **effects)
    return scene.replace(**changes)


__all__ = ['Effects', 'scene_with']


def ground_contact_threshold_v(params, beam, width_s, low_v, high_v, resolution_v=0.02):
    """The model's own single-beam threshold from level by a rule of its own: the beam's rear
    end reaches the ground plate during one pulse of ``width_s``, bisected in [low_v, high_v]
    (V) to ``resolution_v``."""
    from sphere_sim.integrate.solve import simulate
    from sphere_sim.model.assembly import assemble
    from sphere_sim.model.initial_state import rest_state
    from sphere_sim.model.programme import Pulse, PulseProgramme

    model = assemble(load_scene('rest'), params)
    x0 = rest_state(model, (0.0, 0.0, 0.0))

    def pulls_in(amplitude):
        traj = simulate(model, x0, width_s, PulseProgramme((Pulse(beam, amplitude, 0.0,
                                                                  width_s),)),
                        sample_period_s=width_s / 200)
        return min(model.ground_gaps(traj.x[:, i])[0][beam - 1]
                   for i in range(traj.t.size)) <= 0.0

    while high_v - low_v > resolution_v:
        middle = 0.5 * (low_v + high_v)
        low_v, high_v = (low_v, middle) if pulls_in(middle) else (middle, high_v)
    return 0.5 * (low_v + high_v)
