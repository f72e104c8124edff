"""The voltage offsets of §4.1 as a lookup over the resting normal: one design's kick, kept on its
nominal direction from tilted states (Fig. 8).

§4.1 adds an offset v_off to one low beam: V1 when the normal points into the upper-right
half-space of the kick's axis, V2 in the lower-left one, read from a lookup table over a grid of
initial states. The two halves are mirror images (Fig. 7), so the offsets are searched on the
upper-right half only (``sphere-twin primitives offsets``) and the lower-left half takes the
mirror image's offset on the mirror image's beam.

The offset scales with the intensity u_K like the high pair's rise above ``low_v``: at u_K = 0
every beam holds ``low_v`` and there is no kick, with or without an offset on the table. §4.1
gives the offsets for the full kick only; docs/motion_primitives.md says why this reading.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from sphere_sim.kicks.design import KickDesign
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.symmetry import beam_position_angle_rad, kick_axis_mirror

# A node on the kick's axis belongs to the upper-right half (side >= 0) within this distance.
ON_AXIS_TOL = 1e-9


def side_of_axis(direction_rad: float, x_sn: float, y_sn: float) -> float:
    """Signed distance of (x_sn, y_sn) from the kick's axis: > 0 in the upper-right half-space,
    the one left of the kick's direction (for the hind-left kick, y_sn > -x_sn)."""
    return -math.sin(direction_rad) * x_sn + math.cos(direction_rad) * y_sn


def compensating_beam(design: KickDesign, upper_right: bool = True) -> int:
    """The low beam that takes the offset in the upper-right half-space (or the other one).

    The two low beams that the kick's axis mirror swaps are the candidates (§4.1's V1 and V2).
    §4.1 puts the offset on V1, the beam on the right-hand side of the kick's direction, when
    the normal points into the upper-right half, the side left of that direction: the beam on
    the opposite side of the axis from the normal.
    """
    swap = kick_axis_mirror(design.direction_rad).beam_map()
    pair = [b for b in design.low_beams if swap[b] != b and swap[b] in design.low_beams]
    if len(pair) != 2:
        raise ValueError(f'the design has no pair of low beams mirrored at its kick axis '
                         f'(low beams {design.low_beams})')
    right = min(pair, key=lambda b: side_of_axis(design.direction_rad,
                                                 math.cos(beam_position_angle_rad(b)),
                                                 math.sin(beam_position_angle_rad(b))))
    return right if upper_right else swap[right]


class OffsetError(ValueError):
    """A voltage offsets file that cannot be read as one, or one for another kick."""


