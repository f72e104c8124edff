"""``sphere-twin bag info|repair BAG``: inspect a bag, or rebuild one whose recorder died."""

from pathlib import Path

from msg_defs.device import NS_PER_S


def register(subparsers):
    parser = subparsers.add_parser(
        'bag', help='inspect a bag, or repair one whose recorder was killed',
        description='Bag maintenance without ROS: `info` lists what a bag holds and whether '
                    'its MCAP file was closed cleanly; `repair` rebuilds the summary of a file '
                    'left by a recorder that was killed (every complete chunk is kept) and '
                    'regenerates metadata.yaml with the recovered counts and times.')
    actions = parser.add_subparsers(dest='bag_command', metavar='ACTION', required=True)
    info = actions.add_parser('info', help='topics, message counts and file state of a bag')
    info.add_argument('bag', type=Path, help='bag directory (with metadata.yaml)')
    info.set_defaults(func=run_info)
    repair = actions.add_parser(
        'repair', help='rebuild the MCAP summary and metadata.yaml of a damaged bag')
    repair.add_argument('bag', type=Path, help='bag directory (with metadata.yaml)')
    repair.add_argument('--no-backup', action='store_true',
                        help='do not keep the damaged MCAP file as <file>.bak')
    repair.set_defaults(func=run_repair)


def info_lines(bag_dir):
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


def run_info(args):
    print('\n'.join(info_lines(args.bag)))
    return 0


def run_repair(args):
    from sphere_twin.bag.repair import repair_bag

    print(repair_bag(args.bag, backup=not args.no_backup).summary())
    return 0
