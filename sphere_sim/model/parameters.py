"""Physical parameter sets: frozen dataclasses in SI units, loaded from one place.

A parameter set is a YAML file under ``sphere_sim/params``. A file may name a ``base`` set
and override some of its values; the ``calibrated`` set does this and declares which
parameters it treats as uncertain, with a plausible range and a reason for each.
"""

import contextlib
import copy
import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path
from typing import Any

import yaml

from msg_defs.device import DEFAULT_PARAMETER_SET

PARAMS_DIR = Path(__file__).parents[1] / 'params'


class ParameterError(ValueError):
    """A parameter file is missing, malformed or names an unknown key."""


class YamlLoader(yaml.SafeLoader):
    """YAML's safe loader that also reads ``1e-6`` as a number.

    YAML 1.1 (PyYAML) takes a number with an exponent but no decimal point for text; a quoted
    value is text on purpose and is refused where a number belongs (never guessed), so the
    unquoted exponent form must arrive as the number it is.
    """


YamlLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float',
    re.compile(r'^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$'),
    list('-+0123456789.'))


@dataclasses.dataclass(frozen=True)
class BeamParams:
    suspension_z_m: float
    tip_distance_m: float
    length_m: float
    width_m: float
    mass_kg: float
    inertia_kg_m2: float
    inertia_about: str
    cog_distance_m: float
    electrode_length_m: float
    electrode_width_m: float
    insulation_virtual_m: float
    stiffness_z_n_per_m: float
    stiffness_phi_nm_per_rad: float
    damping_z_ns_per_m: float
    damping_phi_nms_per_rad: float
    ground_z_m: float
    ground_length_m: float

    @property
    def suspension_radius_m(self) -> float:
        """Horizontal distance of the suspension from the centre, L_B + d_B/2 (eq. 3)."""
        return self.length_m + 0.5 * self.tip_distance_m

    @property
    def inertia_suspension_kg_m2(self) -> float:
        """Rotational inertia about the suspension point, the (2,2) entry of the mass matrix."""
        if self.inertia_about == 'suspension':
            return self.inertia_kg_m2
        return self.inertia_kg_m2 + self.mass_kg * self.cog_distance_m**2


@dataclasses.dataclass(frozen=True)
class ElectrostaticParams:
    fringe: bool
    fringe_angle_rad: float


@dataclasses.dataclass(frozen=True)
class SphereParams:
    radius_m: float
    cut_angle_rad: float
    mass_kg: float
    cog_offset_m: float
    damping_rot_nms: float
    damping_trans_ns_per_m: float


@dataclasses.dataclass(frozen=True)
class ContactParams:
    stiffness_n_per_m: float
    transition_force_n: float
    loss_s_per_m: float


@dataclasses.dataclass(frozen=True)
class FrictionParams:
    reading: str
    viscous_ns_per_m: float
    coulomb: float
    coulomb_velocity_m_per_s: float
    stribeck: float
    stribeck_velocity_m_per_s: float
    epsilon_m2_per_s2: float
    viscous_onset_m: float
    presliding_m: float
    viscous_s_per_m: float
    bristle_damping_s: float
    static_coefficient: float
    bristle_stiffness_n_per_m: float
    bristle_speed_m_per_s: float
    breakaway_ratio: float


# What a declared-uncertain parameter is fitted to (sphere_sim.fitting.calibration): only Fig. 4's
# pull-in; the paper's other facts test the model and are never fitted. One held at a
# physical estimate declares ESTIMATE_TARGET instead, and the calibration reports what the
# observations do across its range.
CALIBRATION_TARGETS = ('fig4_threshold',)
ESTIMATE_TARGET = 'estimate'


@dataclasses.dataclass(frozen=True)
class UncertainParameter:
    """A parameter the calibration may move, within ``[low, high]``, and why.

    ``target`` names the observation it is fitted to (one of ``CALIBRATION_TARGETS``), or is
    ``ESTIMATE_TARGET`` for a value held at a physical estimate;
    ``tied`` lists further paths that always take the same value (e.g. the Stribeck velocity
    with the Coulomb velocity, both read from one unitless column of Table A1).
    """

    path: str
    low: float
    high: float
    reason: str
    target: str
    tied: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.target not in (*CALIBRATION_TARGETS, ESTIMATE_TARGET):
            raise ParameterError(f'uncertain {self.path}: target must be one of '
                                 f'{(*CALIBRATION_TARGETS, ESTIMATE_TARGET)}, got '
                                 f'{self.target!r}')
        if not self.low < self.high:
            raise ParameterError(f'uncertain {self.path}: low must be below high')
        object.__setattr__(self, 'tied', tuple(self.tied))

    @property
    def paths(self) -> tuple[str, ...]:
        """The fitted path and every path tied to it."""
        return (self.path, *self.tied)


