"""Scenes: what exists, which effects are on, and what happens (YAML, one loader).

A scene names the beams present, whether the sphere exists, the effects, the capacitance model,
the parameter set, the initial state, the voltage programme and any plant perturbation. The
model is assembled from what the scene declares and nothing else
(see :mod:`~sphere_sim.model.assembly`).
"""

import dataclasses
from collections.abc import Collection
from functools import lru_cache
from pathlib import Path
from typing import Any, Self, overload

from msg_defs.device import BEAM_IDS, DEFAULT_PARAMETER_SET, VOLTAGE_LIMIT_V
from sphere_sim.model.parameters import (
    ParameterError,
    ParameterRule,
    ParameterSet,
    check_number,
    check_parameter,
    load_parameter_set,
    read_yaml_file,
)
from sphere_sim.model.programme import (
    OVERLAP_RULES,
    OverlapRule,
    ProgrammeError,
    PulseProgramme,
)

SCENES_DIR = Path(__file__).parents[1] / 'scenes'
CAPACITANCE_MODELS = ('closed_form', 'rbf')
INITIAL_MODES = ('rest', 'explicit')
EFFECTS = ('gravity', 'electrostatics', 'ground_contact', 'sphere_contact', 'contact_losses',
           'damping')
# ``stiction``: the bristle below the sliding law (its static limit and presliding), where the
# parameter set's friction reading has one; without it the sliding law is regularised at rest
# as eq. (51) does.
FRICTION_TERMS = ('viscous', 'coulomb', 'stribeck', 'stiction')

# The scene's numbers, checked by the parameters' checker: wide physical bounds (a
# millimetre-sized device), refusing what would divide by zero or leave the model.
SCENE_RULES = {
    'duration_s': ParameterRule(float, 's', 0.0, 3600.0, above_low=True),
    'initial_state.sphere_angles_deg': ParameterRule(float, 'deg', -180.0, 180.0),
    'initial_state.sphere_lift_m': ParameterRule(float, 'm', 0.0, 1e-3),
    'initial_state.sphere_position_m': ParameterRule(float, 'm', -1e-2, 1e-2),
    'initial_state.sphere_velocity_m_per_s': ParameterRule(float, 'm/s', -10.0, 10.0),
    'initial_state.sphere_omega_rad_per_s': ParameterRule(float, 'rad/s', -1e4, 1e4),
    'initial_state.beam_z_m': ParameterRule(float, 'm', -1e-3, 1e-3),
    'initial_state.beam_phi_rad': ParameterRule(float, 'rad', -1.0, 1.0),
    # The drivers' own limit is the most a scene may allow (msg_defs.device).
    'voltage_programme.voltage_limit_v': ParameterRule(float, 'V', 0.0, VOLTAGE_LIMIT_V,
                                                       above_low=True),
}


class SceneError(ValueError):
    """A scene file with a bad key or value; the message names the key and what is allowed."""


@dataclasses.dataclass(frozen=True)
class Effects:
    gravity: bool = True
    electrostatics: bool = True
    ground_contact: bool = True
    sphere_contact: bool = True
    contact_losses: bool = True
    damping: bool = True
    viscous: bool = True
    coulomb: bool = True
    stribeck: bool = True
    stiction: bool = True

    @property
    def any_friction(self) -> bool:
        return self.viscous or self.coulomb or self.stribeck


@dataclasses.dataclass(frozen=True)
class InitialState:
    """Initial condition.

    ``rest``: beams (and sphere) at static equilibrium for the given sphere orientation; the
    sphere may be lifted by ``sphere_lift_m`` above its resting height. ``explicit``: the
    values as given (missing values are zero; the sphere orientation from the angles).
    """

    mode: str = 'rest'
    sphere_angles_deg: tuple[float, ...] = (0.0, 0.0, 0.0)
    sphere_lift_m: float = 0.0
    sphere_position_m: tuple[float, ...] | None = None
    sphere_velocity_m_per_s: tuple[float, ...] = (0.0, 0.0, 0.0)
    sphere_omega_rad_per_s: tuple[float, ...] = (0.0, 0.0, 0.0)
    beam_z_m: tuple[float, ...] | None = None
    beam_phi_rad: tuple[float, ...] | None = None


