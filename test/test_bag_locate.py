"""Bags by any name: a bag directory, one of its .mcap files, a bare .mcap file without
metadata.yaml, or the name of a bag installed with the package."""

import shutil
from pathlib import Path

import pytest

from sphere_twin.bag.locate import locate_bag
from sphere_twin.bag.reader import BagError, read_messages
from sphere_twin.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / 'bags' / 'example'
(EXAMPLE_MCAP,) = EXAMPLE.glob('*.mcap')


def _count(bag_dir):
    return sum(1 for _ in read_messages(bag_dir))


@pytest.fixture(scope='module')
def example_count():
    return _count(EXAMPLE)


@pytest.fixture
def bare_mcap(tmp_path):
    path = tmp_path / 'run.mcap'
    shutil.copy(EXAMPLE_MCAP, path)
    return path


def test_the_mcap_file_of_a_bag_is_its_bag():
    bag = locate_bag(EXAMPLE_MCAP)
    assert (bag.directory, bag.name, bag.note) == (EXAMPLE, 'example', None)


def test_a_bare_mcap_file_is_read_from_its_records_and_left_untouched(bare_mcap,
                                                                      example_count):
    before = bare_mcap.read_bytes()
    bag = locate_bag(bare_mcap)
    assert bag.name == 'run'
    assert f'({example_count} messages on ' in bag.note and 'closed cleanly' in bag.note
    assert _count(bag.directory) == example_count
    assert sorted(p.name for p in bare_mcap.parent.iterdir()) == ['run.mcap']
    assert bare_mcap.read_bytes() == before


def test_report_takes_a_bare_mcap_file_and_writes_into_the_working_directory(
        bare_mcap, capsys, tmp_path, monkeypatch):
    work = tmp_path / 'work'
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(['report', str(bare_mcap)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f'{bare_mcap} has no metadata.yaml: read from its own records')
    assert 'kicks: ' in out
    assert (work / 'run_report.json').is_file()
    assert sorted(p.name for p in bare_mcap.parent.iterdir()) == ['run.mcap', 'work']


def test_bag_repair_of_a_bare_mcap_file_makes_its_directory_a_bag(bare_mcap, capsys,
                                                                   example_count):
    assert main(['bag', 'repair', str(bare_mcap)]) == 0
    assert 'had no metadata.yaml' in capsys.readouterr().out
    assert _count(bare_mcap.parent) == example_count
    assert main(['bag', 'info', str(bare_mcap.parent)]) == 0
    assert f'metadata.yaml lists {example_count} messages' in capsys.readouterr().out


def test_an_installed_bag_is_found_by_name_and_reports_into_the_working_directory(
        tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    found = locate_bag('example')
    assert found.directory.name == 'example'
    assert _count(found.directory) == _count(EXAMPLE)
    assert main(['report', 'example']) == 0
    assert (tmp_path / 'example_report.json').is_file()


def test_the_player_plays_a_bag_given_by_its_mcap_file(context, example_count):
    from rclpy.parameter import Parameter

    from sphere_twin.nodes.player_node import PlayerNode

    node = PlayerNode(context=context, parameter_overrides=[Parameter('bag',
                                                                      value=str(EXAMPLE_MCAP))])
    try:
        assert sum(1 for item in node.plan if item.data is not None) == example_count
    finally:
        node.destroy_node()


@pytest.mark.parametrize('given', ['no_such_bag', 'README.md', 'bags/nothing.mcap'])
def test_what_is_no_bag_is_one_line(given, capsys):
    with pytest.raises(BagError, match='is not a bag'):
        locate_bag(given)
    assert main(['report', given]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('sphere-twin report: error: ')


@pytest.mark.parametrize('command', [['report'], ['identify'], ['replay-check'], ['bag', 'info'],
                                     ['bag', 'repair']])
@pytest.mark.parametrize(('content', 'reason'), [
    (b'', 'is empty: no MCAP header was ever written'),
    (b'SQLite format 3\x00' + bytes(100),
     'is not an MCAP file (it does not start with the MCAP magic)')])
def test_a_bare_mcap_file_that_is_no_recording_is_named_as_given(command, content, reason,
                                                                  tmp_path, monkeypatch, capsys):
    """The error names the user's file, not the temporary bag directory it is read through,
    and leaves nothing beside it (bag repair writes no metadata.yaml for it)."""
    monkeypatch.chdir(tmp_path)
    Path('zero.mcap').write_bytes(content)
    assert main([*command, 'zero.mcap']) == 2
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [
        f'sphere-twin {" ".join(command)}: error: zero.mcap {reason}']
    assert captured.out == ''
    assert sorted(p.name for p in tmp_path.iterdir()) == ['zero.mcap']