@dataclasses.dataclass(frozen=True)
class ParameterSet:
    name: str
    description: str
    gravity_m_per_s2: float
    beam: BeamParams
    electrostatics: ElectrostaticParams
    sphere: SphereParams
    contact: ContactParams
    friction: FrictionParams
    uncertain: tuple[UncertainParameter, ...] = ()
    # The set a file's overrides change, as its ``base:`` names it ('' for a set of its own):
    # what a fitted set is compared with (replay-check --before).
    base: str = ''

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def digest(self) -> str:
        """Short content hash of the physical values (name, description and the calibration's
        declarations excluded: rewording a reason must not invalidate a table)."""
        physical = {k: v for k, v in self.to_dict().items()
                    if k not in ('name', 'description', 'uncertain', 'base')}
        text = json.dumps(physical, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def replace(self, **paths: float | str) -> 'ParameterSet':
        """A copy with dotted-path values replaced: ``replace(**{'beam.mass_kg': 1e-7})``."""
        data = self.to_dict()
        for path, value in paths.items():
            _set_path(data, path, value)
        return _from_dict(data)

    def get(self, path: str) -> Any:
        node = self
        for part in path.split('.'):
            node = getattr(node, part)
        return node


_Section = BeamParams | ElectrostaticParams | SphereParams | ContactParams | FrictionParams

_SECTIONS: dict[str, type[_Section]] = {
    'beam': BeamParams,
    'electrostatics': ElectrostaticParams,
    'sphere': SphereParams,
    'contact': ContactParams,
    'friction': FrictionParams,
}


@dataclasses.dataclass(frozen=True)
class ParameterRule:
    """What one parameter may hold: a number in ``unit`` within ``low..high``, a boolean, or
    one of ``choices``.

    ``above_low`` excludes ``low`` itself (a division by the value, or a mass matrix that must
    stay positive definite, follows); ``below_high`` likewise excludes ``high``.
    """

    kind: type[float] | type[bool] | type[str]
    unit: str = ''
    low: float = -math.inf
    high: float = math.inf
    above_low: bool = False
    below_high: bool = False
    choices: tuple[str, ...] = ()


def _positive(unit: str, high_si: float) -> ParameterRule:
    return ParameterRule(float, unit, 0.0, high_si, above_low=True)


def _within(unit: str, low_si: float, high_si: float) -> ParameterRule:
    return ParameterRule(float, unit, low_si, high_si)


_FLAG = ParameterRule(bool)


def _one_of(*choices: str) -> ParameterRule:
    return ParameterRule(str, choices=choices)


# Every value of a parameter set, by dotted path: wide physical bounds (the device is a
# millimetre-sized MEMS part), meant to refuse what no device has (a negative mass, a zero
# stiffness divided by, a coefficient of friction of 1000), never a plausible hypothesis.
# A field without an entry here is refused (test_bad_input_files checks that none lacks one).
PARAMETER_RULES: dict[str, ParameterRule] = {
    'gravity_m_per_s2': _positive('m/s^2', 100.0),
    'beam.suspension_z_m': _within('m', -1e-3, 1e-3),
    'beam.tip_distance_m': _positive('m', 1e-2),
    'beam.length_m': _positive('m', 1e-2),
    'beam.width_m': _positive('m', 1e-2),
    'beam.mass_kg': _positive('kg', 1e-3),
    'beam.inertia_kg_m2': _positive('kg m^2', 1e-6),
    'beam.inertia_about': _one_of('suspension', 'cog'),
    'beam.cog_distance_m': _within('m', 0.0, 1e-2),
    'beam.electrode_length_m': _positive('m', 1e-2),
    'beam.electrode_width_m': _positive('m', 1e-2),
    'beam.insulation_virtual_m': _within('m', 0.0, 1e-4),
    'beam.stiffness_z_n_per_m': _positive('N/m', 1e6),
    'beam.stiffness_phi_nm_per_rad': _positive('N m/rad', 1.0),
    'beam.damping_z_ns_per_m': _within('N s/m', 0.0, 1.0),
    'beam.damping_phi_nms_per_rad': _within('N m s/rad', 0.0, 1e-3),
    'beam.ground_z_m': _within('m', -1e-3, 1e-3),
    'beam.ground_length_m': _positive('m', 1e-2),
    'electrostatics.fringe': _FLAG,
    'electrostatics.fringe_angle_rad': _positive('rad', 0.5),
    'sphere.radius_m': _positive('m', 1e-2),
    'sphere.cut_angle_rad': ParameterRule(float, 'rad', 0.0, math.pi, above_low=True),
    'sphere.mass_kg': _positive('kg', 1.0),
    'sphere.cog_offset_m': _within('m', 0.0, 1e-2),
    'sphere.damping_rot_nms': _within('N m s', 0.0, 1e-3),
    'sphere.damping_trans_ns_per_m': _within('N s/m', 0.0, 10.0),
    'contact.stiffness_n_per_m': _positive('N/m', 1e12),
    'contact.transition_force_n': _positive('N', 1e3),
    'contact.loss_s_per_m': _within('s/m', 0.0, 1e6),
    # Coefficients are magnitudes in every reading: the readings apply Table A1's signs.
    'friction.reading': _one_of('paper', 'stiction', 'structure', 'additive', 'printed'),
    'friction.viscous_ns_per_m': _within('N s/m', 0.0, 100.0),
    'friction.coulomb': _within('', 0.0, 10.0),
    'friction.coulomb_velocity_m_per_s': _positive('m/s', 100.0),
    'friction.stribeck': _within('', 0.0, 10.0),
    'friction.stribeck_velocity_m_per_s': _positive('m/s', 100.0),
    'friction.epsilon_m2_per_s2': _positive('m^2/s^2', 1e-2),
    'friction.viscous_onset_m': _within('m', 0.0, 1e-4),  # 0: no ramp (friction.onset_gate)
    'friction.presliding_m': _positive('m', 1e-4),
    'friction.viscous_s_per_m': _within('s/m', 0.0, 1e3),
    'friction.bristle_damping_s': _within('s', 0.0, 1.0),
    'friction.static_coefficient': _within('', 0.0, 10.0),
    'friction.bristle_stiffness_n_per_m': _positive('N/m', 1e12),
    'friction.bristle_speed_m_per_s': _positive('m/s', 100.0),
    'friction.breakaway_ratio': ParameterRule(float, '', 0.0, 1.0, below_high=True),
}


def check_parameter(path: str, value: object) -> float | bool | str:
    """``value`` as parameter ``path`` holds it, or ParameterError saying on one line what is
    wrong and what is allowed. Nothing is guessed: a quoted number or boolean is refused."""
    rule = PARAMETER_RULES.get(path)
    if rule is None:
        raise _unknown_parameter(path)
    if rule.kind is bool:
        if not isinstance(value, bool):
            raise ParameterError(f'{path} = {value!r}: must be true or false, without quotes')
        return value
    if rule.kind is str:
        if not isinstance(value, str) or value not in rule.choices:
            raise ParameterError(f'{path} = {value!r}: must be one of {", ".join(rule.choices)}')
        return value
    return check_number(path, value, rule)


def _unknown_parameter(path: object) -> ParameterError:
    if isinstance(path, str) and path in _SECTIONS:  # a nested mapping where a value belongs
        first = dataclasses.fields(_SECTIONS[path])[0].name
        return ParameterError(f'{path!r} is a section, not one value: name each value by its '
                              f'dotted path, like {path}.{first}')
    return ParameterError(f'unknown parameter {path!r}; every parameter is listed in '
                          f'{PARAMS_DIR / "table_a1.yaml"}')


def check_number(path: str, value: object, rule: ParameterRule) -> float:
    """``value`` as a float if it is a finite, unquoted number within ``rule``'s range, else
    ParameterError naming ``path``, the value, the rule and the allowed range on one line."""
    allowed = _allowed_text(rule)
    if isinstance(value, str):
        raise ParameterError(f'{path} = {value!r}: must be a number written without quotes '
                             f'(allowed {allowed})')
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f'{path} = {value!r}: must be a number, not {_kind_of(value)} '
                             f'(allowed {allowed})')
    number = float(value)
    shown = _with_unit(number, rule.unit)
    if not math.isfinite(number):
        raise ParameterError(f'{path} = {shown}: must be a finite number (allowed {allowed})')
    if number < rule.low or (rule.above_low and number == rule.low):
        raise ParameterError(f'{path} = {shown}: must be {_low_rule(rule)} (allowed {allowed})')
    if number > rule.high or (rule.below_high and number == rule.high):
        raise ParameterError(f'{path} = {shown}: must be {_high_rule(rule)} (allowed {allowed})')
    return number


