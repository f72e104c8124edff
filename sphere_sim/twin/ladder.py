"""The ladder of models, measured: each rung's landing error against the full model and its cost.

A fixed kick set (the diagonal and the axis designs of the shipped tables, at intensities 0.6,
0.8 and 1, from rest at level and at 20 and 35 deg of tilt) is run on the full model at rtol
1e-9, the reference, and on every rung as the live twin would run it: the model rungs
(:mod:`sphere_sim.model.fidelity`) integrated from the full model's rest state at the live
tolerance (the full model also at tighter ones: a tolerance is the numerics' rung), the table
rung looked up. Each rung's landing errors (median, 95th percentile, max) stand
beside its CPU time per kick, and against the live budget: a rung may serve the live twin only
where its 95th percentile is at most a tenth of the sensor noise and its maximum at most the
sensor noise.

Computes and returns; ``sphere-twin bench fidelity`` prints and writes.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
import time
from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from sphere_sim.integrate.solve import DEFAULT_METHOD, simulate
from sphere_sim.integrate.tolerances import LIVE_METHOD, LIVE_RTOL
from sphere_sim.kicks.design import KICK_RELAXATION, cardan_of_normal
from sphere_sim.kicks.discrete import NOISE_STUDY_STD_RAD
from sphere_sim.kicks.engine import SerialEngine
from sphere_sim.kicks.lookup_table import AXIS_TABLE_PATH, DEFAULT_TABLE_PATH, LookupTable
from sphere_sim.kicks.process_models import process_model
from sphere_sim.model.assembly import Model, assemble
from sphere_sim.model.fidelity import RUNGS, TABLE_RUNG, carried_state, rung_named
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet, load_parameter_set
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.rotations import angle_between
from sphere_sim.model.scene import load_scene
from sphere_sim.twin.plants import LIVE_ERROR_BOUND_RAD

# The reference: the full model at this tolerance (a kick then lands within about 1e-8 rad of
# the converged landing, bench/results/work_precision.md).
REFERENCE_RTOL = 1e-9
QUICK_REFERENCE_RTOL = 1e-7
REFERENCE_METHOD = DEFAULT_METHOD  # the studies' (bench/results/work_precision.md)
# The live budget: a rung serves the live twin only within both (the sensor noise of the noise
# study, 9.4e-4 rad, and a tenth of it).
LIVE_P95_BUDGET_RAD = 0.1 * NOISE_STUDY_STD_RAD
LIVE_MAX_BUDGET_RAD = NOISE_STUDY_STD_RAD
# The kick set: 2 designs x 3 intensities x 5 starts = 30 kicks. The tilted starts lie 20 deg
# off the device's mirror lines (multiples of 45 deg), where rounding decides a landing.
TABLE_PATHS = {'diagonal': DEFAULT_TABLE_PATH, 'axis': AXIS_TABLE_PATH}
INTENSITIES = (0.6, 0.8, 1.0)
STARTS_DEG = ((0.0, 0.0), (20.0, 20.0), (20.0, 200.0), (35.0, 20.0), (35.0, 200.0))
QUICK_KICKS = 4
# CPU time of a rung's kick: the fastest of this many runs (the machine is shared).
TIMING_REPEATS = 2
# The ladder's rows: a rung, the tolerance it is integrated at (None for the table) and the
# method. The full model at tighter tolerances shows what the live tolerance itself costs in
# landing error; the Rosenbrock W-method (docs/numerics.md) what a cheaper step buys on each
# model rung.
ROWS: tuple[tuple[str, float | None, str], ...] = (
    ('full', LIVE_RTOL, 'fast'), ('full', 1e-5, 'fast'), ('full', 3e-6, 'fast'),
    ('full', 1e-6, 'fast'), ('full', LIVE_RTOL, 'rosenbrock'),
    ('full', 1e-5, 'rosenbrock'), ('sliding', LIVE_RTOL, 'fast'),
    ('sliding', LIVE_RTOL, 'rosenbrock'), (TABLE_RUNG, None, LIVE_METHOD))
QUICK_ROWS: tuple[tuple[str, float | None, str], ...] = (
    ('full', LIVE_RTOL, LIVE_METHOD), ('sliding', LIVE_RTOL, LIVE_METHOD),
    (TABLE_RUNG, None, LIVE_METHOD))
assert ('full', LIVE_RTOL, LIVE_METHOD) in ROWS  # the row the twin runs


def tilted_normal(tilt_deg: float, azimuth_deg: float) -> NDArray[np.float64]:
    """The unit normal tilted ``tilt_deg`` from level towards the polar angle ``azimuth_deg``."""
    tilt, azimuth = math.radians(tilt_deg), math.radians(azimuth_deg)
    return np.array([math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth),
                     math.cos(tilt)])


@dataclasses.dataclass(frozen=True)
class LadderKick:
    """One kick of the set: a table's design (its action 0) at an intensity, from rest at a
    tilt (deg) towards an azimuth (deg)."""

    design: str
    intensity: float
    tilt_deg: float
    azimuth_deg: float

    @property
    def normal(self) -> NDArray[np.float64]:
        return tilted_normal(self.tilt_deg, self.azimuth_deg)

    @property
    def label(self) -> str:
        return (f'{self.design} u={self.intensity:g} from {self.tilt_deg:g} deg'
                + (f' at {self.azimuth_deg:g} deg' if self.tilt_deg else ''))


def kick_set(quick: bool = False) -> list[LadderKick]:
    """The ladder's kicks (a spread of ``QUICK_KICKS`` of them when ``quick``)."""
    kicks = [LadderKick(design, u, tilt, azimuth) for design in TABLE_PATHS
             for u in INTENSITIES for tilt, azimuth in STARTS_DEG]
    if quick:
        # Off the mirror lines, one of each design at the ends of the intensities.
        kicks = [k for k in kicks if k.tilt_deg == 20.0 and k.azimuth_deg == 20.0
                 and k.intensity in (INTENSITIES[0], INTENSITIES[-1])][:QUICK_KICKS]
    return kicks


