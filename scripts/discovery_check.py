"""Time for two ROS processes on loopback to discover each other (publisher/subscriber).

Starts a subscriber process, waits ``delay`` seconds, starts a publisher process, and
reports the time from the later of the two nodes' creation until both see each other
(``get_subscription_count`` / ``get_publisher_count``). Runs with the environment of
``scripts/env.sh`` (LOCALHOST range, own domain id), once with the project's Fast DDS
profile and, with ``--compare``, once without it.

    python scripts/discovery_check.py [--delays 0.5 1.5 3.2] [--repeat 2] [--compare]

Used by ``make bench``; it is how config/fastdds_localhost.xml was measured.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

TOPIC = 'gripper_sim_discovery_check'


def child(role: str) -> int:
    """One side: create the entity, wait to be matched, print times, wait for stdin EOF."""
    import rclpy
    from std_msgs.msg import Empty
    rclpy.init()
    node = rclpy.create_node(f'discovery_check_{role}')
    if role == 'pub':
        entity = node.create_publisher(Empty, TOPIC, 10)
        count = entity.get_subscription_count
    else:
        entity = node.create_subscription(Empty, TOPIC, lambda _msg: None, 10)
        count = entity.get_publisher_count
    created = time.time()
    deadline = time.monotonic() + 20.0
    while count() == 0 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.005)
    print(f'{created:.4f} {time.time():.4f} {int(count() > 0)}', flush=True)
    sys.stdin.read()
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def measure(delay: float, env: dict[str, str]) -> tuple[float, bool]:
    """Seconds from the later node's creation to both sides matched; and whether both did."""
    def start(role: str) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, __file__, '--child', role], env=env,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    first = start('sub')
    time.sleep(delay)  # the point of the measurement: a participant joining a later one
    second = start('pub')
    lines = [process.stdout.readline().split() for process in (first, second)]
    for process in (first, second):
        process.stdin.close()
        process.wait(timeout=30)
    if not all(len(line) == 3 for line in lines):
        return float('nan'), False
    created = max(float(line[0]) for line in lines)
    matched = max(float(line[1]) for line in lines)
    return matched - created, all(line[2] == '1' for line in lines)


def run(label: str, env: dict[str, str], delays: list[float], repeat: int) -> bool:
    times, all_ok = [], True
    print(f'{label}:', end=' ', flush=True)
    for delay in delays * repeat:
        seconds, ok = measure(delay, env)
        times.append(seconds)
        all_ok &= ok
        print(f'{seconds:.3f}{"" if ok else "(no match)"}', end=' ', flush=True)
    print(f'\n  median {statistics.median(times):.3f} s, max {max(times):.3f} s over '
          f'{len(times)} runs', flush=True)
    return all_ok


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--delays', type=float, nargs='+', default=[0.5, 1.5, 3.2],
                        help='seconds between starting the subscriber and the publisher')
    parser.add_argument('--repeat', type=int, default=2)
    parser.add_argument('--compare', action='store_true',
                        help='also measure without the Fast DDS profile')
    parser.add_argument('--child', choices=('pub', 'sub'), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child)
    env = dict(os.environ)
    for key in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTRTPS_DEFAULT_PROFILES_FILE',
                'ROS_DOMAIN_ID'):
        if key not in env:
            print(f'error: {key} is not set: source scripts/env.sh first', file=sys.stderr)
            return 2
    print(f'discovery on loopback, ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]}, sub then pub '
          f'after {args.delays} s')
    ok = run('with the Fast DDS profile', env, args.delays, args.repeat)
    if args.compare:
        bare = {k: v for k, v in env.items() if k != 'FASTRTPS_DEFAULT_PROFILES_FILE'}
        ok &= run('without it (Fast DDS defaults)', bare, args.delays, args.repeat)
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
