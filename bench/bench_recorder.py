"""Benchmark of the recorder on the node's full-rate output. Prints figures; asserts nothing.

Three measurements:

1. ``writer``: BagWriter alone (no ROS graph) writing the node's seven topics for every
   physics step (the in-node / offline recording path): messages/s, MB/s, and the file
   size per simulated second at full physics rate (1 / dt).
2. ``live``: the raw recorder (a ``gripper-sim record`` subprocess) recording a
   publisher subprocess that publishes the node's seven topics (pre-serialized, raw) at
   ``--steps-per-second`` steps/s: sustained messages/s, MB/s, and messages dropped.
   ``--steps-per-second 0`` publishes as fast as the publisher can.
3. ``node``: the real ``gripper_sim`` node at ``publish_rate = 1 / dt`` and
   ``real_time_factor = 0`` (every step published as fast as physics runs), recorded with
   ``--all``: steps the node published vs steps in the file (by /clock stamps).

Every ROS process runs with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and its own
ROS_DOMAIN_ID. Usage::

    python bench/bench_recorder.py [writer|live|node|all] [--seconds S]
        [--steps-per-second N]
"""
from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def synthetic_result(step: int, dt: float, n_nodes: int = 64):
    """A StepResult like the default 2D fruit's (64 skin nodes) in a grip."""
    from gripper_sim.core.results import Deformation, Energies, JawWrench, StepResult

    angles = np.linspace(0.0, 2 * np.pi, n_nodes, endpoint=False)
    r = 0.03175
    wobble = 1e-4 * np.sin(step * 0.01)
    positions = np.column_stack([(r - wobble) * np.cos(angles), 0.032 + r * np.sin(angles)])
    forces = np.zeros((n_nodes, 2))
    obstacle = np.full(n_nodes, -1)
    for k in (-1, 0, 1):
        forces[k % n_nodes] = (-1.0, 0.05)
        forces[n_nodes // 2 + k] = (1.0, 0.05)
        obstacle[k % n_nodes], obstacle[n_nodes // 2 + k] = 1, 0
    pressure = np.where(obstacle >= 0, 1.2e5, 0.0)
    return StepResult(
        time=step * dt, step=step, positions=positions, velocities=np.zeros((n_nodes, 2)),
        contact_forces=forces, contact_obstacle=obstacle, contact_sticking=obstacle >= 0,
        obstacle_names=('left_jaw', 'right_jaw', 'table'), surface=np.arange(n_nodes),
        left_wrench=JawWrench(np.array([-3.0, 0.0, -0.1]), np.zeros(3)),
        right_wrench=JawWrench(np.array([3.0, 0.0, -0.1]), np.zeros(3)),
        left_jaw_x=-r + wobble, right_jaw_x=r - wobble, jaw_velocity=0.0, lift=0.032,
        lift_velocity=0.0, gap=2 * (r - wobble), grip_force=3.0, slip_distance=0.0,
        slipping=False, centroid=np.array([0.0, 0.032]),
        energies=Energies(1e-6, 2e-3, 0.03),
        deformation=Deformation(2 * wobble, wobble / r, 0.01, 0.004, 1.2e5, pressure),
        newton_iterations=3, substeps=1)


def full_rate_batch(step: int, dt: float) -> dict[str, bytes]:
    """The node's seven messages for one step, serialized: {topic name: CDR}."""
    from rclpy.serialization import serialize_message

    from gripper_sim.configuration import load_config
    from gripper_sim.convert import messages

    batch = messages.build_messages(synthetic_result(step, dt), load_config())
    return {messages.resolved_topic(s): serialize_message(m) for s, m in batch.items()}


def real_run(sim_seconds: float):
    """Results of a real simulation (default apple, force grip then lift), every step."""
    from gripper_sim.configuration import load_config
    from gripper_sim.core.simulation import Simulation

    sim = Simulation(load_config())
    results = [sim.last]
    sim.command_force(8.0)
    while sim.time < sim_seconds / 2:
        results.append(sim.step())
    sim.command_lift(0.08)
    while sim.time < sim_seconds:
        results.append(sim.step())
    return sim, results


def bench_writer(seconds: float, sim_seconds: float) -> None:
    from rclpy.serialization import serialize_message

    from gripper_sim.recording.offline import SimRecorder
    from gripper_sim.recording.reader import BagReader
    from gripper_sim.recording.writer import BagWriter
    from gripper_sim.convert import messages

    wall = time.perf_counter()
    sim, results = real_run(sim_seconds)
    physics = (time.perf_counter() - wall) / len(results)
    dt = sim.dt
    context = messages.MessageContext.from_config(sim.config, initial=results[0])
    batches = []
    for r in results:
        batch = messages.build_messages(r, context)
        batches.append({messages.resolved_topic(k): serialize_message(m)
                        for k, m in batch.items()})
    with tempfile.TemporaryDirectory() as tmp:
        # 1. the whole in-node / offline path on a real run: convert, serialize, write
        path = Path(tmp) / 'sim.mcap'
        start = time.perf_counter()
        with SimRecorder(path, sim.config, initial=results[0]) as rec:
            for r in results[1:]:
                rec.on_step(r)
        elapsed = time.perf_counter() - start
        size = path.stat().st_size
        n = len(results)
        payload = sum(len(d) for b in batches for d in b.values())
        print(f'[writer] real run: {results[-1].time:.2f} s of sim time, {n} steps at dt = '
              f'{dt * 1e3:g} ms, physics {physics * 1e3:.2f} ms per step')
        print(f'[writer]   SimRecorder (build_messages + serialize + write, every step): '
              f'{1e3 * elapsed / n:.2f} ms per step = {n / elapsed:,.0f} steps/s')
        print(f'[writer]   file size per simulated second at full physics rate '
              f'({1 / dt:.0f} steps/s, 7 topics): {size / results[-1].time / 1e6:.2f} MB '
              f'(payload {payload / results[-1].time / 1e6:.2f} MB, zstd chunks '
              f'{size / payload:.2f} of it)')

        # 2. BagWriter alone on the pre-serialized full-rate output
        path = Path(tmp) / 'writer.mcap'
        steps = 0
        payload = 0
        with BagWriter(path) as bag:
            for suffix, (_, type_name) in messages.TOPICS.items():
                bag.add_topic(messages.resolved_topic(suffix), type_name)
            start = time.perf_counter()
            while time.perf_counter() - start < seconds:
                t = steps * int(dt * 1e9)
                for topic, data in batches[steps % len(batches)].items():
                    bag.write(topic, data, log_time=t)
                    payload += len(data)
                steps += 1
            elapsed = time.perf_counter() - start
        with BagReader(path) as bag:
            assert bag.message_count == steps * len(batches[0])
        print(f'[writer]   BagWriter alone, pre-serialized: '
              f'{steps * len(batches[0]) / elapsed:,.0f} messages/s, '
              f'{payload / elapsed / 1e6:.1f} MB/s, {steps / elapsed:,.0f} steps/s')


def _env(domain: int) -> dict[str, str]:
    from gripper_sim.ros.process import ros_environment
    return ros_environment(domain)


def publisher_main(args: argparse.Namespace) -> None:
    """Subprocess: publish the full-rate batch ``steps`` times at ``rate`` steps/s."""
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from gripper_sim.recording.recorder import import_message_class
    from gripper_sim.convert import messages

    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    dt = 1e-3
    batch = full_rate_batch(1, dt)
    types = {messages.resolved_topic(s): t for s, (_, t) in messages.TOPICS.items()}
    pubs = {topic: node.create_publisher(import_message_class(types[topic]), topic, qos)
            for topic in batch}
    deadline = time.monotonic() + 60
    while not all(p.get_subscription_count() for p in pubs.values()):
        if time.monotonic() > deadline:
            print('no subscriber', flush=True)
            return
        time.sleep(0.02)
    time.sleep(0.5)
    rate = args.steps_per_second
    start = time.monotonic()
    step = 0
    while time.monotonic() - start < args.seconds:
        for topic, data in batch.items():
            pubs[topic].publish(data)
        step += 1
        if rate > 0:
            delay = start + step / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    elapsed = time.monotonic() - start
    from rclpy.duration import Duration
    for p in pubs.values():
        p.wait_for_all_acked(Duration(seconds=10))
    print(f'published {step * len(batch)} {elapsed:.3f}', flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def bench_live(seconds: float, steps_per_second: float) -> None:
    from gripper_sim.recording.reader import BagReader
    from gripper_sim.ros.process import pick_domain_id

    domain = pick_domain_id()
    env = _env(domain)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / 'live.mcap'
        from gripper_sim.convert import messages
        topics = [messages.resolved_topic(s) for s in messages.TOPICS]
        rec = subprocess.Popen([sys.executable, '-m', 'gripper_sim.cli.main', 'record', '-o',
                                str(out), *topics], env=env, stderr=subprocess.PIPE,
                               stdout=subprocess.DEVNULL, cwd=ROOT)
        pub = subprocess.run([sys.executable, __file__, 'publish', '--seconds', str(seconds),
                              '--steps-per-second', str(steps_per_second)], env=env,
                             capture_output=True, text=True, cwd=ROOT, timeout=600)
        rec.send_signal(signal.SIGINT)
        _, err = rec.communicate(timeout=120)
        line = [ln for ln in pub.stdout.splitlines() if ln.startswith('published')]
        if not line:
            print(f'[live] publisher failed: {pub.stdout} {pub.stderr[-2000:]}')
            return
        published, pub_elapsed = int(line[0].split()[1]), float(line[0].split()[2])
        with BagReader(out) as bag:
            recorded = bag.message_count
            duration = bag.duration_ns / 1e9
            payload = sum(len(m.data) for m in bag.messages())
        size = out.stat().st_size
    target = 'as fast as possible' if steps_per_second <= 0 else \
        f'{steps_per_second:g} steps/s target'
    print(f'[live] raw recorder subprocess vs publisher subprocess, 7 topics/step, {target}')
    print(f'[live]   published {published:,} messages in {pub_elapsed:.2f} s '
          f'({published / pub_elapsed:,.0f} msg/s, {published / 7 / pub_elapsed:,.0f} steps/s)')
    print(f'[live]   recorded  {recorded:,} messages over {duration:.2f} s: '
          f'{recorded / max(duration, 1e-9):,.0f} msg/s, '
          f'{payload / max(duration, 1e-9) / 1e6:.2f} MB/s; dropped {published - recorded:,} '
          f'({100.0 * (published - recorded) / max(published, 1):.2f} %)')
    print(f'[live]   file {size / 1e6:.2f} MB ({size / max(payload, 1):.2f} of payload)')


def bench_node(seconds: float) -> None:
    from gripper_sim.recording.reader import BagReader
    from gripper_sim.ros.process import node_process, pick_domain_id

    domain = pick_domain_id()
    env = _env(domain)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / 'node.mcap'
        node = node_process({'publish_rate': 1000.0, 'real_time_factor': 0.0}, env=env,
                            log_path=Path(tmp) / 'node.log')
        node.start()
        try:
            if not node.wait_for_log('ready', timeout=120):
                print(f'[node] the node did not start: {node.log()[-2000:]}')
                return
            rec = subprocess.Popen([sys.executable, '-m', 'gripper_sim.cli.main', 'record',
                                    '--all', '--duration', str(seconds), '-o', str(out)],
                                   env=env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                   cwd=ROOT)
            _, err = rec.communicate(timeout=seconds + 120)
        finally:
            node.stop()
        with BagReader(out) as bag:
            counts = {t: i.message_count for t, i in bag.topics.items()}
            stamps = []
            for _raw, msg in bag.decoded_messages(['/gripper_sim/fruit/state']):
                stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            total = bag.message_count
            duration = bag.duration_ns / 1e9
            payload = sum(len(m.data) for m in bag.messages())
    if len(stamps) < 2:
        print(f'[node] too few FruitState messages recorded: {counts}')
        return
    steps = np.diff(np.asarray(stamps))
    dt = float(np.median(steps))
    expected = int(round((stamps[-1] - stamps[0]) / dt)) + 1
    print('[node] gripper_sim node, publish_rate 1000 Hz, real_time_factor 0, record --all')
    print(f'[node]   recorded {total:,} messages on {len(counts)} topics in {duration:.2f} s '
          f'({total / max(duration, 1e-9):,.0f} msg/s, {payload / max(duration, 1e-9) / 1e6:.2f}'
          ' MB/s)')
    print(f'[node]   FruitState: {len(stamps):,} of {expected:,} steps between the first and '
          f'last recorded (missing {expected - len(stamps)}); sim dt {dt / 1e6:g} ms, '
          f'{(stamps[-1] - stamps[0]) / 1e9 / max(duration, 1e-9):.2f}x real time')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('what', nargs='?', default='all',
                        choices=['all', 'writer', 'live', 'node', 'publish'])
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--steps-per-second', type=float, default=1000.0)
    parser.add_argument('--sim-seconds', type=float, default=0.6,
                        help='simulated seconds of the real run used by "writer"')
    args = parser.parse_args()
    if args.what == 'publish':
        publisher_main(args)
        return
    if args.what in ('all', 'writer'):
        bench_writer(args.seconds, args.sim_seconds)
    if args.what in ('all', 'live'):
        bench_live(args.seconds, args.steps_per_second)
        if args.what == 'all':
            bench_live(args.seconds, 0.0)
    if args.what in ('all', 'node'):
        bench_node(args.seconds)


if __name__ == '__main__':
    main()
