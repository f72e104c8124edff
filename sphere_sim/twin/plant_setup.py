"""Building the simulator's plant from a scene name and a plant kind (one place for both)."""

# The physics is imported inside the functions: the node modules import this one for
# PLANT_KINDS and must start (and install their signal handlers) before numba and the tables load.
# The imports for the annotations below are for the type checker only.

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from sphere_sim.kicks.lookup_table import ProgrammedKickPlant
    from sphere_sim.model.parameters import ParameterSet
    from sphere_sim.model.scene import Scene
    from sphere_sim.twin.fidelity_check import FidelityCheck
    from sphere_sim.twin.plants import ContinuousPlant, DiscretePlant, RestPose, TwinPlant

# The first is what the simulator runs unless told otherwise (plant_and_fidelity): the physics,
# which publishes every topic.
PLANT_KINDS = ('continuous', 'discrete')
# The ladder of models (sphere_sim.model.fidelity.LADDER, written out: the node modules import
# this one before numba loads; test_fidelity checks the two agree). The continuous plant
# integrates a model rung, the discrete plant is the last rung, the table.
FIDELITIES = ('full', 'sliding', 'table')
TABLE_FIDELITY = FIDELITIES[-1]
# The live default: the fastest rung within the live error budget on the ladder's kick set
# (bench/results/fidelity.md). The sliding rung is a third of the cost but lands 5e-3 rad off
# at the 95th percentile, fifty times the budget.
LIVE_FIDELITY = 'full'


def plant_and_fidelity(plant: str = '', fidelity: str = '') -> tuple[str, str]:
    """The plant kind and the rung of the ladder it serves kicks from, from the simulator's
    ``plant`` and ``fidelity`` parameters.

    Either alone decides: ``fidelity`` 'table' is the discrete plant and a model rung the
    continuous one; ``plant`` 'discrete' is the table and 'continuous' the live default rung.
    '' leaves it to the other; both '' is the continuous plant on :data:`LIVE_FIDELITY`.

    Raises
    ------
    PlantError
        For an unknown plant or fidelity (naming the choices), or a pair that disagree.
    """
    from sphere_sim.twin.plants import PlantError

    if plant and plant not in PLANT_KINDS:
        raise PlantError(f'unknown plant {plant!r}; choose one of {", ".join(PLANT_KINDS)}')
    if fidelity and fidelity not in FIDELITIES:
        raise PlantError(f'unknown fidelity {fidelity!r}; choose one of '
                         f'{", ".join(FIDELITIES)} (docs/numerics.md, the ladder of models)')
    if not fidelity:
        fidelity = TABLE_FIDELITY if plant == 'discrete' else LIVE_FIDELITY
    kind = 'discrete' if fidelity == TABLE_FIDELITY else 'continuous'
    if plant and plant != kind:
        raise PlantError(f'fidelity {fidelity!r} is served by the {kind} plant, not the {plant} '
                         'one: the discrete plant looks kicks up in the table, the continuous '
                         f'plant integrates a model ({", ".join(FIDELITIES[:-1])})')
    return kind, fidelity


