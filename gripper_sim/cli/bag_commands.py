"""CLI verbs for recordings: ``record``, ``replay``, ``info``, ``analyze``, ``recover``.

A recording is a rosbag2 bag folder (``NAME/NAME_0.mcap``, ... and ``metadata.yaml``)
or a single ``.mcap`` file; every verb takes either. Each handler imports what it needs
when it runs (rclpy only for ``record`` and ``replay``), so ``info``, ``analyze`` and
``recover`` work from the files alone.
Bad input raises ``RecordingError``; ``main`` prints it as ``error: ...`` and exits 2.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from datetime import datetime, timezone
from pathlib import Path

from gripper_sim.cli.arguments import non_negative_float, port_number, positive_float


def _remap(text: str) -> tuple[str, str]:
    if ':=' not in text:
        raise argparse.ArgumentTypeError(f"remap '{text}' must look like /old:=/new")
    old, new = text.split(':=', 1)
    if not old or not new:
        raise argparse.ArgumentTypeError(f"remap '{text}' must look like /old:=/new")
    return old, new


def _byte_count(text: str) -> int:
    """A whole number of bytes >= 0, optionally with a K, M or G (binary) suffix."""
    units = {'K': 2**10, 'M': 2**20, 'G': 2**30}
    number, scale = text.strip(), 1
    if number[-1:].upper() in units:
        number, scale = number[:-1], units[number[-1].upper()]
    try:
        value = int(number)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"'{text}' is not a whole number of bytes (e.g. 1048576 or 1M)") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be >= 0")
    return value * scale


def register(subparsers) -> None:
    p = subparsers.add_parser(
        'record', help='record live topics to a rosbag2 bag folder (MCAP)',
        description='Subscribe (raw) to live topics of any node and write them as '
                    "'ros2 bag record' does: a bag folder NAME/ with NAME_0.mcap, NAME_1.mcap, "
                    '... and metadata.yaml. Ctrl-C or --duration ends the recording cleanly.')
    p.add_argument('topics', nargs='*', metavar='TOPIC', help='topics to record')
    p.add_argument('-o', '--output', required=True, metavar='NAME',
                   help='bag folder to create, or one file if NAME ends in .mcap (never '
                        'overwritten)')
    p.add_argument('-a', '--all', action='store_true',
                   help='record every topic, including ones that appear while recording')
    p.add_argument('-e', '--regex', metavar='REGEX',
                   help='also record topics whose whole name matches REGEX')
    p.add_argument('-x', '--exclude', metavar='REGEX',
                   help='never record topics whose whole name matches REGEX')
    p.add_argument('-b', '--max-bag-size', type=_byte_count, default=0, metavar='BYTES',
                   help='start a new file of the bag when the current one reaches BYTES '
                        '(suffix K, M or G allowed; 0 = never, the default)')
    p.add_argument('--max-bag-duration', type=non_negative_float, default=0.0, metavar='S',
                   help='start a new file of the bag after S seconds of messages '
                        '(0 = never, the default)')
    p.add_argument('--compression', default='zstd', metavar='ZSTD|LZ4|NONE',
                   type=str.lower, help='MCAP chunk compression: zstd (the default), lz4, or '
                   'none (off)')
    p.add_argument('-d', '--duration', type=positive_float, metavar='S',
                   help='stop after S seconds (wall clock)')
    p.add_argument('--flush-interval', type=positive_float, default=0.5, metavar='S',
                   help='close and write a chunk at least every S seconds (default 0.5): '
                        'a killed recorder loses at most about this much')
    p.add_argument('--max-messages', type=int, metavar='N',
                   help='stop after N messages')
    p.set_defaults(handler=_record)

    p = subparsers.add_parser(
        'replay', help='republish the messages of an MCAP recording',
        description='Publish the raw messages of a recording with their original relative '
                    'timing and QoS.')
    p.add_argument('file', metavar='BAG', help='bag folder or .mcap file')
    p.add_argument('-r', '--rate', type=positive_float, default=1.0,
                   help='playback speed factor (default 1)')
    p.add_argument('-l', '--loop', action='store_true', help='play again and again')
    p.add_argument('--topics', nargs='+', metavar='TOPIC', help='only these topics')
    p.add_argument('--start', type=non_negative_float, default=0.0, metavar='S',
                   help='skip the first S seconds of the recording')
    p.add_argument('--clock', nargs='?', type=positive_float, const=100.0, metavar='HZ',
                   help='publish /clock from the recording time (default 100 Hz) so nodes '
                        'with use_sim_time follow the replay')
    p.add_argument('--remap', action='append', type=_remap, default=[], metavar='OLD:=NEW',
                   help='publish topic OLD as NEW (repeatable)')
    p.add_argument('--wait-for-subscribers', type=non_negative_float, default=0.0,
                   metavar='S', help='before playing, wait up to S seconds until every '
                   'replayed topic has a subscriber')
    p.add_argument('--foxglove', nargs='?', type=port_number, const=8765, metavar='PORT',
                   help='also serve the replay and its 3D scene to Foxglove on '
                        '127.0.0.1:PORT (default 8765)')
    p.set_defaults(handler=_replay)

    p = subparsers.add_parser('info', help='topics, types, counts and duration of a recording')
    p.add_argument('file', metavar='BAG', help='bag folder or .mcap file')
    p.add_argument('--json', action='store_true', help='print JSON')
    p.set_defaults(handler=_info)

    p = subparsers.add_parser(
        'analyze', help='time series, summary and figures of a recorded grasp',
        description='Read FruitState and jaw wrenches from a recording (no ROS graph needed) '
                    'and write a CSV time series, a summary JSON, PNG figures and an HTML '
                    'report (report.html, opens offline), for each run of the recording.')
    p.add_argument('file', metavar='BAG', help='bag folder or .mcap file')
    p.add_argument('-o', '--output-dir', default=None, metavar='DIR',
                   help='new folder to write to (default: BAG without .mcap, plus '
                        '_analysis); an existing one is refused without --force')
    p.add_argument('-f', '--force', action='store_true',
                   help='write into DIR even if it exists (files of the same names are '
                        'replaced)')
    p.add_argument('--namespace', default=None,
                   help='topic prefix of the sim node, e.g. /gripper_sim (default: found)')
    p.add_argument('--no-figures', action='store_true', help='write CSV and JSON only')
    p.add_argument('--no-html', action='store_true', help='no report.html')
    p.add_argument('--quiet', action='store_true',
                   help='no progress bar (it shows on a terminal after 2 s)')
    p.set_defaults(handler=_analyze)

    p = subparsers.add_parser(
        'recover', help='rebuild a readable recording from a truncated or killed one',
        description='Copy every whole message of IN into a new indexed recording OUT: a '
                    'file into a file, a bag folder into a new bag folder. IN is only read, '
                    'never modified.')
    p.add_argument('input', metavar='IN', help='.mcap file or bag folder')
    p.add_argument('output', metavar='OUT', help='.mcap file or bag folder to create')
    p.add_argument('-f', '--force', action='store_true', help='replace OUT if it exists')
    p.set_defaults(handler=_recover)


# ---------------------------------------------------------------------- helpers
def _format_size(n: int) -> str:
    size = float(n)
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if size < 1024 or unit == 'GiB':
            return f'{size:.1f} {unit}' if unit != 'B' else f'{n} B'
        size /= 1024
    return f'{n} B'


def _format_time(ns: int) -> str:
    try:
        when = datetime.fromtimestamp(ns // 1_000_000_000, tz=timezone.utc)
        text = when.strftime('%b %d %Y %H:%M:%S')
    except (OverflowError, OSError, ValueError):
        text = '?'
    sec, frac = divmod(ns, 1_000_000_000)
    return f'{text}.{frac:09d} UTC ({sec}.{frac:09d})'


def info_dict(path: str) -> dict:
    """What ``info`` prints, as a dict."""
    from gripper_sim.recording.reader import BagReader

    with BagReader(path) as bag:
        checked = bag.verify()
        bag_meta = bag.bag_metadata() or {}
        return {
            'file': str(bag.path),
            'files': [str(f) for f in bag.files],
            'bag_folder': bag.is_folder,
            'metadata_yaml': bag.folder_metadata is not None,
            'size': sum(f.stat().st_size for f in bag.files),
            'profile': bag.profile,
            'library': bag.library,
            'ros_distro': bag_meta.get('ros_distro', ''),
            'compression': sorted(c for c in bag.compression if c),
            'chunks': bag.chunk_count,
            'chunks_verified': checked,
            'messages': bag.message_count,
            'start_ns': bag.start_time,
            'end_ns': bag.end_time,
            'duration_s': bag.duration_ns / 1e9,
            'topics': [{'name': t.name, 'type': t.type, 'count': t.message_count,
                        'serialization_format': t.message_encoding,
                        'type_hash': t.type_hash,
                        'qos': t.offered_qos_profiles}
                       for t in bag.topics.values()],
            'metadata': list(dict.fromkeys(name for name, _ in bag.metadata)),
        }


def _info(args: argparse.Namespace) -> int:
    data = info_dict(args.file)
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    names = data['files'] if not data['bag_folder'] else \
        [Path(f).name for f in data['files']]
    lines = [f"Bag:               {data['file']}"] if data['bag_folder'] else []
    if data['bag_folder'] and not data['metadata_yaml']:
        lines.append('                   (no metadata.yaml: the recorder did not finish; '
                     "'recover' rebuilds it)")
    lines += [f"{'Files:' if i == 0 else '':<19}{name}" for i, name in enumerate(names)]
    lines += [
        f"Bag size:          {_format_size(data['size'])}",
        'Storage id:        mcap',
        f"Profile:           {data['profile'] or '(none)'}   library: {data['library']}",
        f"ROS Distro:        {data['ros_distro'] or 'unknown'}",
        f"Duration:          {data['duration_s']:.9f}s",
    ]
    if data['messages']:
        lines += [f"Start:             {_format_time(data['start_ns'])}",
                  f"End:               {_format_time(data['end_ns'])}"]
    lines += [
        f"Messages:          {data['messages']}",
        f"Chunks:            {data['chunks']} ({', '.join(data['compression']) or 'none'}),"
        f" {data['chunks_verified']} verified",
    ]
    topics = data['topics']
    if topics:
        width = max(len(t['name']) for t in topics)
        for i, t in enumerate(topics):
            lead = 'Topic information: ' if i == 0 else ' ' * 19
            lines.append(f"{lead}Topic: {t['name']:<{width}} | Type: {t['type']} | "
                         f"Count: {t['count']} | Serialization Format: "
                         f"{t['serialization_format']}")
    else:
        lines.append('Topic information: (no topics)')
    if data['metadata']:
        lines.append(f"Metadata records:  {', '.join(data['metadata'])}")
    print('\n'.join(lines))
    return 0


def _recover(args: argparse.Namespace) -> int:
    from gripper_sim.recording.errors import RecordingError
    from gripper_sim.recording.recover import (iter_bag_report_lines, iter_report_lines,
                                               recover, recover_bag)

    src, dst = Path(args.input), Path(args.output)
    if src.is_dir():
        if args.force:
            raise RecordingError('--force is for a single file; a bag folder is recovered '
                                 'into a new folder only')
        lines = iter_bag_report_lines(recover_bag(src, dst), src, dst)
    else:
        lines = iter_report_lines(recover(src, dst, overwrite=args.force), src, dst)
    for line in lines:
        print(line)
    return 0


def _require_rclpy(verb: str) -> None:
    from gripper_sim.recording.errors import RecordingError
    try:
        import rclpy  # noqa: F401
    except ImportError as err:
        msg = (f"'{verb}' needs ROS 2 (rclpy), which cannot be imported here ({err}); run it "
               "in the project's environment (see Set-up). 'info', 'analyze' and 'recover' "
               'work without ROS.')
        raise RecordingError(msg) from err


def _record(args: argparse.Namespace) -> int:
    from gripper_sim.recording.errors import RecordingError

    _require_rclpy('record')
    from gripper_sim.recording.recorder import run_record

    if not args.all and not args.topics and not args.regex:
        raise RecordingError('give topics to record, --regex or --all')
    if args.max_messages is not None and args.max_messages <= 0:
        raise RecordingError('--max-messages must be positive')
    summary = run_record(args.output, topics=args.topics, all_topics=args.all,
                         regex=args.regex, exclude=args.exclude, duration=args.duration,
                         flush_interval=args.flush_interval, max_messages=args.max_messages,
                         max_bag_size=args.max_bag_size,
                         max_bag_duration=args.max_bag_duration,
                         compression=args.compression)
    print(summary, file=sys.stderr)
    return 0


def remap_table(pairs: list[tuple[str, str]]) -> dict[str, str]:
    """``{recorded topic: published topic}`` from ``--remap OLD:=NEW`` pairs.

    Raises:
        RecordingError: a topic remapped twice (the last would win unseen).
    """
    from gripper_sim.recording.errors import RecordingError

    table: dict[str, str] = {}
    for old, new in pairs:
        if old in table and table[old] != new:
            raise RecordingError(f'--remap gives {old} two names ({table[old]} and {new}); '
                                 'give one')
        table[old] = new
    return table


def _replay(args: argparse.Namespace) -> int:
    _require_rclpy('replay')
    from gripper_sim.ros.replay import run_replay

    summary = run_replay(args.file, rate=args.rate, loop=args.loop, topics=args.topics,
                         start=args.start, clock_hz=args.clock,
                         remaps=remap_table(args.remap),
                         wait_for_subscribers=args.wait_for_subscribers,
                         foxglove_port=args.foxglove)
    print(summary, file=sys.stderr)
    return 0


def default_analysis_dir(bag: str) -> Path:
    """``NAME_analysis`` beside the bag folder ``NAME``, ``FILE_analysis`` beside
    ``FILE.mcap``; a path such as ``.`` or ``bag/..`` names the folder it stands for, so
    the output never lands inside the recording."""
    path = Path(os.path.normpath(bag))
    if path.name in ('', '.', '..'):
        path = Path(os.path.abspath(bag))
    name = path.stem if path.suffix == '.mcap' and not path.is_dir() else path.name
    return path.parent / f'{name or "recording"}_analysis'


def _analyze(args: argparse.Namespace) -> int:
    from gripper_sim.cli.progress import StageProgress
    from gripper_sim.recording.analysis import analyze

    out_dir = args.output_dir
    if out_dir is None:
        out_dir = str(default_analysis_dir(args.file))
    with StageProgress('analyze', quiet=args.quiet) as progress:
        result = analyze(args.file, out_dir, namespace=args.namespace,
                         figures=not args.no_figures, html=not args.no_html,
                         progress=progress, overwrite=args.force)
    for line in result.describe():
        print(line)
    return 0
