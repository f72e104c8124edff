"""A bad parameter or scene file ends ``sphere-twin`` with one line and status 2, quickly.

Every case runs ``sphere-twin kick`` in this process from a working directory holding only
its input files (each case's files have their own names: the loaders cache by name). A
parameter file given with ``--params`` is refused by argparse, named by a scene by the scene's
loader: either way alone on its line.
"""

import dataclasses
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from sphere_sim.model.parameters import (
    PARAMETER_RULES,
    ParameterError,
    ParameterSet,
    available_parameter_sets,
    check_parameter,
    load_parameter_set,
)
from sphere_twin import cli

OVERRIDE = 'base: calibrated\noverrides:\n'
SCENE = 'name: bad\nparameters: calibrated\nbeams: [1, 2, 3, 4]\ninitial_state: {mode: rest}\n'
NOT_UTF8 = b'name: caf\xe9\n'  # Latin-1, as an editor on another system may save it
HANG_TIMEOUT_S = 60.0  # a refusal takes the CLI's start-up, a few seconds; the hang was forever

# file name -> content (str, bytes, or None for a directory of that name)
INPUTS: dict[str, str | bytes | None] = {
    'neg_mass.yaml': OVERRIDE + '  beam.mass_kg: -1.0e-7\n',
    'zero_length.yaml': OVERRIDE + '  beam.length_m: 0\n',
    'zero_stiffness.yaml': OVERRIDE + '  beam.stiffness_z_n_per_m: 0.0\n',
    'zero_inertia.yaml': OVERRIDE + '  beam.inertia_kg_m2: 0\n',
    'zero_gap.yaml': OVERRIDE + '  beam.ground_z_m: 0.0\n',
    'zero_speed.yaml': OVERRIDE + '  friction.coulomb_velocity_m_per_s: 0\n',
    'zero_presliding.yaml': OVERRIDE + '  friction.presliding_m: 0.0\n',
    'nan_mass.yaml': OVERRIDE + '  beam.mass_kg: .nan\n',
    'inf_contact.yaml': OVERRIDE + '  contact.stiffness_n_per_m: .inf\n',
    'huge_sphere.yaml': OVERRIDE + '  sphere.mass_kg: 1.0e+6\n',
    'huge_friction.yaml': OVERRIDE + '  friction.coulomb: 1000\n',
    'overrides_list.yaml': 'base: calibrated\noverrides: [beam.mass_kg, 1.0e-7]\n',
    'overrides_scalar.yaml': 'base: calibrated\noverrides: 3\n',
    'overrides_nested.yaml': OVERRIDE + '  beam:\n    mass_kg: 1.0e-7\n',
    'value_mapping.yaml': OVERRIDE + '  beam.mass_kg: {value: 1.0e-7}\n',
    'value_date.yaml': OVERRIDE + '  beam.mass_kg: 2020-01-01\n',
    'quoted_number.yaml': OVERRIDE + '  friction.static_coefficient: "0.3"\n',
    'quoted_bool.yaml': OVERRIDE + '  electrostatics.fringe: "false"\n',
    'bool_number.yaml': OVERRIDE + '  friction.coulomb: true\n',
    'bad_choice.yaml': OVERRIDE + '  friction.reading: dry\n',
    'base_list.yaml': 'base: [calibrated]\n',
    'no_base.yaml': 'overrides:\n  beam.mass_kg: 1.0e-7\n',
    'uncertain_scalar.yaml': 'base: calibrated\nuncertain: 3\n',
    'uncertain_quoted.yaml': ('base: calibrated\nuncertain:\n- {path: beam.mass_kg, low: "1e-8", '
                              'high: 1.0e-7, target: estimate, reason: test}\n'),
    'uncertain_wide.yaml': ('base: calibrated\nuncertain:\n- {path: beam.mass_kg, low: -1.0, '
                            'high: 1.0e-7, target: estimate, reason: test}\n'),
    'params_latin1.yaml': b'base: calibrated\n' + NOT_UTF8,
    'params_dir.yaml': None,
    # scenes
    's_neg_mass.yaml': SCENE + 'parameters: neg_mass_scene.yaml\n',
    'neg_mass_scene.yaml': OVERRIDE + '  beam.mass_kg: -1.0e-7\n',
    's_zero_duration.yaml': SCENE + 'duration_s: 0\n',
    's_quoted_duration.yaml': SCENE + 'duration_s: "0.01"\n',
    's_bool_duration.yaml': SCENE + 'duration_s: true\n',
    's_inf_duration.yaml': SCENE + 'duration_s: .inf\n',
    's_latin1.yaml': NOT_UTF8,
    's_dir.yaml': None,
    's_sunk.yaml': SCENE + 'initial_state: {mode: rest, sphere_lift_m: -1.0e-3}\n',
    's_angle.yaml': SCENE + 'initial_state: {mode: explicit, sphere_angles_deg: [0, 400, 0]}\n',
    's_limit.yaml': SCENE + 'voltage_programme: {voltage_limit_v: 200}\n',
    's_perturb_text.yaml': SCENE + 'perturbation: {beam.mass_kg: heavy}\n',
    's_perturb_neg.yaml': SCENE + 'perturbation: {beam.mass_kg: -1.0e-7}\n',
    's_bool_beam.yaml': SCENE.replace('[1, 2, 3, 4]', '[true, 2]'),
    's_late_pulse.yaml': SCENE + ('duration_s: 0.01\nvoltage_programme:\n  pulses:\n    - {beam: '
                                  '1, amplitude_v: 50.0, start_s: 0.02, width_s: 0.001}\n'),
    's_cut_pulse.yaml': SCENE + ('duration_s: 0.01\nvoltage_programme:\n  pulses:\n    - {beam: '
                                 '1, amplitude_v: 50.0, start_s: 0.008, width_s: 0.004}\n'),
}
# SCENE's own `parameters:` line comes first; a later duplicate key replaces it in YAML.
INPUTS = {name: (text.replace('parameters: calibrated\n', '', 1)
                 if isinstance(text, str) and text.count('parameters:') == 2 else text)
          for name, text in INPUTS.items()}

