"""Every bad option value and output path is one line, status 2, and nothing written.

The cases run ``sphere-twin`` in this process, from an empty working directory holding a text
file (``notes.txt``, where a directory is needed) and an empty directory (``figs``, where a file
is needed), like test_cli_errors. Each is refused before any computing: by the option's checked
type (a range, finite numbers only, an output path that can be written), or, for a run too
long to sample, before its initial state is solved.
"""

import argparse
import io
from pathlib import Path

import pytest

from sphere_sim.integrate.segment import SolverError, SolverStatus
from sphere_twin import cli
from sphere_twin.commands import kick, options

REPO = Path(__file__).resolve().parents[1]
WATCHED = (REPO / 'bench' / 'results', REPO / 'sphere_sim' / 'tables', REPO / 'bags')
NESTED_COMMANDS = ('table', 'bag', 'primitives', 'bench', 'synthetic')
SCENE = ('name: long\ndescription: ten minutes of rest\nparameters: calibrated\n'
         'beams: [1, 2, 3, 4]\nsphere: true\ninitial_state: {mode: rest}\n')
RTOL_RANGE = 'must be a positive number from 1e-12 to 0.01'
DURATION_RANGE = 'must be a positive number from 0.001 to 3600'
GRID_RANGE = 'must be a positive number from 0.01 to 1'
SEED_RANGE = 'must be an integer from 0 to 4294967295'
NOT_A_DIRECTORY = 'cannot create notes.txt/sub: notes.txt is a file, not a directory'


def _case(argv, line):
    return pytest.param(argv, line, id=' '.join(argv)[:60])


CASES = [
    # tolerances: a range, not just "positive" (1e-30 hung, 10 failed naming no option)
    _case(['kick', 'rest', '--rtol', '10'], f'argument --rtol: {RTOL_RANGE}'),
    _case(['kick', 'rest', '--rtol', '1e-30'], f'argument --rtol: {RTOL_RANGE}'),
    _case(['kick', 'rest', '--rtol', 'nan'], f'argument --rtol: {RTOL_RANGE}'),
    _case(['kick', 'rest', '--rtol', 'inf'], f'argument --rtol: {RTOL_RANGE}'),
    # durations, and a scene whose sample grid would not fit in memory
    _case(['bench', 'twin', '--duration-s', '1e9', '--out', 'out'],
          f'argument --duration-s: {DURATION_RANGE}'),
    _case(['bench', 'twin', '--duration-s', 'nan', '--out', 'out'],
          f'argument --duration-s: {DURATION_RANGE}'),
    _case(['bench', 'twin', '--real-time-factor', 'nan', '--out', 'out'],
          'argument --real-time-factor: must be a number >= 0'),
    _case(['kick', 'long.yaml'], 'a run of 600 s sampled every 0.0001 s would hold 6e+06 '
                                 'samples (2.06 GiB); the duration must be at most 291.8 s at '
                                 'this sampling'),
    # a directory where a file is needed, a file where a directory is needed
    _case(['pullin', '--plot', 'figs'], 'argument --plot: figs is a directory; give a file name '
                                        'in it'),
    _case(['pullin', '--plot', 'figure'], 'argument --plot: figure: the file name must end in '
                                          '.png'),
    _case(['capacitance', '--plot', 'figs/'], 'argument --plot: figs/ is a directory; give a '
                                              'file name in it'),
    _case(['optimize-kick', '--output', 'figs'], 'argument --output: figs is a directory; give '
                                                 'a file name in it'),
    _case(['table', 'build', '--output', 'table.txt'],
          'argument --output: table.txt: the file name must end in .npz'),
    _case(['bench', 'work-precision', '--out', 'notes.txt'],
          'argument --out: notes.txt is a file; give a directory'),
    # an output directory that cannot be created is refused before the computing
    _case(['bench', 'regularisation', '--out', 'notes.txt/sub'], f'argument --out: '
                                                                 f'{NOT_A_DIRECTORY}'),
    _case(['bench', 'throughput', '--out', 'notes.txt/sub'], f'argument --out: {NOT_A_DIRECTORY}'),
    _case(['bench', 'twin', '--out', 'notes.txt/sub'], f'argument --out: {NOT_A_DIRECTORY}'),
    _case(['evaluate', '--out', 'notes.txt/sub'], f'argument --out: {NOT_A_DIRECTORY}'),
    _case(['primitives', 'width', '--out', 'notes.txt/sub'], f'argument --out: '
                                                             f'{NOT_A_DIRECTORY}'),
    _case(['primitives', 'offsets', '--out', 'notes.txt/sub'], f'argument --out: '
                                                               f'{NOT_A_DIRECTORY}'),
    _case(['synthetic', 'record', 'notes.txt/sub'], f'argument out: {NOT_A_DIRECTORY}'),
    _case(['synthetic', 'study', '--out', 'notes.txt/sub/study.md'],
          'argument --out: cannot create notes.txt/sub: notes.txt is a file, not a directory'),
    _case(['optimize-kick', '--output', 'notes.txt/sub/kick.json'],
          'argument --output: cannot create notes.txt/sub: notes.txt is a file, not a directory'),
    # nan, inf and out-of-range numbers of every other float option
    _case(['primitives', 'width', '--alphas-deg', 'nan', '--out', 'out'],
          'argument --alphas-deg: must be a number from -40 to 40 (degrees of tilt inside the '
          'cone of the paper), got nan'),
    _case(['primitives', 'width', '--alphas-deg', '0', 'inf', '--out', 'out'],
          'argument --alphas-deg: must be a number from -40 to 40 (degrees of tilt inside the '
          'cone of the paper), got inf'),
    _case(['primitives', 'width', '--alphas-deg', '80', '--out', 'out'],
          'argument --alphas-deg: must be a number from -40 to 40 (degrees of tilt inside the '
          'cone of the paper), got 80'),
    _case(['primitives', 'offsets', '--grid-step', 'nan', '--out', 'out'],
          f'argument --grid-step: {GRID_RANGE}'),
    _case(['table', 'build', '--grid-step', '1e-9', '--output', 'out.npz'],
          f'argument --grid-step: {GRID_RANGE}'),
    _case(['table', 'check', '--grid', '0'], f'argument --grid: {GRID_RANGE}'),
    _case(['table', 'build', '--window-s', 'nan', '--output', 'out.npz'],
          'argument --window-s: must be a positive number from 0.01 to 1'),
    _case(['evaluate', '--kick-period-s', '1e6', '--out', 'out'],
          'argument --kick-period-s: must be a positive number from 0.01 to 10'),
    _case(['evaluate', '--kick-period-s', 'nan', '--out', 'out'],
          'argument --kick-period-s: must be a positive number from 0.01 to 10'),
    _case(['capacitance', '--fringe-angle-rad', 'inf'],
          'argument --fringe-angle-rad: must be a positive number, got inf'),
    # seeds: numpy's are unsigned 32-bit
    _case(['optimize-kick', '--seed', '-1', '--output', 'out.json'],
          f'argument --seed: {SEED_RANGE}, got -1'),
    _case(['table', 'check', '--seed', '-5'], f'argument --seed: {SEED_RANGE}, got -5'),
    _case(['synthetic', 'record', 'bag', '--seed', 'nan'],
          "argument --seed: not an integer: 'nan'"),
]


