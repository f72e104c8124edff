"""The models a process assembles for the kicks it runs: once per scene and parameter set.

Every kick workload (table builds, kick optimisations, identification fits) runs its kicks as
tasks that carry only their inputs, so that they pickle small; the process that runs a task
takes the model from here, and an engine's worker (:mod:`sphere_sim.kicks.engine`) keeps it
between tasks and workloads instead of assembling it for each.
"""

from functools import lru_cache

from sphere_sim.model.assembly import Model, assemble
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.scene import load_scene

# A calibration moves between a few parameter sets, an identification between its probes'.
MODELS_PER_PROCESS = 8


@lru_cache(maxsize=MODELS_PER_PROCESS)
def process_model(params: ParameterSet | None, scene_name: str = 'rest') -> Model:
    """The model of ``scene_name`` with ``params`` (the scene's own set if None), assembled
    once in this process."""
    return assemble(load_scene(scene_name), params)
