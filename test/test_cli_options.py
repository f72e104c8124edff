"""The options the subcommands share: one --params, resolved once, errors as usage errors."""

import argparse
import itertools
from pathlib import Path

import pytest

from sphere_sim.model.parameters import ParameterSet, load_parameter_set
from sphere_twin.cli import build_parser
from sphere_twin.commands.options import parameter_set

REPO = Path(__file__).resolve().parents[1]


def subcommand_parsers(parser):
    """(name, parser) of every subcommand, nested ones included."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield name, sub
                for inner, subsub in subcommand_parsers(sub):
                    yield f'{name} {inner}', subsub


def params_actions():
    out = {}
    for name, sub in subcommand_parsers(build_parser()):
        for action in sub._actions:
            if any('param' in option for option in action.option_strings):
                out[name] = action
    return out


def test_every_command_that_takes_a_parameter_set_takes_it_the_same_way():
    actions = params_actions()
    assert {'kick', 'pullin', 'capacitance', 'validate', 'optimize-kick', 'table build',
            'primitives width', 'primitives offsets', 'replay-check'} <= set(actions)
    for name, action in actions.items():
        assert action.option_strings == ['--params'], name
        assert action.type is parameter_set, name


def test_the_option_hands_down_a_loaded_set_and_reads_files(tmp_path):
    args = build_parser().parse_args(['validate'])
    assert isinstance(args.params, ParameterSet)
    assert args.params == load_parameter_set()
    override = tmp_path / 'stiffer.yaml'
    override.write_text('base: calibrated\nname: stiffer\n'
                        'overrides:\n  contact.stiffness_n_per_m: 2.0e5\n')
    args = build_parser().parse_args(['pullin', '--params', str(override)])
    assert args.params.name == 'stiffer'
    assert args.params.contact.stiffness_n_per_m == 2.0e5
    # kick leaves the choice to the scene unless told.
    assert build_parser().parse_args(['kick', 'rest']).params is None


@pytest.mark.parametrize('argv', [['validate', '--params', 'nosuch'],
                                  ['capacitance', '--params', 'nosuch.yaml'],
                                  ['table', 'build', '--params', 'nosuch']])
def test_a_bad_parameter_set_is_a_one_line_usage_error(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith(f'sphere-twin {argv[0]}') and 'error: argument --params:' in err
    assert 'nosuch' in err and 'Traceback' not in err


def test_validate_prints_the_widths_with_the_shipped_offsets_only_for_the_set_they_belong_to(
        monkeypatch):
    """The shipped voltage offsets were searched for the shipped design on `calibrated`: a file
    that keeps the name but changes a value is another device and gets none, nor does another
    set."""
    from pathlib import Path

    from sphere_sim.kicks.offset_lookup import OffsetLookup
    from sphere_twin.commands import validate

    monkeypatch.chdir(Path(__file__).parents[1])
    design = validate._design(None)
    calibrated = load_parameter_set('calibrated')
    lookup = validate._offsets(design, calibrated)
    assert isinstance(lookup, OffsetLookup) and lookup
    softer = calibrated.replace(**{'friction.bristle_stiffness_n_per_m': 1e3})
    assert softer.name == 'calibrated' and validate._offsets(design, softer) is None
    assert validate._offsets(design, load_parameter_set('dry_contact')) is None


def test_kick_help_lists_every_shipped_scene(capsys):
    shipped = sorted(p.stem for p in (REPO / 'sphere_sim' / 'scenes').glob('*.yaml'))
    assert {'rest', 'asymmetric_kick'} <= set(shipped)
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(['kick', '--help'])
    assert exit_.value.code == 0
    help_text = ' '.join(capsys.readouterr().out.split())  # argparse wraps at the terminal
    assert f'a shipped scene ({", ".join(shipped)}) or the path of a scene YAML file' in help_text


def test_the_readme_command_table_names_every_subcommand():
    readme = (REPO / 'README.md').read_text()
    lines = readme[readme.index('| command | what it does |'):].splitlines()[2:]
    rows = itertools.takewhile(lambda line: line.startswith('| `'), lines)
    named = {row[3:].split('`')[0].split()[0] for row in rows}
    commands = {name for name, _ in subcommand_parsers(build_parser()) if ' ' not in name}
    assert commands == named
