"""Finding a bag by whatever a user passes: a bag directory, one of its MCAP files, a bare MCAP
file without metadata.yaml, or the name of a bag installed with the package (``example``).

``ros2 bag info`` and Foxglove accept the MCAP file of a bag as well as its directory; so do
``sphere-twin report``, ``replay-check``, ``bag info``, ``bag repair`` and the player.
"""

import atexit
import dataclasses
import os
import shutil
import tempfile
from pathlib import Path

import yaml

from sphere_twin.bag import format as bag_format
from sphere_twin.bag.reader import BagError, read_metadata

MCAP_SUFFIX = '.mcap'
# The source tree's bags, for a checkout that was not installed.
SOURCE_BAGS_DIR = Path(__file__).resolve().parents[2] / 'bags'


@dataclasses.dataclass(frozen=True)
class BagLocation:
    """Where a bag's directory is and what to call it (a command's outputs are named after it
    and go into the working directory, never beside the bag).

    Attributes
    ----------
    directory : pathlib.Path
        A bag directory the readers take (metadata.yaml and the MCAP file).
    name : str
        What the user's bag is called (outputs are named after it).
    note : str or None
        What was done to read it, to say to the user (a bare MCAP file's recovered summary).
    """

    directory: Path
    name: str
    note: str | None = None


def lists_file(bag_dir: str | os.PathLike[str], file_name: str) -> bool:
    """Whether the bag directory's metadata.yaml lists ``file_name`` (False without one)."""
    try:
        listed = read_metadata(bag_dir).get('relative_file_paths') or []
    except BagError:
        return False
    return file_name in [Path(p).name for p in listed]


def _installed(name: str) -> Path | None:
    """A bag of that name installed with the package (``share/sphere_twin/bags``) or in the
    source tree, or None."""
    if not name or '/' in name or name.endswith(MCAP_SUFFIX):
        return None
    places = [share / 'bags' for share in bag_format.package_share_candidates('sphere_twin')]
    for place in [*places, SOURCE_BAGS_DIR]:
        if (place / name / bag_format.METADATA_FILENAME).is_file():
            return place / name
    return None


def write_placeholder_metadata(bag_dir: str | os.PathLike[str], file_name: str) -> None:
    """Write a metadata.yaml into ``bag_dir`` that lists ``file_name`` and nothing else;
    ``repair_bag`` then fills in the rest from the file's records."""
    (Path(bag_dir) / bag_format.METADATA_FILENAME).write_text(yaml.safe_dump(
        {'rosbag2_bagfile_information': {
            'version': bag_format.METADATA_VERSION,
            'storage_identifier': bag_format.STORAGE_IDENTIFIER,
            'relative_file_paths': [file_name], 'message_count': 0,
            'topics_with_message_count': []}}))


def _read_bare_mcap(path: Path) -> tuple[Path, str]:
    """A bag directory (temporary, removed at exit) that holds a link to the bare MCAP file
    and the metadata recovered from its records."""
    from sphere_twin.bag.repair import repair_bag

    view = Path(tempfile.mkdtemp(prefix='sphere_twin_bag_'))
    atexit.register(shutil.rmtree, view, True)
    (view / path.name).symlink_to(path.resolve())
    write_placeholder_metadata(view, path.name)
    try:
        result = repair_bag(view, backup=False)
    except BagError as error:
        # The view is a detail of reading: the user gave the file, so the error names it.
        shutil.rmtree(view, True)
        raise BagError(str(error).replace(str(view / path.name), str(path))) from None
    state = ('closed cleanly' if result.was_complete
             else f'not closed ({result.stop_reason})')
    return view, (f'{path} has no metadata.yaml: read from its own records '
                  f'({result.message_count} messages on {len(result.topic_counts)} topics, '
                  f'{state})')


def locate_bag(given: str | os.PathLike[str]) -> BagLocation:
    """The bag that ``given`` (a path or an installed bag's name) names.

    Raises
    ------
    BagError
        If it names none, with what was looked for.
    """
    path = Path(given)
    if path.is_dir():
        return BagLocation(path, path.name)
    if path.is_file() and path.suffix == MCAP_SUFFIX:
        if lists_file(path.parent, path.name):
            return BagLocation(path.parent, path.parent.name)
        view, note = _read_bare_mcap(path)
        return BagLocation(view, path.stem, note)
    if path.is_file():
        raise BagError(f'{given} is not a bag: give a bag directory or an {MCAP_SUFFIX} file')
    installed = _installed(str(given))
    if installed is not None:
        return BagLocation(installed, installed.name)
    raise BagError(f'{given} is not a bag: no such directory or {MCAP_SUFFIX} file, and no bag '
                   'of that name is installed with sphere_twin')