def _kind_of(value: object) -> str:
    """What a YAML value that is not a number is, in a user's words."""
    if value is None:
        return 'empty'
    if isinstance(value, bool):
        return 'true/false'
    if isinstance(value, dict):
        return 'a mapping'
    if isinstance(value, list):
        return 'a list'
    return type(value).__name__


def _with_unit(number: float, unit: str) -> str:
    return f'{number:g} {unit}' if unit else f'{number:g}'


def _allowed_text(rule: ParameterRule) -> str:
    """``0..0.001 kg, 0 excluded``: the range as a user reads it."""
    text = f'{rule.low:g}..{_with_unit(rule.high, rule.unit)}'
    excluded = [f'{bound:g}' for bound, open_ in ((rule.low, rule.above_low),
                                                  (rule.high, rule.below_high)) if open_]
    return f'{text}, {" and ".join(excluded)} excluded' if excluded else text


def _low_rule(rule: ParameterRule) -> str:
    if rule.above_low:
        return 'positive' if rule.low == 0.0 else f'above {_with_unit(rule.low, rule.unit)}'
    return 'zero or positive' if rule.low == 0.0 else f'at least {_with_unit(rule.low, rule.unit)}'


def _high_rule(rule: ParameterRule) -> str:
    if rule.below_high:
        return f'below {_with_unit(rule.high, rule.unit)}'
    return f'at most {_with_unit(rule.high, rule.unit)}'