@lru_cache(maxsize=4)
def _table(design: str, params: ParameterSet) -> LookupTable:
    return LookupTable.load(TABLE_PATHS[design], params=params)


@lru_cache(maxsize=64)
def _rest(params: ParameterSet, tilt_deg: float, azimuth_deg: float) -> NDArray[np.float64]:
    return rest_state(process_model(params),
                      cardan_of_normal(tilted_normal(tilt_deg, azimuth_deg)),
                      relaxation=KICK_RELAXATION)


@lru_cache(maxsize=8)
def _rung_model(name: str, params: ParameterSet) -> Model:
    return assemble(rung_named(name).scene(load_scene('rest')), params)


def _programme_of(kick: LadderKick, params: ParameterSet) -> PulseProgramme:
    return _table(kick.design, params).programme(0, kick.intensity, kick.normal)


def landing(rung: str, kick: LadderKick, params: ParameterSet, rtol: float = LIVE_RTOL,
            method: str = LIVE_METHOD) -> tuple[NDArray[np.float64], float]:
    """(landing normal, CPU s) of ``kick`` on ``rung``: a model rung integrated at ``rtol`` by
    ``method`` from the full model's rest state (the state the live twin holds), the table
    looked up."""
    window_s = _table(kick.design, params).spec.window_s
    if rung == TABLE_RUNG:
        started = time.process_time()
        result = _table(kick.design, params).kick(kick.normal, 0, kick.intensity)
        return np.asarray(result.normal, dtype=float), time.process_time() - started
    full = process_model(params)
    model = _rung_model(rung, params)
    x0 = carried_state(full, model, _rest(params, kick.tilt_deg, kick.azimuth_deg))
    programme = _programme_of(kick, params)
    started = time.process_time()
    traj = simulate(model, x0, window_s, programme, rtol=rtol, sample_period_s=window_s,
                    method=method)
    cpu_s = time.process_time() - started
    return model.surface_normal(traj.final_state), cpu_s


def reference_landing(job: tuple[LadderKick, ParameterSet, float]) -> NDArray[np.float64]:
    """The full model's landing of one kick at the reference tolerance (a pool's task)."""
    kick, params, rtol = job
    return landing('full', kick, params, rtol, REFERENCE_METHOD)[0]


