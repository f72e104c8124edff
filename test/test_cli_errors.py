"""A user's mistake ends a subcommand with one line and status 2, and changes nothing.

Every case runs ``sphere-twin`` in this process from an empty working directory holding only
the case's input files, and checks the status, that stderr is the one line
``sphere-twin <cmd>: error: ...`` naming what to fix, that no traceback was printed, and that
nothing was written: neither in the working directory nor in the shipped results and tables.
"""

import json
from pathlib import Path

import pytest

from sphere_twin import cli

REPO = Path(__file__).resolve().parents[1]
WATCHED = (REPO / 'bench' / 'results', REPO / 'sphere_sim' / 'tables', REPO / 'bags')

SCENE = ('name: bad\ndescription: a scene with a mistake\nparameters: calibrated\n'
         'beams: [1, 2, 3, 4]\nsphere: true\ninitial_state: {mode: rest}\n')
INPUTS = {
    'malformed.yaml': 'name: [unclosed\nbeams: : :\n',
    'empty.yaml': '',
    'truncated.yaml': SCENE[:60],
    'list.yaml': '- 1\n- 2\n',
    'negative_duration.yaml': SCENE + 'duration_s: -1\n',
    'unknown_key.yaml': SCENE + 'duration_s: 0.01\nwind_speed: 3\n',
    'over_limit.yaml': SCENE + ('duration_s: 0.01\nvoltage_programme:\n  pulses:\n'
                                '    - {beam: 1, amplitude_v: 95.0, start_s: 0.0, '
                                'width_s: 0.001}\n'),
    'negative_volts.yaml': SCENE + ('duration_s: 0.01\nvoltage_programme:\n  pulses:\n'
                                    '    - {beam: 1, amplitude_v: -50.0, start_s: 0.0, '
                                    'width_s: 0.001}\n'),
    # +50 V and -50 V at once on beam 1: the sum (0 V) would hide a sign error
    'opposite_pulses.yaml': SCENE + ('duration_s: 0.01\nvoltage_programme:\n  pulses:\n'
                                     '    - {beam: 1, amplitude_v: 50.0, start_s: 0.0, '
                                     'width_s: 0.001}\n'
                                     '    - {beam: 1, amplitude_v: -50.0, start_s: 0.0, '
                                     'width_s: 0.001}\n'),
    'overlapping_pulses.yaml': SCENE + ('duration_s: 0.01\nvoltage_programme:\n  pulses:\n'
                                        '    - {beam: 1, amplitude_v: 50.0, start_s: 0.0, '
                                        'width_s: 0.004}\n'
                                        '    - {beam: 2, amplitude_v: 50.0, start_s: 0.0, '
                                        'width_s: 0.004}\n'
                                        '    - {beam: 1, amplitude_v: 20.0, start_s: 0.002, '
                                        'width_s: 0.004}\n'),
    'params_malformed.yaml': 'base: calibrated\noverrides: {beam.length_m: [\n',
    'params_unknown.yaml': 'base: calibrated\noverrides:\n  beam.wingspan_m: 1.0\n',
    'params_nobase.yaml': 'base: nosuch\n',
    'params_text.yaml': 'just words\n',
    'foreign.npz': 'not a table\n',
    'foreign.mcap': 'not a recording\n',
    'design_truncated.json': '{"design": {"low_v": 35',
    'notes.txt': 'a text file\n',
}


def _case(argv, fragment):
    return pytest.param(argv, fragment, id=' '.join(argv)[:60])


