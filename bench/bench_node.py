"""Benchmark of the gripper_sim node: real-time factor, publish rate, command latency.

Starts the node (default fruit) in a subprocess on loopback with its own domain id and
measures, through a real rclpy client subscribed to every topic:

1. the bare core's speed (Simulation.step in this process, no ROS) for reference;
2. the achieved real-time factor at real_time_factor 0 (as fast as possible) and 1;
3. the achieved publish rate of ~/fruit/state (wall Hz and sim-time Hz) at 1;
4. the latency from publishing a jaw gap command to the first changed jaw wrench
   received (wall ms, and in sim time), jaws closed on the fruit.

Run: ``python bench/bench_node.py [--seconds 5] [--samples 10]``. Prints figures only.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

#: the tests' directory, whose ROS client (test/ros_client.py) the benchmark drives the node with
TEST_DIR = Path(__file__).resolve().parents[1] / 'test'


def core_speed(seconds: float) -> float:
    from gripper_sim.configuration import load_config
    from gripper_sim.core.simulation import Simulation
    sim = Simulation(load_config())
    sim.command_force(5.0)
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        sim.step()
    return sim.time / (time.perf_counter() - start)


def measure_rate(client, seconds: float) -> tuple[float, float, float]:
    """(real-time factor, state messages per wall s, per sim s) over ``seconds``."""
    client.wait_sim_time(0.02)
    count0, sim0, wall0 = client.counts['fruit/state'], client.sim_time(), time.monotonic()
    client.spin_until(lambda: time.monotonic() - wall0 >= seconds, seconds + 60)
    wall = time.monotonic() - wall0
    sim = client.sim_time() - sim0
    count = client.counts['fruit/state'] - count0
    return sim / wall, count / wall, count / sim if sim > 0 else float('nan')


def latency(client, samples: int) -> tuple[list[float], list[float]]:
    """Wall and sim-time delays from a gap command to the first changed wrench."""
    client.publish('force', 5.0)
    client.spin_until(lambda: abs(client.latest['fruit/state'].grip_force - 5.0) < 0.05, 60,
                      'a 5 N grip')
    walls, sims = [], []
    for i in range(samples):
        client.wait_sim_time(0.1)
        before = client.latest['left_jaw/wrench']
        reference = before.wrench.force.x
        stamp0 = before.header.stamp.sec + before.header.stamp.nanosec * 1e-9
        gap = client.latest['fruit/state'].gap + (-0.0005 if i % 2 == 0 else 0.0005)
        t0 = time.monotonic()
        client.publishers['gap'].publish(__import__('std_msgs.msg').msg.Float64(data=gap))

        def changed():
            msg = client.latest['left_jaw/wrench']
            return abs(msg.wrench.force.x - reference) > 1e-3 and msg
        msg = client.spin_until(changed, 30, 'a changed wrench')
        walls.append((time.monotonic() - t0) * 1e3)
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        sims.append((stamp - stamp0) * 1e3)
    return walls, sims


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=5.0, help='wall s per rate figure')
    parser.add_argument('--samples', type=int, default=10, help='latency samples')
    options = parser.parse_args()

    from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment
    sys.path.insert(0, str(TEST_DIR))   # the tests' ROS client (test/ros_client.py)
    from ros_client import SimClient

    print(f'core alone (no ROS, default fruit, force mode): real-time factor '
          f'{core_speed(options.seconds):.2f}')
    domain = pick_domain_id(50)
    node = node_process({'real_time_factor': 0.0}, env=ros_environment(domain)).start()
    client = SimClient(domain, name='bench_client')
    try:
        client.wait_ready(120)
        client.publish('force', 5.0)
        rtf, hz, sim_hz = measure_rate(client, options.seconds)
        missed = ('' if sim_hz > 99.0 else
                  ' received of the 100 published: this client, subscribed to every topic, '
                  'reads fewer than the node sends and its depth-10 history drops the rest')
        print(f'node, real_time_factor 0 (as fast as possible), all topics subscribed: '
              f'real-time factor {rtf:.2f}, state {hz:.0f} msg/s wall ({sim_hz:.0f} per sim s'
              f'{missed})')
        ok, = client.set_parameters(real_time_factor=1.0)
        assert ok.successful, ok.reason
        client.restart()   # paused around the reset: the t = 0 state is seen on every topic
        client.publish('force', 5.0)
        rtf, hz, sim_hz = measure_rate(client, options.seconds)
        print(f'node, real_time_factor 1 (target 1.00), publish_rate 100: real-time factor '
              f'{rtf:.2f}, state {hz:.1f} msg/s wall ({sim_hz:.1f} per sim s)')
        walls, sims = latency(client, options.samples)
        print(f'jaw gap command -> first changed wrench ({options.samples} samples, '
              f'real_time_factor 1): wall median {statistics.median(walls):.1f} ms, max '
              f'{max(walls):.1f} ms; sim time median {statistics.median(sims):.1f} ms, max '
              f'{max(sims):.1f} ms (publish period 10 ms)')
    finally:
        client.close()
        node.stop()


if __name__ == '__main__':
    main()