@dataclasses.dataclass(frozen=True)
class RungResult:
    """A rung's landing errors (rad) and CPU seconds, kick by kick, at tolerance ``rtol`` (None
    for the table) by ``method``."""

    name: str
    leaves_out: str
    errors_rad: tuple[float, ...]
    cpu_s: tuple[float, ...]
    rtol: float | None = None
    method: str = LIVE_METHOD

    @property
    def label(self) -> str:
        if self.rtol is None:
            return self.name
        return f'{self.name} ({self.method}, rtol {self.rtol:g})'

    @property
    def median_rad(self) -> float:
        return float(np.median(self.errors_rad))

    @property
    def p95_rad(self) -> float:
        return float(np.percentile(self.errors_rad, 95))

    @property
    def max_rad(self) -> float:
        return float(np.max(self.errors_rad))

    @property
    def ms_per_kick(self) -> float:
        return 1e3 * statistics.median(self.cpu_s)

    @property
    def meets_live_budget(self) -> bool:
        return self.p95_rad <= LIVE_P95_BUDGET_RAD and self.max_rad <= LIVE_MAX_BUDGET_RAD

    def to_dict(self) -> dict[str, object]:
        return {'name': self.name, 'rtol': self.rtol, 'method': self.method,
                'leaves_out': self.leaves_out,
                'median_rad': self.median_rad, 'p95_rad': self.p95_rad,
                'max_rad': self.max_rad, 'ms_per_kick': self.ms_per_kick,
                'meets_live_budget': self.meets_live_budget,
                'errors_rad': list(self.errors_rad), 'cpu_s': list(self.cpu_s)}


@dataclasses.dataclass(frozen=True)
class Ladder:
    """The measured ladder: the kicks, the reference's rtol and every rung's result."""

    kicks: tuple[LadderKick, ...]
    reference_rtol: float
    rungs: tuple[RungResult, ...]

    def rung(self, name: str, rtol: float | None = LIVE_RTOL,
             method: str = LIVE_METHOD) -> RungResult:
        """The row of rung ``name`` at ``rtol`` by ``method`` (the table's has neither)."""
        return next(r for r in self.rungs
                    if r.name == name and (r.name == TABLE_RUNG
                                           or (r.rtol == rtol and r.method == method)))

    def live_rung(self) -> RungResult | None:
        """The fastest model rung within the live budget (the continuous plant's choice) at
        whatever tolerance, or None where none is."""
        return live_rung_of(self.rungs)

    def to_dict(self) -> dict[str, object]:
        live = self.live_rung()
        return {'reference_rtol': self.reference_rtol, 'live_rtol': LIVE_RTOL,
                'live_p95_budget_rad': LIVE_P95_BUDGET_RAD,
                'live_max_budget_rad': LIVE_MAX_BUDGET_RAD,
                'sensor_noise_rad': NOISE_STUDY_STD_RAD,
                'live_integration_bound_rad': LIVE_ERROR_BOUND_RAD,
                'live_rung': None if live is None else live.label,
                'kicks': [dataclasses.asdict(k) | {'label': k.label} for k in self.kicks],
                'rungs': [r.to_dict() for r in self.rungs]}


def live_rung_of(results: Sequence[RungResult]) -> RungResult | None:
    """The fastest of ``results`` that is a model rung and meets the live budget."""
    serving = [r for r in results if r.name in RUNGS and r.meets_live_budget]
    return min(serving, key=lambda r: r.ms_per_kick, default=None)


def measure_ladder(params: ParameterSet | None = None, quick: bool = False,
                   engine: SerialEngine | None = None,
                   progress: Callable[[str], None] | None = None) -> Ladder:
    """Run the kick set on the reference and on every rung of the ladder.

    The references (seconds a kick) run on ``engine``'s workers; the rungs run here, one kick
    at a time, so that their CPU times are those of one process alone.
    """
    params = load_parameter_set('calibrated') if params is None else params
    engine = SerialEngine() if engine is None else engine
    kicks = kick_set(quick)
    rtol = QUICK_REFERENCE_RTOL if quick else REFERENCE_RTOL
    say = progress or (lambda text: None)
    say(f'reference: the full model at rtol {rtol:g} on {len(kicks)} kicks '
        f'({engine.workers} worker(s))')
    references = engine(reference_landing, [(k, params, rtol) for k in kicks])
    results = []
    for name, row_rtol, method in (QUICK_ROWS if quick else ROWS):
        say(f'rung {name}' + ('' if row_rtol is None else f' at rtol {row_rtol:g} ({method})'))
        errors, cpu = [], []
        for kick, reference in zip(kicks, references, strict=True):
            normal, best_s = landing(name, kick, params, row_rtol or LIVE_RTOL, method)
            for _ in range(TIMING_REPEATS - 1):
                best_s = min(best_s,
                             landing(name, kick, params, row_rtol or LIVE_RTOL, method)[1])
            errors.append(angle_between(reference, normal))
            cpu.append(best_s)
        leaves_out = RUNGS[name].leaves_out if name in RUNGS else \
            'the whole transient: the landing interpolated in the tables built on the full model'
        results.append(RungResult(name, leaves_out, tuple(errors), tuple(cpu), row_rtol,
                                  method))
    return Ladder(tuple(kicks), rtol, tuple(results))