@dataclasses.dataclass(frozen=True)
class OffsetLookup:
    """v_off (V) of the full kick over the upper-right half of the resting normals.

    Attributes
    ----------
    grid_step : float
        Step of the square grid in x_sn and y_sn the offsets were searched on (0: no offsets).
    nodes : tuple of (x_sn, y_sn, offset_v)
        The searched grid nodes, all in the upper-right half (or on the axis), in the frame of
        the design's own kick direction.
    pushes : tuple of bool
        For each node, whether the compensating beam's tip pushes the sphere until that beam's
        rear lands at the node's offset (the offset's branch,
        :meth:`~sphere_sim.kicks.characteristics.KickBench.tip_pushes`); empty where it was
        not measured, and then every node counts as on one branch.
    """

    grid_step: float = 0.0
    nodes: tuple[tuple[float, float, float], ...] = ()
    pushes: tuple[bool, ...] = ()

    def __post_init__(self) -> None:
        nodes = tuple((float(x), float(y), float(v)) for x, y, v in self.nodes)
        object.__setattr__(self, 'nodes', nodes)
        object.__setattr__(self, 'pushes', tuple(bool(p) for p in self.pushes))
        if nodes and not self.grid_step > 0.0:
            raise ValueError('offsets need the grid step they were searched on')
        if self.pushes and len(self.pushes) != len(nodes):
            raise ValueError(f'{len(self.pushes)} branches for {len(nodes)} offset nodes')

    def __bool__(self) -> bool:
        return bool(self.nodes)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> OffsetLookup:
        return cls(float(data.get('grid_step', 0.0)), tuple(map(tuple, data.get('nodes', ()))),
                   tuple(data.get('pushes', ())))

    @classmethod
    def load(cls, path: str | Path, design: KickDesign, parameter_set: str) -> OffsetLookup:
        """The offsets saved by ``sphere-twin primitives offsets`` for ``design`` on the named
        parameter set.

        Raises
        ------
        OffsetError
            For a file that is not such a JSON, or one searched for another design or set
            (OSError for one that cannot be read).
        """
        try:
            data = json.loads(Path(path).read_text())
            searched = (data['design'], data['parameter_set'])
            states = data['states']
            pushes = [s.get('pushes') for s in states]
            lookup = cls(float(data['grid_step']),
                         tuple((s['x_sn'], s['y_sn'], s['offset_v']) for s in states),
                         () if None in pushes else tuple(pushes))
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise OffsetError(f'{path} holds no voltage offsets saved by `sphere-twin '
                              f'primitives offsets`: {type(exc).__name__}: {exc}') from exc
        if searched != (json.loads(json.dumps(design.to_dict())), parameter_set):
            raise OffsetError(f'{path} holds the offsets of another kick design or parameter '
                              f'set (searched on {data["parameter_set"]!r}); search them with '
                              f'`sphere-twin primitives offsets` for this design on '
                              f'{parameter_set!r}')
        return lookup

    def offset_v(self, direction_rad: float, x_sn: float, y_sn: float) -> float:
        """The full kick's offset at (x_sn, y_sn), bilinear over the grid, on one branch.

        A point of the lower-left half reads its mirror image's offset; grid nodes the search
        left out (beyond the cone) take the nearest searched node's. In a cell whose corners lie
        on both branches (:attr:`pushes`), the point takes the branch that holds most of its
        bilinear weight (the pushing one at a tie) and the weighted mean of that branch's
        corners: between the branches lies the band where the compensating beam's tip loses
        the sphere and strikes it again, and a mean across it would put the offset there
        (docs/motion_primitives.md, "Two branches of the offset").
        """
        if not self.nodes:
            return 0.0
        grid, pushing, axis = _full_grid(self, round(direction_rad, 12))
        point = np.array([x_sn, y_sn, 1.0])
        if side_of_axis(direction_rad, x_sn, y_sn) < 0.0:
            point = kick_axis_mirror(direction_rad).apply_vector(point)
        u = np.clip((point[:2] - axis[0]) / self.grid_step, 0.0, axis.size - 1)
        i, j = np.minimum(np.floor(u).astype(int), axis.size - 2)
        fx, fy = u - (i, j)
        corners = (slice(i, i + 2), slice(j, j + 2))
        weights = np.outer((1 - fx, fx), (1 - fy, fy))
        branch = pushing[corners]
        if branch.any() and not branch.all():
            branch = branch if weights[branch].sum() >= 0.5 else ~branch
            weights = np.where(branch, weights, 0.0)
        return float(np.sum(weights * grid[corners]) / np.sum(weights))

    def programme(self, design: KickDesign, x_sn: float, y_sn: float, intensity: float,
                  upper_right: bool | None = None) -> PulseProgramme:
        """The design's programme at ``intensity`` with the offset for a rest at (x_sn, y_sn).

        ``upper_right`` chooses the half whose beam takes the offset; by default the half the
        point lies in (§4.1's rule). The table's nodes beyond the axis keep the upper-right
        beam, so that its interpolation near the axis follows one programme.
        """
        if upper_right is None:
            upper_right = side_of_axis(design.direction_rad, x_sn, y_sn) >= -ON_AXIS_TOL
        offset = intensity * self.offset_v(design.direction_rad, x_sn, y_sn)
        if offset == 0.0:
            return design.programme(intensity)
        return design.programme(intensity, offset, compensating_beam(design, upper_right))


@functools.lru_cache(maxsize=8)
def _full_grid(lookup: OffsetLookup, direction_rad: float
               ) -> tuple[NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]:
    """The offsets and their branches on the whole square grid: the searched half, its mirror
    image, and the nearest searched node's beyond the cone."""
    step = lookup.grid_step
    half = max(round(max(abs(c) for n in lookup.nodes for c in n[:2]) / step), 1)
    axis = step * np.arange(-half, half + 1)
    grid = np.full((axis.size, axis.size), np.nan)
    pushing = np.zeros(grid.shape, dtype=bool)
    mirror = kick_axis_mirror(direction_rad)
    pushes = lookup.pushes or (False,) * len(lookup.nodes)
    for (x, y, v), push in zip(lookup.nodes, pushes, strict=True):
        for px, py, _ in (np.array([x, y, 1.0]), mirror.apply_vector([x, y, 1.0])):
            grid[round(px / step) + half, round(py / step) + half] = v
            pushing[round(px / step) + half, round(py / step) + half] = push
    known = np.argwhere(np.isfinite(grid))
    for i, j in np.argwhere(~np.isfinite(grid)):
        nearest = tuple(known[np.argmin(np.hypot(*(known - (i, j)).T))])
        grid[i, j] = grid[nearest]
        pushing[i, j] = pushing[nearest]
    return grid, pushing, cast(NDArray[np.float64], axis)
