"""``sphere-twin bag info|repair BAG``: inspect a bag, or rebuild one whose recorder died."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from msg_defs.device import NS_PER_S

BAG_HELP = ('bag directory, one of its .mcap files, a bare .mcap file (its summary is read), or '
            'the name of an installed bag (example)')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'bag', help='inspect a bag, or repair one whose recorder was killed',
        description='Bag maintenance without ROS: `info` lists what a bag holds and whether '
                    'its MCAP file was closed cleanly; `repair` rebuilds the summary of a file '
                    'left by a recorder that was killed (every complete chunk is kept) and '
                    'regenerates metadata.yaml with the recovered counts and times.')
    actions = parser.add_subparsers(dest='bag_command', metavar='ACTION', required=True)
    info = actions.add_parser('info', help='topics, message counts and file state of a bag')
    info.add_argument('bag', help=BAG_HELP)
    info.set_defaults(func=run_info)
    repair = actions.add_parser(
        'repair', help='rebuild the MCAP summary and metadata.yaml of a damaged bag')
    repair.add_argument('bag', type=Path, help='bag directory, one of its .mcap files, or a bare '
                        '.mcap file (then metadata.yaml is written beside it)')
    repair.add_argument('--no-backup', action='store_true',
                        help='do not keep the damaged MCAP file as <file>.bak')
    repair.set_defaults(func=run_repair)


def info_lines(bag_dir: str | os.PathLike[str]) -> list[str]:
    """The lines ``bag info`` prints.

    Raises
    ------
    BagError
        If ``bag_dir`` is not a readable bag.
    """
    from sphere_twin.bag.reader import check_ros2, read_metadata, scan_mcap, storage_files

    metadata = read_metadata(bag_dir)
    lines = [f'bag: {bag_dir}',
             f'metadata.yaml lists {metadata.get("message_count", 0)} messages']
    for path in storage_files(bag_dir):
        scan = scan_mcap(path)
        check_ros2(path, scan.schemas, scan.channels)
        counts = scan.message_counts()
        times = [m.log_time for m in scan.messages]
        duration_s = (max(times) - min(times)) / NS_PER_S if times else 0.0
        state = ('closed cleanly' if scan.complete
                 else f'not closed ({scan.stop_reason}); run `sphere-twin bag repair`')
        lines.append(f'{path.name}: {len(scan.messages)} readable messages in '
                     f'{scan.chunk_count} chunks over {duration_s:.3f} s, {state}')
        for channel_id, channel in scan.channels.items():
            lines.append(f'  {channel.topic} ({scan.type_name(channel_id)}): '
                         f'{counts[channel_id]}')
    return lines


def run_info(args: argparse.Namespace) -> int:
    from sphere_twin.bag.locate import locate_bag

    bag = locate_bag(args.bag)
    if bag.note:
        print(bag.note)
    print('\n'.join(info_lines(bag.directory)))
    return 0


def run_repair(args: argparse.Namespace) -> int:
    from sphere_twin.bag.reader import BagError
    from sphere_twin.bag.repair import repair_bag

    bag_dir, written = args.bag, None
    if args.bag.is_file():
        bag_dir, written = _bag_dir_of_file(args.bag)
    try:
        result = repair_bag(bag_dir, backup=not args.no_backup)
    except BagError:
        if written is not None:  # a file that is no bag leaves no metadata.yaml behind
            written.unlink(missing_ok=True)
        raise
    if written is not None:
        print(f'{args.bag} had no metadata.yaml: wrote {written} from its records')
    print(result.summary())
    return 0


def _bag_dir_of_file(path: Path) -> tuple[Path, Path | None]:
    """The directory of an MCAP file to repair, with a metadata.yaml that lists it, and that
    metadata.yaml's path when it was written here (there was none), else None."""
    from sphere_twin.bag import format as bag_format
    from sphere_twin.bag.locate import MCAP_SUFFIX, lists_file, write_placeholder_metadata
    from sphere_twin.bag.reader import BagError, read_metadata

    if path.suffix != MCAP_SUFFIX:
        raise BagError(f'{path} is not a bag: give a bag directory or an {MCAP_SUFFIX} file')
    metadata_path = path.parent / bag_format.METADATA_FILENAME
    if not metadata_path.exists():
        write_placeholder_metadata(path.parent, path.name)
        return path.parent, metadata_path
    if not lists_file(path.parent, path.name):
        read_metadata(path.parent)  # a metadata.yaml that is no bag's says so first
        raise BagError(f'{path} is not listed in {metadata_path}: repair that bag, or move the '
                       'file to a directory of its own')
    return path.parent, None
