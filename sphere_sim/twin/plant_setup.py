"""Building the simulator's plant from a scene name and a plant kind (one place for both)."""

# The physics is imported inside the functions: the node modules import this one for
# PLANT_KINDS and must start (and install their signal handlers) before numba and the tables load.

PLANT_KINDS = ('discrete', 'continuous')


def load_kick_model(table_paths=(), params=None):
    """The discrete kick model: one table, or several combined into one action set.

    Parameters
    ----------
    table_paths : sequence of path
        Empty for the shipped default (the four diagonal kicks).
    params : ParameterSet, optional
        Refuse tables built for other parameters.
    """
    from sphere_sim.kicks.lookup_table import DEFAULT_TABLE_PATH, CombinedKickPlant, LookupTable

    paths = list(table_paths) or [DEFAULT_TABLE_PATH]
    tables = [LookupTable.load(path, params=params) for path in paths]
    return tables[0] if len(tables) == 1 else CombinedKickPlant(tables)


def build_plant(kind, scene_name='rest', table_paths=(), params_name=''):
    """The plant of ``kind`` for the scene's parameters and initial tilt.

    ``params_name`` (a shipped set or a YAML file) replaces the scene's parameter set; '' keeps
    it.

    The discrete plant executes the kicks of its tables and refuses tables built for other
    parameters than the scene's (:class:`~sphere_sim.kicks.lookup_table.TableError`).

    Raises
    ------
    PlantError
        For an unknown kind.
    """
    from sphere_sim.kicks.discrete import normal_from_cardan
    from sphere_sim.model.assembly import assemble
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_sim.model.scene import load_scene
    from sphere_sim.twin.plants import ContinuousPlant, DiscretePlant, PlantError

    if kind not in PLANT_KINDS:
        raise PlantError(f'unknown plant {kind!r}; choose one of {", ".join(PLANT_KINDS)}')
    scene = load_scene(scene_name)
    params = scene.parameters(load_parameter_set(params_name) if params_name else None)
    if kind == 'continuous':
        return ContinuousPlant(assemble(scene, params))
    kicks = load_kick_model(table_paths, params)
    alpha, beta, _ = scene.initial.sphere_angles_deg
    return DiscretePlant(kicks, normal_from_cardan(alpha, beta), kicks.spec.window_s)