ALLOWED_MASS = '(allowed 0..0.001 kg, 0 excluded)'


def _params(file: str, fragment: str) -> Any:
    return pytest.param(['kick', 'rest', '--params', file], fragment, id=file)


def _scene(file: str, fragment: str) -> Any:
    return pytest.param(['kick', file], fragment, id=file)


CASES = [
    # not finite, zero where a division follows, or far outside physics
    _params('neg_mass.yaml', f'neg_mass.yaml: beam.mass_kg = -1e-07 kg: must be positive '
                             f'{ALLOWED_MASS}'),
    _params('zero_length.yaml', 'beam.length_m = 0 m: must be positive (allowed 0..0.01 m'),
    _params('zero_stiffness.yaml', 'beam.stiffness_z_n_per_m = 0 N/m: must be positive'),
    _params('zero_inertia.yaml', 'beam.inertia_kg_m2 = 0 kg m^2: must be positive'),
    _params('zero_gap.yaml', 'beam.ground_z_m = 0 m: must lie below beam.suspension_z_m'),
    _params('zero_speed.yaml', 'friction.coulomb_velocity_m_per_s = 0 m/s: must be positive'),
    _params('zero_presliding.yaml', 'friction.presliding_m = 0 m: must be positive'),
    _params('nan_mass.yaml', f'beam.mass_kg = nan kg: must be a finite number {ALLOWED_MASS}'),
    _params('inf_contact.yaml', 'contact.stiffness_n_per_m = inf N/m: must be a finite number'),
    _params('huge_sphere.yaml', 'sphere.mass_kg = 1e+06 kg: must be at most 1 kg (allowed 0..1 kg'),
    _params('huge_friction.yaml', 'friction.coulomb = 1000: must be at most 10 (allowed 0..10)'),
    # override blocks of the wrong shape
    _params('overrides_list.yaml', 'overrides must be a mapping of dotted paths to values, like '
                                   'beam.mass_kg: 1.0e-7; not a list'),
    _params('overrides_scalar.yaml', 'overrides must be a mapping of dotted paths to values'),
    _params('overrides_nested.yaml', "'beam' is a section, not one value: name each value by "
                                     'its dotted path, like beam.suspension_z_m'),
    _params('value_mapping.yaml', "beam.mass_kg = {'value': 1e-07}: must be a number, not a "
                                  'mapping'),
    _params('value_date.yaml', 'beam.mass_kg = datetime.date(2020, 1, 1): must be a number'),
    _params('no_base.yaml', 'overrides need a base'),
    _params('base_list.yaml', 'base must name a parameter set, like calibrated; not a list'),
    _params('uncertain_scalar.yaml', 'uncertain must be a list of entries'),
    _params('uncertain_wide.yaml', 'beam.mass_kg = -1 kg: must be positive'),
    # quoted values are refused, never guessed
    _params('quoted_number.yaml', "friction.static_coefficient = '0.3': must be a number "
                                  'written without quotes (allowed 0..10)'),
    _params('quoted_bool.yaml', "electrostatics.fringe = 'false': must be true or false, "
                                'without quotes'),
    _params('uncertain_quoted.yaml', "beam.mass_kg = '1e-8': must be a number written without "
                                     'quotes'),
    _params('bool_number.yaml', 'friction.coulomb = True: must be a number, not true/false'),
    _params('bad_choice.yaml', "friction.reading = 'dry': must be one of paper, stiction"),
    # files that are not parameter files
    _params('params_latin1.yaml', 'params_latin1.yaml is not UTF-8 text (byte 26): save it '
                                  'as UTF-8'),
    _params('params_dir.yaml', 'params_dir.yaml is a directory, not a parameter file'),
    # scenes
    _scene('s_neg_mass.yaml', "scene file s_neg_mass.yaml: 'parameters'/'perturbation': "
                              'neg_mass_scene.yaml: beam.mass_kg = -1e-07 kg: must be positive'),
    _scene('s_zero_duration.yaml', 'scene file s_zero_duration.yaml: duration_s = 0 s: must be '
                                   'positive (allowed 0..3600 s, 0 excluded)'),
    _scene('s_quoted_duration.yaml', "duration_s = '0.01': must be a number written without "
                                     'quotes'),
    _scene('s_bool_duration.yaml', 'duration_s = True: must be a number, not true/false'),
    _scene('s_inf_duration.yaml', 'duration_s = inf s: must be a finite number'),
    _scene('s_latin1.yaml', 'scene file s_latin1.yaml is not UTF-8 text (byte 9)'),
    # a pulse the run would never apply, or cut short
    _scene('s_late_pulse.yaml', "'voltage_programme': the pulse on beam 1 from 0.02 to 0.021 s "
                                'ends after the scene (duration_s = 0.01 s)'),
    _scene('s_cut_pulse.yaml', "'voltage_programme': the pulse on beam 1 from 0.008 to 0.012 s "
                               'ends after the scene (duration_s = 0.01 s)'),
    _scene('s_dir.yaml', 's_dir.yaml is a directory, not a scene file'),
    _scene('s_sunk.yaml', 'initial_state.sphere_lift_m = -0.001 m: must be zero or positive'),
    _scene('s_angle.yaml', 'initial_state.sphere_angles_deg[1] = 400 deg: must be at most '
                           '180 deg (allowed -180..180 deg)'),
    _scene('s_limit.yaml', 'voltage_programme.voltage_limit_v = 200 V: must be at most 80 V'),
    _scene('s_perturb_text.yaml', "'perturbation': beam.mass_kg = 'heavy': must be a number"),
    _scene('s_perturb_neg.yaml', "'perturbation': beam.mass_kg = -1e-07 kg: must be positive"),
    _scene('s_bool_beam.yaml', "'beams' must be a non-empty list of distinct beam numbers"),
]