@dataclasses.dataclass(frozen=True)
class Scene:
    name: str
    description: str
    parameter_set: str
    beams: tuple[int, ...]
    sphere: bool
    effects: Effects
    capacitance: str
    initial: InitialState
    programme: PulseProgramme
    duration_s: float
    # ((dotted parameter path, value), ...)
    perturbation: tuple[tuple[str, float | bool | str], ...] = ()

    def parameters(self, base: ParameterSet | None = None) -> ParameterSet:
        """The parameter set (``base`` instead of the one named, if given) with the plant
        perturbation applied."""
        params = load_parameter_set(self.parameter_set) if base is None else base
        if self.perturbation:
            params = params.replace(**dict(self.perturbation))
        return params

    def replace(self, **changes: Any) -> Self:
        return dataclasses.replace(self, **changes)


def _require_mapping(value: Any, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise SceneError(f'{key!r} must be a mapping, got {type(value).__name__}')
    return value


def _check_keys(mapping: Collection[str], allowed: Collection[str], where: str) -> None:
    extra = set(mapping) - set(allowed)
    if extra:
        raise SceneError(f'unknown key(s) {sorted(extra)} in {where}; allowed: {sorted(allowed)}')


def _bool(value: Any, key: str) -> bool:
    if not isinstance(value, bool):
        raise SceneError(f'{key!r} must be true or false, got {value!r}')
    return value


@overload
def _vector(value: None, key: str, length: int) -> None: ...
@overload
def _vector(value: list[Any], key: str, length: int) -> tuple[float, ...]: ...
@overload
def _vector(value: Any, key: str, length: int) -> tuple[float, ...] | None: ...
def _vector(value: Any, key: str, length: int) -> tuple[float, ...] | None:
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise SceneError(f'{key!r} must be a list of {length} numbers, got {value!r}')
    return tuple(_number(v, key, f'{key}[{index}]') for index, v in enumerate(value))


def _number(value: Any, key: str, shown_as: str | None = None) -> float:
    """Scene number ``key`` checked against its SCENE_RULES entry (named ``shown_as``)."""
    try:
        return check_number(shown_as or key, value, SCENE_RULES[key])
    except ParameterError as exc:
        raise SceneError(str(exc)) from exc


def _perturbation(values: Any) -> tuple[tuple[str, float | bool | str], ...]:
    """The plant perturbation's (path, value) pairs, each checked as its parameter."""
    perturbation = _require_mapping(values or {}, 'perturbation')
    try:
        checked = [(str(path), check_parameter(str(path), value))
                   for path, value in perturbation.items()]
    except ParameterError as exc:
        raise SceneError(f"'perturbation': {exc}") from exc
    return tuple(sorted(checked, key=lambda item: item[0]))


def scene_from_dict(data: Any, name: str = 'scene') -> Scene:
    """Build and validate a :class:`Scene` from a parsed YAML mapping."""
    data = _require_mapping(data, name)
    top = ('name', 'description', 'parameters', 'beams', 'sphere', 'effects', 'capacitance',
           'initial_state', 'voltage_programme', 'duration_s', 'perturbation')
    _check_keys(data, top, 'scene')

    beams = data.get('beams', list(BEAM_IDS))
    if (not isinstance(beams, list) or not beams or len(set(beams)) != len(beams)
            or any(isinstance(b, bool) or b not in BEAM_IDS for b in beams)):
        raise SceneError(f"'beams' must be a non-empty list of distinct beam numbers from "
                         f"{list(BEAM_IDS)}, got {beams!r}")
    sphere = _bool(data.get('sphere', True), 'sphere')

    effects_in = _require_mapping(data.get('effects', {}), 'effects')
    _check_keys(effects_in, (*EFFECTS, 'friction'), "'effects'")
    friction_in = effects_in.get('friction', {})
    if isinstance(friction_in, bool):
        friction_in = dict.fromkeys(FRICTION_TERMS, friction_in)
    friction_in = _require_mapping(friction_in, 'effects.friction')
    _check_keys(friction_in, FRICTION_TERMS, "'effects.friction'")
    effects = Effects(
        **{k: _bool(effects_in.get(k, True), f'effects.{k}') for k in EFFECTS},
        **{k: _bool(friction_in.get(k, True), f'effects.friction.{k}') for k in FRICTION_TERMS},
    )

    capacitance = data.get('capacitance', 'closed_form')
    if capacitance not in CAPACITANCE_MODELS:
        raise SceneError(f"'capacitance' must be one of {list(CAPACITANCE_MODELS)}, "
                         f'got {capacitance!r}')

    init_in = _require_mapping(data.get('initial_state', {}), 'initial_state')
    init_fields = [f.name for f in dataclasses.fields(InitialState)]
    _check_keys(init_in, init_fields, "'initial_state'")
    mode = init_in.get('mode', 'rest')
    if mode not in INITIAL_MODES:
        raise SceneError(f"'initial_state.mode' must be one of {list(INITIAL_MODES)}, got {mode!r}")
    n_beams = len(beams)
    initial = InitialState(
        mode=mode,
        sphere_angles_deg=_vector(init_in.get('sphere_angles_deg', [0, 0, 0]),
                                  'initial_state.sphere_angles_deg', 3),
        sphere_lift_m=_number(init_in.get('sphere_lift_m', 0.0), 'initial_state.sphere_lift_m'),
        sphere_position_m=_vector(init_in.get('sphere_position_m'),
                                  'initial_state.sphere_position_m', 3),
        sphere_velocity_m_per_s=_vector(init_in.get('sphere_velocity_m_per_s', [0, 0, 0]),
                                        'initial_state.sphere_velocity_m_per_s', 3),
        sphere_omega_rad_per_s=_vector(init_in.get('sphere_omega_rad_per_s', [0, 0, 0]),
                                       'initial_state.sphere_omega_rad_per_s', 3),
        beam_z_m=_vector(init_in.get('beam_z_m'), 'initial_state.beam_z_m', n_beams),
        beam_phi_rad=_vector(init_in.get('beam_phi_rad'), 'initial_state.beam_phi_rad', n_beams),
    )

    prog_in = data.get('voltage_programme', {}) or {}
    prog_in = _require_mapping(prog_in, 'voltage_programme')
    _check_keys(prog_in, ('pulses', 'voltage_limit_v', 'overlap'), "'voltage_programme'")
    try:
        programme = PulseProgramme.from_dicts(
            prog_in.get('pulses', []) or [],
            _number(prog_in.get('voltage_limit_v', VOLTAGE_LIMIT_V),
                    'voltage_programme.voltage_limit_v'),
            _overlap_rule(prog_in.get('overlap', 'refuse')))
    except ProgrammeError as exc:
        raise SceneError(f"'voltage_programme': {exc}") from exc
    absent = sorted({p.beam for p in programme.pulses} - set(beams))
    if absent:
        raise SceneError(f"'voltage_programme' drives beam(s) {absent} that the scene lacks")

    duration_s = _number(data.get('duration_s', 0.1), 'duration_s')
    _check_pulses_within(programme, duration_s)
    parameter_set = str(data.get('parameters', DEFAULT_PARAMETER_SET))
    scene = Scene(
        name=str(data.get('name', name)),
        description=str(data.get('description', '')),
        parameter_set=parameter_set,
        beams=tuple(int(b) for b in beams),
        sphere=sphere,
        effects=effects,
        capacitance=capacitance,
        initial=initial,
        programme=programme,
        duration_s=duration_s,
        perturbation=_perturbation(data.get('perturbation')),
    )
    try:
        scene.parameters()
    except ParameterError as exc:
        raise SceneError(f"'parameters'/'perturbation': {exc}") from exc
    return scene


def _overlap_rule(value: Any) -> OverlapRule:
    """The scene's ``voltage_programme.overlap``: pulses on one beam that share time are
    refused unless the scene says ``add`` (PulseProgramme)."""
    for rule in OVERLAP_RULES:
        if value == rule:
            return rule
    raise SceneError(f"'voltage_programme.overlap' must be one of {list(OVERLAP_RULES)}, "
                     f'got {value!r}')


def _check_pulses_within(programme: PulseProgramme, duration_s: float) -> None:
    """A pulse that starts after the scene ends never acts, and one that ends after it is cut
    short: either is a mistake the run would hide, so the scene is refused."""
    for pulse in programme.pulses:
        if pulse.end_s > duration_s:
            raise SceneError(
                f"'voltage_programme': the pulse on beam {pulse.beam} from "
                f'{pulse.start_s:g} to {pulse.end_s:g} s ends after the scene '
                f'(duration_s = {duration_s:g} s): lengthen duration_s or move the pulse')


def available_scenes() -> list[str]:
    return sorted(p.stem for p in SCENES_DIR.glob('*.yaml'))


@lru_cache(maxsize=64)
def load_scene(name_or_path: str | Path) -> Scene:
    """Load a scene by name (a file in ``sphere_sim/scenes``) or by YAML path."""
    path = Path(name_or_path)
    if path.suffix not in ('.yaml', '.yml'):
        path = SCENES_DIR / f'{name_or_path}.yaml'
    if not path.exists():
        raise SceneError(f'scene {name_or_path!r} not found; shipped scenes: {available_scenes()}')
    data = read_yaml_file(path, 'scene file', SceneError)
    if data is None:
        raise SceneError(f'scene file {path} is empty')
    try:
        return scene_from_dict(data, name=path.stem)
    except SceneError as exc:
        raise SceneError(f'scene file {path}: {exc}') from exc