def _snapshot(*roots):
    return {p: p.stat().st_mtime_ns for root in roots if root.exists()
            for p in root.rglob('*') if p.is_file()}


def _command_of(argv):
    return ' '.join(argv[:2] if argv[0] in NESTED_COMMANDS else argv[:1])


def _run(argv, tmp_path, monkeypatch, capsys):
    """(status, stderr lines) of ``sphere-twin argv`` in ``tmp_path``; asserts it wrote
    nothing there nor in the shipped results, tables and bags."""
    (tmp_path / 'notes.txt').write_text('a text file\n')
    (tmp_path / 'figs').mkdir()
    (tmp_path / 'long.yaml').write_text(SCENE + 'duration_s: 600\n')
    monkeypatch.chdir(tmp_path)
    before = _snapshot(tmp_path, *WATCHED)
    dirs_before = sorted(p for p in tmp_path.rglob('*') if p.is_dir())
    try:
        status = cli.main(argv)
    except SystemExit as exit_:  # argparse's own usage errors
        status = exit_.code
    err = capsys.readouterr().err
    assert 'Traceback' not in err
    assert _snapshot(tmp_path, *WATCHED) == before
    assert sorted(p for p in tmp_path.rglob('*') if p.is_dir()) == dirs_before
    return status, err.strip().splitlines()


@pytest.mark.parametrize(('argv', 'line'), CASES)
def test_bad_input_is_refused_in_one_line(argv, line, tmp_path, monkeypatch, capsys):
    status, lines = _run(argv, tmp_path, monkeypatch, capsys)
    assert status == 2
    prefix = f'sphere-twin {_command_of(argv)}: error: '
    # One line, whoever refuses: argparse (a usage error) or the command.
    assert len(lines) == 1, lines
    assert lines[0].startswith(prefix + line), lines


