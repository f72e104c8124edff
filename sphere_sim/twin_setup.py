"""Building the simulator's plant from a scene name and a plant kind (one place for both)."""

from sphere_sim.discrete import normal_from_cardan
from sphere_sim.lookup_table import DEFAULT_TABLE_PATH, LookupTable
from sphere_sim.model import assemble
from sphere_sim.plants import ContinuousPlant, DiscretePlant, PlantError
from sphere_sim.scene import load_scene

PLANT_KINDS = ('discrete', 'continuous')  # also named in sphere_sim.simulator_node


def build_plant(kind, scene_name='rest', table_path=None):
    """The plant of ``kind`` for the scene's parameters and initial tilt.

    The discrete plant takes the kick design its table was built with and refuses a table
    built for other parameters than the scene's (:class:`~sphere_sim.lookup_table.TableError`).

    Raises
    ------
    PlantError
        For an unknown kind.
    """
    scene = load_scene(scene_name)
    if kind == 'continuous':
        return ContinuousPlant(assemble(scene))
    if kind == 'discrete':
        table = LookupTable.load(table_path or DEFAULT_TABLE_PATH, params=scene.parameters())
        alpha, beta, _ = scene.initial.sphere_angles_deg
        return DiscretePlant(table, table.spec.design, normal_from_cardan(alpha, beta),
                             table.spec.window_s)
    raise PlantError(f'unknown plant {kind!r}; choose one of {", ".join(PLANT_KINDS)}')
