"""What a command writes when not told where lands in the working directory: never in a tracked
file, never beside a shipped bag, and under a name git ignores."""

import argparse
import subprocess
from pathlib import Path

from sphere_twin import cli

REPO = Path(__file__).resolve().parents[1]
# Options that name where a command writes.
OUTPUT_DESTS = ('out', 'output', 'plot', 'bags_dir')
# What the commands write by default, one name per pattern of .gitignore's list.
DEFAULT_OUTPUT_NAMES = (
    'example_report.png', 'example_report.json', 'example_report.txt', 'example_replay.png',
    'example_replay.json', 'synthetic_device_identified.yaml',
    'synthetic_device_identified_start.yaml', 'work_precision.md', 'work_precision_quick.csv',
    'regularisation.csv', 'throughput.json', 'twin_continuous_paced.json', 'twin_discrete.md',
    'fast_costs.md', 'threshold_search.md', 'evaluation.json', 'evaluation_fig15.png',
    'fig4_pullin_calibrated.png',
    'identification.md', 'identification.json', 'kick_optimization.json',
    'kick_optimization_axis.json', 'kick_table.npz', 'rotation_width.png',
    'voltage_offsets.json', 'bags/demo_20260101T000000Z/demo_0.mcap',
    'bags/demo_20260101T000000Z_error.png',
)


def _subcommand_parsers(parser, prog=()):
    """Every (sub)parser with the command words that reach it."""
    yield prog, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _subcommand_parsers(sub, (*prog, name))


def test_no_output_option_defaults_outside_the_working_directory():
    checked = 0
    for prog, parser in _subcommand_parsers(cli.build_parser()):
        for action in parser._actions:
            if action.dest not in OUTPUT_DESTS or action.default is None:
                continue
            path = Path(action.default)
            # The working directory itself, or a name in it (the demo's bags/ folder).
            assert not path.is_absolute() and len(path.parts) <= 1, (prog, action.default)
            checked += 1
    # The walk saw the commands that write (bench's four, evaluate, primitives, table, ...).
    assert checked >= 10


def test_report_writes_into_the_working_directory_not_beside_the_shipped_bag(
        tmp_path, monkeypatch, capsys):
    bags = REPO / 'bags'
    before = sorted(p.relative_to(bags) for p in bags.rglob('*'))
    monkeypatch.chdir(tmp_path)
    assert cli.main(['report', 'example']) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        'example_report.json', 'example_report.png', 'example_report.txt']
    assert sorted(p.relative_to(bags) for p in bags.rglob('*')) == before
    assert 'kicks: ' in capsys.readouterr().out


def test_every_default_output_name_is_ignored_by_git():
    result = subprocess.run(['git', '-C', str(REPO), 'check-ignore', '--no-index',
                             *DEFAULT_OUTPUT_NAMES], capture_output=True, text=True, check=False)
    ignored = set(result.stdout.split())
    assert ignored == set(DEFAULT_OUTPUT_NAMES)
    # and the committed results are not: a pattern must not hide them.
    committed = subprocess.run(['git', '-C', str(REPO), 'check-ignore', '--no-index',
                                'bench/results/evaluation.json', 'bags/example/metadata.yaml',
                                'sphere_sim/tables/default_kick_table.npz'],
                               capture_output=True, text=True, check=False)
    assert committed.stdout == ''