def _set_path(data: dict[str, Any], path: Any, value: Any) -> None:
    """Set one value by its dotted path; the path must name one value of the table."""
    if not isinstance(path, str) or path not in PARAMETER_RULES:
        raise _unknown_parameter(path)
    *sections, key = path.split('.')
    node: Any = data
    for section in sections:
        node = node.get(section) if isinstance(node, dict) else None
    if not isinstance(node, dict):
        raise ParameterError(f'cannot set {path}: the base set has no section {sections[0]!r}')
    node[key] = value


def _section(section: str, cls: type[_Section], values: Any) -> _Section:
    """One section's dataclass from its YAML mapping, every key checked and converted."""
    if values is None:
        raise ParameterError(f'parameter set lacks section {section!r}')
    if not isinstance(values, dict):
        raise ParameterError(f'section {section!r} must be a mapping of its parameters, not '
                             f'{_kind_of(values)}')
    allowed = [f.name for f in dataclasses.fields(cls)]
    extra = set(values) - set(allowed)
    missing = set(allowed) - set(values)
    if extra:
        raise ParameterError(
            f'unknown key(s) {sorted(map(str, extra))} in {section!r}; allowed: {sorted(allowed)}')
    if missing:
        raise ParameterError(f'missing key(s) {sorted(missing)} in {section!r}')
    checked: dict[str, Any] = {key: check_parameter(f'{section}.{key}', value)
                               for key, value in values.items()}
    return cls(**checked)


def _from_dict(data: dict[str, Any]) -> ParameterSet:
    top_fields = {f.name for f in dataclasses.fields(ParameterSet)}
    unknown = set(data) - top_fields - {'base', 'overrides'}
    if unknown:
        raise ParameterError(
            f'unknown key(s) {sorted(unknown)} in parameter set; allowed: {sorted(top_fields)}')
    kwargs: dict[str, Any] = {section: _section(section, cls, data.get(section))
                              for section, cls in _SECTIONS.items()}
    _check_gap(kwargs['beam'])
    _check_friction(kwargs['friction'])
    if 'gravity_m_per_s2' not in data:
        raise ParameterError('parameter set lacks gravity_m_per_s2')
    return ParameterSet(
        name=str(data.get('name', 'unnamed')),
        description=str(data.get('description', '')),
        gravity_m_per_s2=float(check_parameter('gravity_m_per_s2', data['gravity_m_per_s2'])),
        uncertain=_uncertain_entries(data.get('uncertain')),
        base=str(data.get('base', '')),
        **kwargs,
    )


