"""The work-precision scenes of this tree: the optimised diagonal kick of bench/results (or the
paper's template when none was optimised), shared by ``bench work-precision`` and
``bench levers``."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

from sphere_sim.kicks.design import KickDesign
from sphere_sim.model.assembly import assemble
from sphere_sim.model.fidelity import rung_named
from sphere_sim.model.scene import load_scene
from sphere_sim.studies.work_precision import BenchScene, bench_scenes, sliding_scene

RESULTS_DIR = Path(__file__).resolve().parents[2] / 'bench' / 'results'
KICK_FILE = RESULTS_DIR / 'kick_optimization.json'


def optimised_design() -> tuple[KickDesign, bool]:
    """The optimised diagonal kick of bench/results/kick_optimization.json (or the paper's)."""
    if not KICK_FILE.exists():
        return KickDesign(), False
    data = json.loads(KICK_FILE.read_text())['design']
    fields = {f.name for f in dataclasses.fields(KickDesign)}
    kwargs: dict[str, Any] = {k: (tuple(v) if isinstance(v, list) else v)
                              for k, v in data.items() if k in fields}
    return KickDesign(**kwargs), True


def scenes_of_this_tree() -> list[BenchScene]:
    """The benchmark's scenes with the optimised diagonal kick of bench/results (or the
    paper's template when none was optimised)."""
    design, optimised = optimised_design()
    label = 'optimised diagonal kick' if optimised else '35 V / 80 V asymmetric pulse pair'
    return bench_scenes(assemble(load_scene('rest')), design.programme(), label)




def work_precision_scenes() -> list[BenchScene]:
    """:func:`scenes_of_this_tree` and the same kick on the ladder's sliding rung."""
    design, optimised = optimised_design()
    label = 'optimised diagonal kick' if optimised else '35 V / 80 V asymmetric pulse pair'
    sliding = assemble(rung_named('sliding').scene(load_scene('rest')))
    return [*scenes_of_this_tree(), sliding_scene(sliding, design.programme(), label)]