CASES = [
    # missing, empty, truncated and foreign files
    _case(['kick', 'nofile.yaml'], "scene 'nofile.yaml' not found"),
    _case(['kick', 'empty.yaml'], 'empty.yaml'),
    _case(['kick', 'truncated.yaml'], 'truncated.yaml'),
    _case(['kick', 'list.yaml'], 'mapping'),
    _case(['kick', 'malformed.yaml'], 'not valid YAML'),
    _case(['table', 'check', '--table', 'nofile.npz'], 'no table at nofile.npz'),
    _case(['table', 'check', '--table', 'foreign.npz'], 'is not a sphere_twin kick table'),
    _case(['report', 'nosuchdir'], 'nosuchdir'),
    _case(['report', 'notes.txt'], 'notes.txt'),
    _case(['replay-check', 'nosuchdir'], 'nosuchdir'),
    _case(['bag', 'info', 'foreign.mcap'], 'foreign.mcap'),
    _case(['bag', 'repair', 'nosuchdir'], 'nosuchdir'),
    _case(['primitives', 'width', '--design', 'nofile.json', '--out', 'out'], 'nofile.json'),
    _case(['primitives', 'width', '--design', 'design_truncated.json', '--out', 'out'],
          'design_truncated.json'),
    _case(['evaluate', '--table', 'nofile.npz', '--out', 'out'], 'no table at nofile.npz'),
    # malformed and out-of-range scenes and parameter files
    _case(['kick', 'negative_duration.yaml'], 'duration_s'),
    _case(['kick', 'unknown_key.yaml'], 'wind_speed'),
    _case(['kick', 'over_limit.yaml'], 'exceeds the limit'),
    # the drivers are unipolar: the programme keeps the wire's rule (-50 V is not +50 V)
    _case(['kick', 'negative_volts.yaml'], 'must be >= 0 V'),
    # a pulse is checked alone, whatever it would sum to with the others on its beam
    _case(['kick', 'opposite_pulses.yaml'],
          "'voltage_programme': pulse 1 (beam 1): amplitude_v must be >= 0 V (the drivers are "
          'unipolar), got -50 V'),
    # pulses on one beam that share time are refused, both named, unless the scene says add
    _case(['kick', 'overlapping_pulses.yaml'],
          "'voltage_programme': pulse 0 (beam 1, 50 V from 0 to 0.004 s) and pulse 2 (beam 1, "
          '20 V from 0.002 to 0.006 s) overlap: move one, or set overlap: add to sum them'),
    _case(['kick', 'rest', '--params', 'params_malformed.yaml'], 'params_malformed.yaml'),
    _case(['kick', 'rest', '--params', 'params_unknown.yaml'], 'beam.wingspan_m'),
    _case(['validate', '--params', 'params_nobase.yaml'], 'nosuch'),
    _case(['pullin', '--params', 'params_text.yaml'], 'params_text.yaml'),
    _case(['capacitance', '--params', 'nosuch'], "unknown parameter set 'nosuch'"),
    # bad option values
    _case(['kick', 'rest', '--rtol', '-1'], 'must be a positive number'),
    _case(['kick', 'rest', '--rtol', '0'], 'must be a positive number'),
    _case(['kick', 'rest', '--rtol', 'tight'], "not a number: 'tight'"),
    _case(['table', 'build', '--grid-step', '0', '--output', 'out.npz'],
          'must be a positive number'),
    _case(['table', 'build', '--grid-step', '1.0', '--output', 'out.npz'],
          'at x_sn^2 + y_sn^2 = 2 >= 1'),
    _case(['table', 'build', '--intensities', '0.5', '1.5', '--output', 'out.npz'],
          'must lie in [0, 1]'),
    _case(['table', 'build', '--workers', '0', '--output', 'out.npz'], 'must be at least 1'),
    _case(['table', 'check', '--points', '0'], 'must be at least 1'),
    _case(['optimize-kick', '--popsize', '0', '--output', 'out.json'], 'must be at least 1'),
    _case(['evaluate', '--kick-period-s', '-0.05', '--out', 'out'],
          'must be a positive number'),
    _case(['report', 'nosuchdir', '--band-deg', 'nan'], 'must be a positive number'),
    _case(['calibrate', '--target', 'nosuch'], "invalid choice: 'nosuch'"),
    _case(['capacitance', '--fringe-angle-rad', '0'], 'must be a positive number'),
    _case(['bench', 'throughput', '--workers', '0', '--out', 'out'],
          'worker counts must be 2 or more'),
    _case(['bench', 'throughput', '--workers', 'two', '--out', 'out'],
          "not worker counts like 2,4,8: 'two'"),
]


def _snapshot(*roots):
    return {p: p.stat().st_mtime_ns for root in roots if root.exists()
            for p in root.rglob('*') if p.is_file()}


@pytest.mark.parametrize(('argv', 'fragment'), CASES)
def test_bad_input_is_one_line_status_2_and_writes_nothing(argv, fragment, tmp_path,
                                                           monkeypatch, capsys):
    for name, text in INPUTS.items():
        (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    before = _snapshot(tmp_path, *WATCHED)
    try:
        status = cli.main(argv)
    except SystemExit as exit_:  # argparse's own usage errors
        status = exit_.code
    captured = capsys.readouterr()
    assert status == 2
    lines = captured.err.strip().splitlines()
    command = ' '.join(argv[:2] if argv[0] in ('table', 'bag', 'primitives', 'bench')
                       else argv[:1])
    # One line, whoever refuses: argparse (a usage error) or the command.
    assert len(lines) == 1, lines
    assert lines[0].startswith(f'sphere-twin {command}: error: '), lines
    assert fragment in lines[0]
    assert 'Traceback' not in captured.err
    assert _snapshot(tmp_path, *WATCHED) == before


def test_debug_shows_the_traceback_of_a_user_error(tmp_path, monkeypatch):
    from sphere_sim.model.scene import SceneError

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SceneError):
        cli.main(['--debug', 'kick', 'nofile.yaml'])


def test_the_case_table_covers_every_subcommand_that_reads_input():
    covered = {argv[0] for argv, _ in (case.values for case in CASES)}
    assert {'kick', 'table', 'report', 'replay-check', 'bag', 'primitives', 'evaluate',
            'validate', 'pullin', 'capacitance', 'optimize-kick', 'calibrate'} <= covered
    assert len(CASES) >= 25
    json.dumps([case.values[0] for case in CASES])  # plain argv lists, as a user types them


def test_the_evaluation_note_names_a_shipped_table_by_its_path_in_the_checkout(tmp_path,
                                                                              monkeypatch):
    """bench/results/evaluation.json's note names the tables it ran on; from a checkout that
    is the path in it, not the machine's absolute one."""
    from pathlib import Path

    from sphere_sim.kicks.lookup_table import DEFAULT_TABLE_PATH
    from sphere_twin.commands.evaluate import shown_path

    root = Path(__file__).resolve().parents[1]
    monkeypatch.chdir(root)
    assert shown_path(DEFAULT_TABLE_PATH) == DEFAULT_TABLE_PATH.resolve().relative_to(root)
    assert not shown_path(DEFAULT_TABLE_PATH).is_absolute()
    monkeypatch.chdir(tmp_path)  # outside the checkout: as given
    assert shown_path(DEFAULT_TABLE_PATH) == DEFAULT_TABLE_PATH