def _write_inputs(directory: Path) -> None:
    for name, content in INPUTS.items():
        if content is None:
            (directory / name).mkdir()
        elif isinstance(content, bytes):
            (directory / name).write_bytes(content)
        else:
            (directory / name).write_text(content)


@pytest.mark.parametrize(('argv', 'fragment'), CASES)
def test_bad_input_file_is_one_line_status_2(argv: list[str], fragment: str, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    _write_inputs(tmp_path)
    monkeypatch.chdir(tmp_path)
    status: int | str | None
    try:
        status = cli.main(argv)
    except SystemExit as exit_:  # argparse's own usage errors (--params)
        status = exit_.code
    captured = capsys.readouterr()
    assert status == 2
    assert 'Traceback' not in captured.err
    lines = captured.err.strip().splitlines()
    assert lines[-1].startswith('sphere-twin kick: error: '), lines
    assert fragment in lines[-1]
    assert len(lines) == 1, lines
    assert captured.out == ''
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(INPUTS)


def test_bad_input_negative_beam_mass_is_refused_not_hung(tmp_path: Path) -> None:
    """A negative beam mass used to hang the compiled integrator, where no signal reaches
    Python: a separate process bounds the wait."""
    _write_inputs(tmp_path)
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    done = subprocess.run([sys.executable, '-m', 'sphere_twin.cli', 'kick', 's_neg_mass.yaml'],
                          cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=HANG_TIMEOUT_S)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        "sphere-twin kick: error: scene file s_neg_mass.yaml: 'parameters'/'perturbation': "
        f'neg_mass_scene.yaml: beam.mass_kg = -1e-07 kg: must be positive {ALLOWED_MASS}']
    assert done.stdout == ''


