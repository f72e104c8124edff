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