def _check_gap(beam: BeamParams) -> None:
    """The ground plate must lie below the suspension: the electrostatic force divides by
    the gap between them (eq. 8), which the table's ranges alone do not keep positive."""
    if not beam.ground_z_m < beam.suspension_z_m:
        raise ParameterError(f'beam.ground_z_m = {beam.ground_z_m:g} m: must lie below '
                             f'beam.suspension_z_m = {beam.suspension_z_m:g} m (the '
                             'electrode gap must be positive)')


# Speeds, relative to v_s, at which the ``paper`` reading's sliding law is checked not to drive.
_LAW_CHECK_SPEEDS = tuple(10.0 ** (k / 20.0) for k in range(-100, 41))


def _check_friction(f: FrictionParams) -> None:
    """Refuse coefficients with which the ``paper`` reading would inject energy or divide by
    zero: its loaded part mu_c tanh(v/v_c) + (mu_s - mu_c tanh(v_s/v_c)) b(v/v_s) must not turn
    negative at any speed (the signs and the positive velocities and bristle constants are
    PARAMETER_RULES')."""
    if f.reading != 'paper':
        return
    peak = f.stribeck - f.coulomb * math.tanh(f.stribeck_velocity_m_per_s
                                              / f.coulomb_velocity_m_per_s)
    for ratio in _LAW_CHECK_SPEEDS:
        v = ratio * f.stribeck_velocity_m_per_s
        loaded = (f.coulomb * math.tanh(v / f.coulomb_velocity_m_per_s)
                  + peak * ratio * math.exp(0.5 - 0.5 * ratio * ratio))
        if loaded < 0.0:
            raise ParameterError(f'the paper reading\'s sliding law drives at {v:.3g} m/s '
                                 f'(mu_c {f.coulomb}, mu_s {f.stribeck}): its loaded part is '
                                 f'{loaded:.3g} F_n there')


def _uncertain_entries(entries: Any) -> tuple[UncertainParameter, ...]:
    if entries is None:
        return ()
    if not isinstance(entries, (list, tuple)):
        raise ParameterError(f'uncertain must be a list of entries (path, low, high, target, '
                             f'reason), not {_kind_of(entries)}')
    return tuple(_uncertain(item) for item in entries)


def _uncertain(item: Any) -> UncertainParameter:
    if isinstance(item, UncertainParameter):
        return item
    if not isinstance(item, dict):
        raise ParameterError(f'uncertain entry {item!r}: must be a mapping with path, low, '
                             'high, target and reason')
    fields = {f.name for f in dataclasses.fields(UncertainParameter)}
    required = {f.name for f in dataclasses.fields(UncertainParameter)
                if f.default is dataclasses.MISSING}
    unknown = set(item) - fields
    missing = required - set(item)
    if unknown or missing:
        raise ParameterError(f'uncertain entry {item.get("path", "?")!r}: unknown key(s) '
                             f'{sorted(map(str, unknown))}, missing key(s) {sorted(missing)}; '
                             f'allowed: {sorted(fields)}')
    return UncertainParameter(**_checked_uncertain(item))


def _checked_uncertain(item: dict[str, Any]) -> dict[str, Any]:
    """An uncertain entry's values checked against the table: its range lies within its
    parameter's, and every path it names is a number of the set."""
    tied = item.get('tied', ())
    if not isinstance(tied, (list, tuple)):  # a tuple when replace() rebuilds a set
        raise ParameterError(f'uncertain {item["path"]!r}: tied must be a list of parameter '
                             f'paths, not {_kind_of(tied)}')
    for path in (item['path'], *tied):
        rule = PARAMETER_RULES.get(path) if isinstance(path, str) else None
        if rule is None or rule.kind is not float:
            raise ParameterError(f'uncertain {path!r}: must name a numeric parameter like '
                                 'beam.mass_kg')
    for key in ('reason', 'target'):
        if not isinstance(item[key], str):
            raise ParameterError(f'uncertain {item["path"]!r}: {key} must be text, not '
                                 f'{_kind_of(item[key])}')
    return {**item, 'tied': tuple(tied),
            'low': check_parameter(item['path'], item['low']),
            'high': check_parameter(item['path'], item['high'])}