def test_bad_input_hopeless_tolerance_names_the_option(tmp_path, monkeypatch, capsys):
    def stalls(*args, **kwargs):
        raise SolverError('fast: step size fell below 10 ulp of t at t = 0.002 s (h = 1e-19 s)',
                          0.002, None, SolverStatus.STEP_TOO_SMALL)

    monkeypatch.setattr(kick, 'run_scene', stalls)
    status, lines = _run(['kick', 'rest', '--rtol', '0.01'], tmp_path, monkeypatch, capsys)
    assert status == 2
    assert lines == ["sphere-twin kick: error: fast: step size fell below 10 ulp of t at "
                     "t = 0.002 s (h = 1e-19 s): the integration of scene 'rest' at --rtol 0.01 "
                     "gave up; try another --rtol from 1e-12 to 1e-2 (default 1e-06)"]


def subcommand_parsers(parser):
    """(name, parser) of every subcommand, nested ones included."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield name, sub
                yield from ((f'{name} {inner}', p) for inner, p in subcommand_parsers(sub))


def test_bad_input_nan_and_inf_fail_every_number_option():
    """No option parses a bare float (which takes nan and inf); every checked number type
    refuses both."""
    checked = 0
    for name, parser in subcommand_parsers(cli.build_parser()):
        for action in parser._actions:
            assert action.type is not float, (name, action.option_strings)
            if action.type is None or not action.option_strings or action.choices:
                continue
            for text in ('nan', 'inf', '-inf'):
                try:
                    action.type(text)
                except argparse.ArgumentTypeError:
                    checked += 1
                except Exception:  # a file or set loader: it refuses its own way
                    pass
    assert checked >= 3 * 15


def test_an_output_that_can_be_created_is_accepted_and_not_created(tmp_path):
    deep = tmp_path / 'a' / 'b' / 'c'
    assert options.output_directory(str(deep)) == deep
    assert options.output_file('.png')(str(deep / 'x.png')) == deep / 'x.png'
    assert not (tmp_path / 'a').exists()


def test_a_scene_without_a_sphere_prints_its_beams(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(['kick', 'beams_only']) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith('scene: beams_only (parameters: calibrated), 10.0 ms simulated')
    assert lines[0].endswith('no sphere, the beams alone')
    # The 80 V pulse on all four beams moves them alike, by micrometres, and lets them go.
    excursions = [float(part.split(': ')[1]) for part in
                  lines[2].removeprefix('largest tip excursion (um): ').split(', ')]
    assert len(excursions) == 4 and max(excursions) - min(excursions) < 1e-3
    assert 1.0 < excursions[0] < 10.0
    assert lines[3].startswith('smallest electrode gap (um): beam 1: ')


def test_the_cases_cover_every_command_that_writes():
    covered = {_command_of(argv) for argv, _ in (case.values for case in CASES)}
    assert {'pullin', 'capacitance', 'optimize-kick', 'table build', 'evaluate',
            'bench work-precision', 'bench regularisation', 'bench throughput', 'bench twin',
            'primitives width', 'primitives offsets', 'synthetic record',
            'synthetic study'} <= covered
    assert len(CASES) >= 20


def test_a_study_writes_into_the_new_directory_it_was_given(tmp_path, monkeypatch):
    """The output check accepts a directory that can be created; the study then creates it
    when it writes (it once computed for minutes and failed to write: results lost)."""
    from sphere_sim.studies.regularisation import STUDIES
    from sphere_twin.commands import bench

    def rows(programmes, direction_rad, rtols, progress):
        return [{'parameter': path, 'value': value, 'kick': name, 'rtol': rtol,
                 'along_deg': 0.5, 'steps': 10}
                for path, values in STUDIES for value in values for name in programmes
                for rtol in rtols]

    monkeypatch.setattr(bench, 'regularisation_rows', rows)
    out = options.output_directory(str(tmp_path / 'missing' / 'dir' / 'x'))
    written = bench.run_regularisation_study(quick=True, out_dir=out, stream=io.StringIO())
    assert (out / 'regularisation.csv').read_text().count('\n') == len(written) + 1
    assert '| rtol 1e-07 | steps |' in (out / 'regularisation.md').read_text()


def test_identify_thresholds_of_a_bag_without_the_protocol_says_so(tmp_path, monkeypatch,
                                                                  capsys):
    """A bag without a threshold search (the demo's) has nothing to fit: one error line naming
    the bag and what would record one, status 2, after the line that says it read the bag."""
    bag = REPO / 'bags' / 'example'
    status, lines = _run(['identify', str(bag), '--thresholds'], tmp_path, monkeypatch, capsys)
    assert status == 2
    assert lines[-1] == (f'sphere-twin identify: error: {bag}: no threshold search of the '
                         'experiment protocol with both sides seen (record one with sphere-twin '
                         'experiment or sphere-twin synthetic record --protocol)')
    assert all('error' not in line for line in lines[:-1])
