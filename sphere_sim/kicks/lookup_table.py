"""The discrete model x_{t+1} = f(x_t, a_t, u_K) as a lookup table over the kick's outcomes (§5).

The table holds, for the reference kick (the hind-left design) at resting normals on a grid of
(x_sn, y_sn) inside the cone and intensities u_K, the normal's displacement at the end of the
kick window, the transient peak and the settling time; it is linearly interpolated. Other kick
directions and the other half of the cone are images under the device's symmetry (Fig. 7): the
grid covers only y_sn >= -x_sn (plus one band of nodes beyond it, for interpolation). Each kick
carries §4.1's voltage offset for its state (:mod:`sphere_sim.kicks.offset_lookup`), so a kick's
programme depends on the normal it starts from: ``programme(action, intensity, normal)``.

A table is a ``.npz`` file carrying its format version and the digests of the parameter set and
of the kick it was built from; loading it for other parameters is refused.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, cast

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import RegularGridInterpolator

from msg_defs.device import DEFAULT_PARAMETER_SET, KICK_WINDOW_S
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.kicks.design import KickDesign
from sphere_sim.kicks.discrete import CONE_HALF_ANGLE_RAD, LEVEL_NORMAL, KickPlant, KickResult
from sphere_sim.kicks.offset_lookup import OffsetLookup, side_of_axis
from sphere_sim.model.parameters import ParameterSet, load_parameter_set
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.symmetry import Symmetry, kick_axis_mirror

TABLE_FORMAT_VERSION = 1
DEFAULT_TABLE_PATH = Path(__file__).parents[1] / 'tables' / 'default_kick_table.npz'
# The axis-parallel kick's table: with the default one, the eight directions of §6.
AXIS_TABLE_PATH = Path(__file__).parents[1] / 'tables' / 'axis_kick_table.npz'
CONE_MARGIN = 1.05  # nodes slightly beyond the cone keep interpolation inside it linear


class TableError(ValueError):
    """A table file that is missing, malformed, of another version or for other parameters."""


class ProgrammedKickPlant(KickPlant, Protocol):
    """A :class:`~sphere_sim.kicks.discrete.KickPlant` that also says how each kick is driven:
    its design and the pulse programme that makes it.

    The tables (:class:`LookupTable`, :class:`CombinedKickPlant`) implement it; the discrete
    plant decodes programmes through it (:func:`sphere_sim.twin.plants.decode_kick`), and the
    controllers send what ``programme`` gives.
    """

    def design(self, action: int) -> KickDesign:
        """The kick design whose turned image ``action`` (index into ``directions_rad``) is."""
        ...

    def programme(self, action: int, intensity: float,
                  normal: NDArray[np.float64] = LEVEL_NORMAL) -> PulseProgramme:
        """The pulse programme of kick ``action`` at ``intensity`` in [0, 1] from rest at
        ``normal`` (with the voltage offset for that normal, §4.1)."""
        ...


@dataclasses.dataclass(frozen=True)
class TableSpec:
    """What a table is built from: grid, intensities, kick design, window and parameters."""

    # About 4.6 deg. With 0.12 and six intensities the check found 0.067 deg against direct
    # simulation, most of it along u_K, where the pull-in threshold bends the outcome.
    grid_step: float = 0.08
    # Denser towards full intensity, where the optimised kicks' width rises steeply and smoothly
    # (0.12 deg at u_K = 0.9, 0.73 deg at 1; docs/motion_primitives.md): a uniform 0.1 step
    # left 0.14 deg of interpolation error there, 0.01 steps leave about 1e-3 deg. Dense too
    # across the high pair's pull-in, where the width jumps (from the level state 0.044 deg at
    # 0.54, 0.242 deg at 0.56): the calibrated intensities of small kicks fall there
    # (sphere_control.intensity_calibration), and 0.5 and 0.6 alone interpolated across it.
    intensities: tuple[float, ...] = (0.0, 0.2, 0.4, 0.5, 0.52, 0.54, 0.55, 0.56, 0.57, 0.58,
                                      0.6, 0.65, 0.7, 0.75, 0.8, 0.84, 0.87, 0.9, 0.92, 0.94,
                                      0.95, 0.96, 0.97, 0.98, 0.99, 1.0)
    window_s: float = KICK_WINDOW_S
    rtol: float = DEFAULT_RTOL
    parameter_set: str = DEFAULT_PARAMETER_SET
    design: KickDesign = dataclasses.field(default_factory=KickDesign)
    cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD
    # §4.1's voltage offsets on the design's compensating beams; none by default.
    offsets: OffsetLookup = dataclasses.field(default_factory=OffsetLookup)

    def __post_init__(self) -> None:
        outside = [math.hypot(x, y) for _, _, x, y in self.nodes() if math.hypot(x, y) >= 1.0]
        if outside:
            raise TableError(
                f'grid step {self.grid_step:g} puts table nodes at x_sn^2 + y_sn^2 = '
                f'{max(outside) ** 2:.3g} >= 1, where no surface normal is (a tilt of 90 deg '
                f'or more): the {math.degrees(self.cone_half_angle_rad):g} deg cone and its '
                f'band of nodes beyond fit inside the unit disk with a grid step below '
                f'{self.largest_safe_grid_step():.3g}')

    def largest_safe_grid_step(self) -> float:
        """Below this step every node lies inside the unit disk (a sufficient bound: the nodes
        reach at most one step beyond the cone and its margin)."""
        return 1.0 - CONE_MARGIN * math.sin(self.cone_half_angle_rad)

    def axis(self) -> NDArray[np.float64]:
        """Grid nodes (shape (n,)) of x_sn and of y_sn, symmetric about 0."""
        half = math.ceil(CONE_MARGIN * math.sin(self.cone_half_angle_rad) / self.grid_step)
        return cast(NDArray[np.float64], self.grid_step * np.arange(-half, half + 1))

    def nodes(self) -> list[tuple[int, int, float, float]]:
        """(i, j, x, y) of the nodes to simulate: within the cone and not deep below y = -x."""
        axis = self.axis()
        out = []
        for i, x in enumerate(axis):
            for j, y in enumerate(axis):
                reach = CONE_MARGIN * math.sin(self.cone_half_angle_rad) + self.grid_step
                in_cone = math.hypot(x, y) <= reach
                if in_cone and self.side(x, y) >= -1.5 * self.grid_step:
                    out.append((i, j, float(x), float(y)))
        return out

    def side(self, x: float, y: float) -> float:
        """Signed distance of (x, y) from the kick's own axis, > 0 on the simulated side."""
        return side_of_axis(self.design.direction_rad, x, y)

    def node_programme(self, x_sn: float, y_sn: float, intensity: float) -> PulseProgramme:
        """The programme simulated at a node: the design with the offset of the upper-right
        half's beam, also at the band of nodes beyond the axis, so that the interpolation
        between the axis and those nodes follows one programme."""
        return self.offsets.programme(self.design, x_sn, y_sn, intensity, upper_right=True)

    def programme(self, action: int, intensity: float,
                  normal: NDArray[np.float64] = LEVEL_NORMAL) -> PulseProgramme:
        """Kick ``action`` (the design turned by ``action`` quarter turns) at ``intensity`` from
        rest at ``normal``, with the offset §4.1's half-space rule gives for that normal."""
        g = Symmetry(int(action) % 4)
        local = g.inverse().apply_vector(normal)
        return g.apply_programme(self.offsets.programme(self.design, local[0], local[1],
                                                        float(intensity)))

    def to_dict(self) -> dict[str, Any]:
        return json.loads(json.dumps(_jsonable(self)))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TableSpec:
        data = dict(data)
        design = dict(data.pop('design'))
        design['low_beams'] = tuple(design['low_beams'])
        design['high_beams'] = tuple(design['high_beams'])
        data['intensities'] = tuple(data['intensities'])
        data['offsets'] = OffsetLookup.from_dict(data.get('offsets', {}))
        return cls(design=KickDesign(**design), **data)

    def digest(self, params_digest: str) -> str:
        text = json.dumps({'spec': _jsonable(self), 'params': params_digest}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def _jsonable(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj):
        # An instance: the specs hold no dataclass types.
        return {k: _jsonable(v) for k, v in dataclasses.asdict(cast(Any, obj)).items()}
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    return obj


@dataclasses.dataclass(frozen=True)
class LookupTable:
    """A built table; implements the :class:`~sphere_sim.kicks.discrete.KickPlant` interface.

    Attributes
    ----------
    axis : ndarray, shape (n,)
    intensities : ndarray, shape (m,)
    displacement : ndarray, shape (n, n, m, 2)
        Normal's x-y displacement of the reference kick (NaN where not simulated).
    peak_rad, settle_s : ndarray, shape (n, n, m)
    meta : dict
    """

    axis: NDArray[np.float64]
    intensities: NDArray[np.float64]
    displacement: NDArray[np.float64]
    peak_rad: NDArray[np.float64]
    settle_s: NDArray[np.float64]
    meta: dict[str, Any]

    if TYPE_CHECKING:
        # Set by __post_init__ (through object.__setattr__: the table is frozen), not fields.
        _spec: TableSpec = dataclasses.field(init=False, repr=False, compare=False)
        _mirror: Symmetry = dataclasses.field(init=False, repr=False, compare=False)
        _interp: RegularGridInterpolator = dataclasses.field(init=False, repr=False,
                                                             compare=False)

    @property
    def directions_rad(self) -> tuple[float, ...]:
        """Nominal direction of each action: the design's kick and its quarter turns."""
        d = self.spec.design.direction_rad
        return tuple(d + q * 0.5 * math.pi for q in range(4))

    def __post_init__(self) -> None:
        spec = TableSpec.from_dict(self.meta['spec'])
        object.__setattr__(self, '_spec', spec)
        object.__setattr__(self, '_mirror', kick_axis_mirror(spec.design.direction_rad))
        grid = (self.axis, self.axis, self.intensities)
        values = np.concatenate([self.displacement, self.peak_rad[..., None],
                                 self.settle_s[..., None]], axis=-1)
        object.__setattr__(self, '_interp', RegularGridInterpolator(
            grid, values, method='linear', bounds_error=False, fill_value=np.nan))

    # --- the KickPlant interface -----------------------------------------------------------
    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        """Interpolated outcome of kick ``action`` (0..3) at ``intensity`` from ``normal``."""
        g = Symmetry(int(action) % 4)
        local = g.inverse().apply_vector(normal)
        mirror = self._spec.side(local[0], local[1]) < 0.0
        if mirror:
            local = self._mirror.apply_vector(local)
        values = self._interp([[local[0], local[1], float(np.clip(intensity, 0.0, 1.0))]])[0]
        if np.any(np.isnan(values)):
            raise TableError(f'normal {np.round(normal, 4).tolist()} lies outside the table')
        moved = np.array([local[0] + values[0], local[1] + values[1], 0.0])
        moved[2] = math.sqrt(max(0.0, 1.0 - moved[0] ** 2 - moved[1] ** 2))
        if mirror:
            moved = self._mirror.apply_vector(moved)
        return KickResult(g.apply_vector(moved), float(values[2]), float(values[3]))

    def design(self, action: int) -> KickDesign:
        """The kick design whose turned image ``action`` is."""
        return self.spec.design

    def programme(self, action: int, intensity: float,
                  normal: NDArray[np.float64] = LEVEL_NORMAL) -> PulseProgramme:
        """The pulse programme of kick ``action`` at ``intensity`` from rest at ``normal``: the
        design turned, with the table's voltage offset for that normal (§4.1's half-space
        rule: the offset's beam follows the half the normal points into)."""
        return self._spec.programme(action, intensity, normal)

    def direction_errors_rad(self, intensity: float = 1.0) -> NDArray[np.float64]:
        """|direction - nominal| (rad) of the reference kick at ``intensity`` from every node
        of the simulated half inside the cone: how far the table's kicks stray from their
        nominal direction, the offsets' measure (§4.1)."""
        k = int(np.argmin(np.abs(self.intensities - intensity)))
        d = self._spec.design.direction_rad
        return np.array([abs(math.remainder(math.atan2(self.displacement[i, j, k, 1],
                                                       self.displacement[i, j, k, 0]) - d,
                                            2.0 * math.pi)) for i, j in self._simulated_inside()])

    def largest_stray_kick_rad(self) -> float:
        """The largest displacement (rad) among the simulated kicks from nodes inside the cone
        that have no component along their nominal direction (more than 90 deg off it).

        Below the pull-in, or from far out in the cone, a programme can slip the sphere this
        far in a direction of its own (docs/parameters.md, the ratchet): a kick no longer than
        this says nothing of its action's direction.
        """
        d = self._spec.design.direction_rad
        largest = 0.0
        for i, j in self._simulated_inside():
            for dx, dy in self.displacement[i, j]:
                off = abs(math.remainder(math.atan2(dy, dx) - d, 2.0 * math.pi))
                if off > 0.5 * math.pi:
                    largest = max(largest, math.hypot(dx, dy))
        return largest

    def _simulated_inside(self) -> list[tuple[int, int]]:
        """Grid indices of the simulated half's nodes inside the cone (the other half is its
        mirror image)."""
        spec = self._spec
        return [(i, j) for i, j, x, y in spec.nodes() if spec.side(x, y) >= 0.0
                and math.hypot(x, y) <= math.sin(spec.cone_half_angle_rad)]

    # --- files -----------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, axis=self.axis, intensities=self.intensities,
                            displacement=self.displacement, peak_rad=self.peak_rad,
                            settle_s=self.settle_s, meta=json.dumps(self.meta, sort_keys=True))
        return path

    @classmethod
    def load(cls, path: str | Path = DEFAULT_TABLE_PATH,
             params: ParameterSet | None = None) -> LookupTable:
        """Load a table; with ``params`` given, refuse one built for other parameters."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data['meta']))
                arrays = {k: data[k] for k in ('axis', 'intensities', 'displacement', 'peak_rad',
                                               'settle_s')}
        except FileNotFoundError as exc:
            raise TableError(f'no table at {path}; build one with `sphere-twin table build`') \
                from exc
        except (KeyError, ValueError, OSError) as exc:
            raise TableError(f'{path} is not a sphere_twin kick table: {exc}') from exc
        if meta.get('format_version') != TABLE_FORMAT_VERSION:
            raise TableError(f'{path} has table format {meta.get("format_version")}, this '
                             f'version reads {TABLE_FORMAT_VERSION}; rebuild it')
        if params is not None and meta.get('params_digest') != params.digest():
            raise TableError(
                f'{path} was built for parameter set {meta.get("parameter_set")!r} (digest '
                f'{meta.get("params_digest")}), not for {params.name!r} (digest '
                f'{params.digest()}); rebuild it with `sphere-twin table build`')
        return cls(meta=meta, **arrays)

    @property
    def spec(self) -> TableSpec:
        """The :class:`TableSpec` the table was built from."""
        return self._spec

    def parameters(self) -> ParameterSet:
        """The parameter set the table names, refused if its values changed since the build."""
        params = load_parameter_set(self.meta['parameter_set'])
        if params.digest() != self.meta['params_digest']:
            raise TableError(
                f'the table was built for parameter set {params.name!r} with digest '
                f'{self.meta["params_digest"]}; its values now give {params.digest()}: '
                f'rebuild it with `sphere-twin table build`')
        return params

    @classmethod
    def load_current(cls, path: str | Path = DEFAULT_TABLE_PATH) -> LookupTable:
        """Load a table and refuse it unless its parameter set still has the values it had."""
        table = cls.load(path)
        table.parameters()
        return table


class CombinedKickPlant:
    """The actions of several tables as one action set, ordered by direction.

    With the diagonal and the axis-parallel tables this is the eight-direction action set of
    §6; it implements the same interface as :class:`LookupTable`.

    Parameters
    ----------
    tables : sequence of LookupTable
        Built for the same parameters and window.
    """

    def __init__(self, tables: Sequence[LookupTable]) -> None:
        digests = {t.meta['params_digest'] for t in tables}
        if len(digests) != 1:
            raise TableError('the tables were built for different parameter sets')
        entries = [(math.remainder(d, 2 * math.pi), table, a)
                   for table in tables for a, d in enumerate(table.directions_rad)]
        # Counter-clockwise from the hind-left kick's -45 deg, as DIAGONAL_/EIGHT_DIRECTIONS_RAD.
        entries.sort(key=lambda e: round((e[0] + 0.25 * math.pi) % (2 * math.pi), 9))
        self._entries: list[tuple[LookupTable, int]] = [(table, a) for _, table, a in entries]
        self.directions_rad = tuple(d for d, _, _ in entries)
        self.tables = tuple(tables)
        self.spec = tables[0].spec

    def kick(self, normal: NDArray[np.float64], action: int, intensity: float) -> KickResult:
        table, local = self._entries[action]
        return table.kick(normal, local, intensity)

    def design(self, action: int) -> KickDesign:
        return self._entries[action][0].spec.design

    def largest_stray_kick_rad(self) -> float:
        """The largest of the tables' (:meth:`LookupTable.largest_stray_kick_rad`)."""
        return max(table.largest_stray_kick_rad() for table in self.tables)

    def programme(self, action: int, intensity: float,
                  normal: NDArray[np.float64] = LEVEL_NORMAL) -> PulseProgramme:
        table, local = self._entries[action]
        return table.programme(local, intensity, normal)


def load_kick_model(table_paths: Iterable[str | Path] = (),
                    params: ParameterSet | None = None) -> LookupTable | CombinedKickPlant:
    """The discrete kick model: one table, or several combined into one action set.

    Parameters
    ----------
    table_paths : sequence of path
        Empty for the shipped default (the four diagonal kicks).
    params : ParameterSet, optional
        Refuse tables built for other parameters.
    """
    paths = list(table_paths) or [DEFAULT_TABLE_PATH]
    tables = [LookupTable.load(path, params=params) for path in paths]
    return tables[0] if len(tables) == 1 else CombinedKickPlant(tables)