def test_bad_input_cases_cover_every_kind() -> None:
    ids = {case.id for case in CASES}
    assert len(CASES) >= 20
    assert {'neg_mass.yaml', 's_neg_mass.yaml', 's_zero_duration.yaml', 's_latin1.yaml',
            'params_dir.yaml', 'quoted_bool.yaml', 'overrides_list.yaml'} <= ids


def _value_paths(cls: type, prefix: str = '') -> set[str]:
    """Every value's dotted path in the dataclass ``cls`` (sections recursed into)."""
    paths = set()
    for field in dataclasses.fields(cls):
        if isinstance(field.type, type) and dataclasses.is_dataclass(field.type):
            paths |= _value_paths(field.type, f'{field.name}.')
        else:
            paths.add(prefix + field.name)
    return paths


def test_every_parameter_field_has_a_rule() -> None:
    """A field added to a ParameterSet dataclass cannot skip the table (nor the table keep
    a field that no longer exists)."""
    # Text, the calibration's ranges and the set a file's overrides change.
    declarations = {'name', 'description', 'uncertain', 'base'}
    assert _value_paths(ParameterSet) - declarations == set(PARAMETER_RULES)


@pytest.mark.parametrize('name', available_parameter_sets())
def test_every_shipped_set_passes_the_table(name: str) -> None:
    params = load_parameter_set(name)
    for path in PARAMETER_RULES:
        assert check_parameter(path, params.get(path)) == params.get(path), path
    for entry in params.uncertain:  # the calibration's ranges lie inside the physical ones
        for path in entry.paths:
            assert check_parameter(path, entry.low) == entry.low
            assert check_parameter(path, entry.high) == entry.high


def test_an_unquoted_exponent_is_a_number_and_a_quoted_one_is_refused(tmp_path: Path) -> None:
    """YAML 1.1 reads 1e-7 (no decimal point) as text; the loader reads it as the number."""
    plain = tmp_path / 'exponent_plain.yaml'
    plain.write_text(OVERRIDE + '  beam.mass_kg: 9e-8\n  beam.stiffness_z_n_per_m: 4E+1\n')
    params = load_parameter_set(str(plain))
    assert params.beam.mass_kg == 9e-8
    assert params.beam.stiffness_z_n_per_m == 40.0
    quoted = tmp_path / 'exponent_quoted.yaml'
    quoted.write_text(OVERRIDE + "  beam.mass_kg: '9e-8'\n")
    with pytest.raises(ParameterError, match='must be a number written without quotes'):
        load_parameter_set(str(quoted))


def test_a_replaced_value_is_checked_too() -> None:
    """Perturbations in code pass the same table: a negative mass never reaches the model."""
    params = load_parameter_set('calibrated')
    with pytest.raises(ParameterError, match=r'beam\.mass_kg = -1e-07 kg: must be positive'):
        params.replace(**{'beam.mass_kg': -1e-7})
    assert params.replace(**{'beam.mass_kg': 1e-7}).beam.mass_kg == 1e-7
