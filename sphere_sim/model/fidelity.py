"""The ladder of models: the full model, and the reduced rungs a scene may run instead.

The full model (every part the scene declares) is the reference. A reduced rung leaves one
named mechanism out, and only that one: it is the same scene with that effect switched off, so
the assembly builds it from the same parts and parameters. What a rung costs in landing error
against the full model, and what it saves in time, is measured on a fixed kick set and printed
side by side (``sphere-twin bench fidelity``, :mod:`sphere_sim.twin.ladder`); a rung may serve
the live twin only where it meets the live error budget there.

The kick table (the discrete plant) is the ladder's last rung. It keeps no mechanism but the
landing, so it is not a model and does not appear here.
"""

import dataclasses

import numpy as np
from numpy.typing import NDArray

from sphere_sim.model.assembly import Model
from sphere_sim.model.scene import Effects, Scene


class FidelityError(ValueError):
    """An unknown rung, or a rung asked to run a scene that needs what it leaves out."""


@dataclasses.dataclass(frozen=True)
class Rung:
    """One rung of the ladder.

    Attributes
    ----------
    name : str
    leaves_out : str
        The mechanism it leaves out, in words ('' for the full model).
    effects_off : tuple of str
        The scene's effects (fields of :class:`~sphere_sim.model.scene.Effects`) it switches
        off.
    """

    name: str
    leaves_out: str
    effects_off: tuple[str, ...] = ()

    def scene(self, scene: Scene) -> Scene:
        """``scene`` with this rung's mechanisms left out (the scene itself for the full model).

        Raises
        ------
        FidelityError
            Where the scene already leaves the mechanism out: the rung would not differ from
            the scene, and its measured error would not be its own.
        """
        if not self.effects_off:
            return scene
        missing = [e for e in self.effects_off if not getattr(scene.effects, e)]
        if missing:
            raise FidelityError(f"rung {self.name!r} leaves out {', '.join(missing)}, which "
                                f'scene {scene.name!r} does not have')
        return scene.replace(effects=dataclasses.replace(
            scene.effects, **dict.fromkeys(self.effects_off, False)))


FULL = Rung('full', '')
SLIDING = Rung(
    'sliding',
    "stiction and presliding (each tip's bristle below the sliding law): the paper's sliding "
    'law acts at every speed, regularised at rest by eq. (51); nothing holds a resting sphere',
    ('stiction',))
RUNGS: dict[str, Rung] = {r.name: r for r in (FULL, SLIDING)}
# The ladder's last rung, the kick table of the discrete plant: the landings alone.
TABLE_RUNG = 'table'
LADDER = (*RUNGS, TABLE_RUNG)

assert all(f in {field.name for field in dataclasses.fields(Effects)}
           for r in RUNGS.values() for f in r.effects_off)


def rung_named(name: str) -> Rung:
    """The model rung called ``name``.

    Raises
    ------
    FidelityError
        For any other name, naming the rungs there are.
    """
    try:
        return RUNGS[name]
    except KeyError:
        raise FidelityError(f'unknown fidelity {name!r}; choose one of '
                            f'{", ".join(LADDER)}') from None


def rung_of_scene(scene: Scene) -> Rung:
    """The rung a scene is: the one that leaves out just what the scene's effects leave out of
    the rungs' mechanisms (the full model where it leaves none of them out).

    Raises
    ------
    FidelityError
        For a scene that leaves out a combination no rung does.
    """
    off = {e for r in RUNGS.values() for e in r.effects_off if not getattr(scene.effects, e)}
    for r in RUNGS.values():
        if set(r.effects_off) == off:
            return r
    raise FidelityError(f'scene {scene.name!r} leaves out {", ".join(sorted(off))}: no rung '
                        'of the ladder does')


def carried_state(full: Model, reduced: Model, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """A state of ``full`` as the reduced model carries it: the states both have (beams and
    sphere come first in either layout), without those of the mechanism left out.

    Raises
    ------
    FidelityError
        Where ``reduced`` has states that ``full`` lacks (it is not a reduction of it).
    """
    if reduced.n_states > full.n_states or reduced.n_beams != full.n_beams:
        raise FidelityError('the reduced model has states the full model lacks')
    return np.array(x[:reduced.n_states], dtype=float)