def build_plant(kind: str = '', scene_name: str = 'rest', table_paths: Iterable[str | Path] = (),
                params_name: str = '', fidelity: str = '') -> ContinuousPlant | DiscretePlant:
    """The plant of ``kind`` and ``fidelity`` (:func:`plant_and_fidelity`) for the scene's
    parameters and initial tilt.

    ``params_name`` (a shipped set or a YAML file) replaces the scene's parameter set; '' keeps
    it. A reduced rung is the scene with the rung's mechanism left out
    (:meth:`~sphere_sim.model.fidelity.Rung.scene`), started from the full model's rest: the
    state the live twin would hold had it run the full model until then.

    The discrete plant executes the kicks of its tables and refuses tables built for other
    parameters than the scene's (:class:`~sphere_sim.kicks.lookup_table.TableError`).

    Raises
    ------
    PlantError
        For an unknown kind or fidelity, or a pair that disagree.
    FidelityError
        For a rung that leaves out a mechanism the scene does not have.
    """
    from sphere_sim.kicks.design import KICK_RELAXATION
    from sphere_sim.kicks.discrete import kick_period_s, normal_from_cardan
    from sphere_sim.kicks.lookup_table import load_kick_model
    from sphere_sim.model.assembly import assemble
    from sphere_sim.model.fidelity import carried_state, rung_named
    from sphere_sim.model.initial_state import initial_state
    from sphere_sim.twin.plants import ContinuousPlant, RestPose

    kind, fidelity = plant_and_fidelity(kind, fidelity)
    scene, params = scene_and_parameters(scene_name, params_name)
    # Refused before the seconds below: a rung that cannot run the scene.
    rung_scene = None if kind == 'discrete' else rung_named(fidelity).scene(scene)
    alpha, beta, _ = scene.initial.sphere_angles_deg
    # The continuous plant takes only the kicks' timing from the tables (when a kick's effect
    # is over): they need not be built for this parameter set. Loaded first: a bad table is
    # refused before the seconds of the rest below.
    kicks = load_kick_model(table_paths, params if kind == 'discrete' else None)
    model = assemble(scene, params)
    # A node's start waits for this: relaxed as the tables relax their nodes (KICK_RELAXATION).
    x0 = initial_state(model, relaxation=KICK_RELAXATION)
    if rung_scene is not None:
        rung_model = model if rung_scene is scene else assemble(rung_scene, params)
        return ContinuousPlant(rung_model, carried_state(model, rung_model, x0),
                               kick_period_s=kick_period_s(kicks))
    # The sphere and beams it reports rest where the continuous plant starts (the scene's
    # initial state), so both plants publish the same state until the first kick.
    return discrete_plant(kicks, normal_from_cardan(alpha, beta), RestPose.of_state(model, x0))


def plant_rung(plant: ContinuousPlant | DiscretePlant | TwinPlant) -> str:
    """The rung of the ladder of models that ``plant`` serves kicks from: its model's, the
    table, or 'other' for a plant of neither kind (a test's)."""
    from sphere_sim.model.fidelity import TABLE_RUNG, rung_of_scene
    from sphere_sim.twin.plants import ContinuousPlant, DiscretePlant

    if isinstance(plant, ContinuousPlant):
        return rung_of_scene(plant.model.scene).name
    return TABLE_RUNG if isinstance(plant, DiscretePlant) else 'other'


def fidelity_check(scene_name: str, params_name: str, period_s: float) -> FidelityCheck:
    """The full model of the scene (with ``params_name``'s set, '' for its own) run beside the
    twin on every kick, whichever plant serves them (:mod:`sphere_sim.twin.fidelity_check`)."""
    from msg_defs.device import KICK_WINDOW_S
    from sphere_sim.model.assembly import assemble
    from sphere_sim.twin.fidelity_check import FidelityCheck

    return FidelityCheck(assemble(*scene_and_parameters(scene_name, params_name)),
                         KICK_WINDOW_S, period_s)


def scene_and_parameters(scene_name: str, params_name: str) -> tuple[Scene, ParameterSet]:
    """The simulator's scene and the set it runs on: ``params_name``'s (a shipped set or a
    YAML file) with the scene's perturbation, or the scene's own for ''."""
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_sim.model.scene import load_scene

    scene = load_scene(scene_name)
    return scene, scene.parameters(load_parameter_set(params_name) if params_name else None)


def discrete_plant(kicks: ProgrammedKickPlant, normal0: NDArray[np.float64],
                   rest: RestPose | None = None) -> DiscretePlant:
    """The discrete plant of the kick model ``kicks``, resting at ``normal0`` (and, given
    ``rest``, reporting the sphere's and beams' resting state too)."""
    from sphere_sim.kicks.discrete import kick_period_s
    from sphere_sim.twin.plants import DiscretePlant

    # A kick lands when it has settled (every kick of the shipped tables is within 0.005 deg
    # of its outcome by 45 ms), after the kick period the offline loop and the controller
    # use, not at the end of the longer window the table was built with.
    return DiscretePlant(kicks, normal0, kick_period_s(kicks), rest)