def read_yaml_file(path: Path, kind: str, error: type[Exception]) -> Any:
    """The content of the YAML file ``path`` (a ``kind``: 'parameter file', 'scene file'),
    read with :class:`YamlLoader`; every way it cannot be read is one ``error``, in one line."""
    if path.is_dir():
        raise error(f'{path} is a directory, not a {kind}')
    try:
        with open(path, encoding='utf-8') as stream:
            return yaml.load(stream, Loader=YamlLoader)  # a SafeLoader
    except FileNotFoundError as exc:
        raise error(f'{kind} not found: {path}') from exc
    except UnicodeDecodeError as exc:
        raise error(f'{kind} {path} is not UTF-8 text (byte {exc.start}): save it as '
                    'UTF-8') from exc
    except yaml.YAMLError as exc:
        raise error(f'{kind} {path} is not valid YAML: {" ".join(str(exc).split())}') from exc


def _read_yaml(path: Path) -> dict[str, Any]:
    """A parameter file's mapping; every way it can fail to be one is a ParameterError."""
    data = read_yaml_file(path, 'parameter file', ParameterError)
    if not isinstance(data, dict):
        raise ParameterError(f'parameter file {path} must hold a mapping')
    return data


@contextlib.contextmanager
def _naming(source: Path) -> Iterator[None]:
    """Prefix the ParameterErrors raised inside with the file whose content they are about."""
    try:
        yield
    except ParameterError as exc:
        raise ParameterError(f'{source}: {exc}') from exc


def _resolve(data: dict[str, Any], source: Path, seen: tuple[str, ...] = ()) -> dict[str, Any]:
    """The set ``data`` (read from ``source``) describes, its ``base`` and ``overrides``
    merged in; override paths and values are checked here, where their file is known."""
    base = data.get('base')
    if base is None:
        if 'overrides' in data:
            raise ParameterError(f'{source}: overrides need a base: the set they change, like '
                                 'base: calibrated')
        return data
    with _naming(source):
        base_path = _base_path(base, seen)
        overrides = data.get('overrides') or {}
        if not isinstance(overrides, dict):
            raise ParameterError('overrides must be a mapping of dotted paths to values, like '
                                 f'beam.mass_kg: 1.0e-7; not {_kind_of(overrides)}')
    merged = copy.deepcopy(_resolve(_read_yaml(base_path), base_path, (*seen, base)))
    with _naming(source):
        for path, value in overrides.items():
            check_parameter(path, value)
            _set_path(merged, path, value)
    for key in ('name', 'description', 'uncertain'):
        if key in data:
            merged[key] = data[key]
    merged['base'] = base
    return merged


def _base_path(base: Any, seen: tuple[str, ...]) -> Path:
    if not isinstance(base, str):
        raise ParameterError(f'base must name a parameter set, like calibrated; not '
                             f'{_kind_of(base)}')
    if base in seen:
        raise ParameterError(f'parameter sets form a cycle through {base!r}')
    path = _path_of(base)
    if not path.exists():
        raise ParameterError(f'base: unknown parameter set {base!r}; available: '
                             f'{available_parameter_sets()}')
    return path


def _path_of(name_or_path: str | Path) -> Path:
    path = Path(name_or_path)
    if path.suffix in ('.yaml', '.yml'):
        return path
    return PARAMS_DIR / f'{name_or_path}.yaml'


def available_parameter_sets() -> list[str]:
    return sorted(p.stem for p in PARAMS_DIR.glob('*.yaml'))


@lru_cache(maxsize=32)
def load_parameter_set(name_or_path: str | Path = DEFAULT_PARAMETER_SET) -> ParameterSet:
    """Load a parameter set by name (``table_a1``, ``calibrated``) or YAML path.

    Raises
    ------
    ParameterError
        When the file is missing or a key is unknown, missing or of the wrong type.
    """
    path = _path_of(name_or_path)
    if not path.exists():
        raise ParameterError(
            f'unknown parameter set {name_or_path!r}; available: {available_parameter_sets()}')
    merged = _resolve(_read_yaml(path), path)
    with _naming(path):
        return _from_dict(merged)
