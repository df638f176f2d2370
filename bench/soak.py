"""Soak benchmark of the gripper_sim node: long random use, valid and invalid.

Starts the node (default fruit, ``real_time_factor`` 0) in a subprocess on loopback
with its own domain id, and for ``--minutes`` drives it through a real rclpy client
with random jaw, force and lift commands (a third of them invalid: NaN, inf,
negative, 1e300), Grasp and GripperCommand goals (valid and invalid; some run to
their end, some are canceled, some preempted by the next), resets, pause-step-resume
(some long ``~/step`` requests interrupted by ``~/reset``) and parameter changes
(valid and out of range, tiny real-time factors and back). Prints:

- crashes: the node process ended (0 expected);
- stalls: sim time did not advance for ``--stall`` s of wall time while the node was
  meant to run, or the node reported a stall on ``/diagnostics`` (0 expected);
- the node's resident memory (RSS) after a warm-up and at the end, and the growth
  (< 5 % expected);
- the slowest answer of each service (wall time, as a client sees it) and of goal
  acceptance;
- the node's CPU time (user + system, from /proc) per second of sim time.

Run: ``nice python bench/soak.py [--minutes 10] [--seed 1]``. Exit 0 when every
expectation holds, 1 otherwise.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import sys
import time
from collections import defaultdict
from pathlib import Path

from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from std_msgs.msg import Float64

from control_msgs.action import GripperCommand
from control_msgs.msg import GripperCommand as GripperCommandMsg
from gripper_sim_interfaces.action import Grasp
from gripper_sim_interfaces.srv import Step
from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
from ros_client import SimClient, TimeoutError_  # noqa: E402  (the tests' ROS client)

INVALID = (math.nan, math.inf, -math.inf, -1.0, 1e300, -1e300)
RSS_GROWTH_LIMIT = 0.05
CLOCK_TICKS = os.sysconf('SC_CLK_TCK')


def rss_bytes(pid: int) -> int:
    with open(f'/proc/{pid}/status') as status:
        for line in status:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) * 1024
    raise RuntimeError('no VmRSS')


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (s), its threads included."""
    with open(f'/proc/{pid}/stat') as stat:
        fields = stat.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS


class Soak:
    """The random driver; ``slowest[name]`` is the slowest answer of each request (s)."""

    def __init__(self, client: SimClient, rng: random.Random, stall_after: float):
        self.client = client
        self.rng = rng
        self.stall_after = stall_after
        self.slowest: dict[str, float] = defaultdict(float)
        self.counts: dict[str, int] = defaultdict(int)
        self.paused = False
        self.pending: list = []          # accepted goal handles not yet finished
        self.stalls = 0
        self.reported_stalls = 0
        self._progress = (time.monotonic(), -1.0)
        client.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 10)

    def _on_diag(self, array: DiagnosticArray) -> None:
        for status in array.status:
            if status.name.endswith(': physics') and status.level == DiagnosticStatus.ERROR:
                self.reported_stalls += 1

    def timed(self, name: str, call):
        start = time.monotonic()
        answer = call()
        self.slowest[name] = max(self.slowest[name], time.monotonic() - start)
        self.counts[name] += 1
        return answer

    def value(self, low: float, high: float) -> float:
        if self.rng.random() < 1 / 3:
            return self.rng.choice(INVALID)
        return self.rng.uniform(low, high)

    # ------------------------------------------------------------------ actions
    def command(self) -> None:
        what, low, high = self.rng.choice([('gap', 0.0, 0.08), ('force', 0.2, 15.0),
                                           ('lift', 0.02, 0.1)])
        self.client.publishers[what].publish(Float64(data=self.value(low, high)))
        self.counts[f'{what} command'] += 1

    def goal(self) -> None:
        rng = self.rng
        if rng.random() < 0.5:
            goal = Grasp.Goal(target_force=self.value(1.0, 10.0),
                              lift_height=rng.choice([0.0, 0.01, 0.03]),
                              hold_time=rng.choice([0.0, 0.2, 3000.0]),
                              release=rng.random() < 0.3)
            server = self.client.grasp
        else:
            goal = GripperCommand.Goal(command=GripperCommandMsg(
                position=self.value(0.0, 0.08), max_effort=self.value(0.0, 12.0)))
            server = self.client.gripper_cmd
        handle = self.timed('goal acceptance', lambda: self.client.send_goal(server, goal))
        if not handle.accepted:
            return
        self._settle_pending()   # the new goal preempted them
        fate = rng.random()
        endless = isinstance(goal, Grasp.Goal) and goal.hold_time > 1.0
        if fate < 0.3 or (fate < 0.6 and endless):
            self.timed('goal cancel', lambda: self.client.cancel(handle))
        if fate < 0.6:
            self.client.result(handle, timeout=300)
        else:
            self.pending.append(handle)   # the next goal preempts it, or a reset ends it

    def reset(self) -> None:
        self.timed('~/reset', self.client.reset)
        self._settle_pending()

    def step(self) -> None:
        client = self.client
        paused = self.timed('~/pause', lambda: client.pause(True))
        self.paused = True
        if self.rng.random() < 0.2:   # a long request, interrupted by ~/reset
            future = client.step_client.call_async(Step.Request(steps=1_000_000))
            # 'paused at t = 1.234000 s': a later state comes from the requested steps
            t_paused = float(paused.message.split('t = ')[1].split()[0])
            client.spin_until(lambda: client.sim_time() > t_paused + 0.005, 60,
                              'the requested steps')
            self.timed('~/reset', client.reset)
            client.spin_until(future.done, 120, 'the interrupted ~/step')
            self._settle_pending()
        else:
            steps = self.rng.randint(1, 300)
            self.timed('~/step', lambda: client.step(steps))
        self.timed('~/pause', lambda: client.pause(False))
        self.paused = False
        self._progress = (time.monotonic(), client.sim_time())

    def parameters(self) -> None:
        rng = self.rng
        name, value = rng.choice([
            ('real_time_factor', rng.choice([0.0, 0.0, 1e-300, 1e-13, 2.0, -1.0, 1e4])),
            ('publish_rate', rng.choice([100.0, 50.0, 1000.0, 1e-310, 0.0, 1e5])),
            ('physics__contact__jaw__static_friction', rng.choice([0.5, 0.8, -1.0, 1e300])),
            ('physics__gripper__close_speed', rng.choice([0.02, 0.01, 0.0, math.inf])),
            ('max_effort', rng.choice([10.0, 1e-300, -5.0])),
        ])
        self.timed('set_parameters', lambda: self.client.set_parameters(**{name: value}))
        if name == 'real_time_factor' and value != 0.0:
            self.timed('set_parameters', lambda: self.client.set_parameters(
                real_time_factor=0.0))
        self._progress = (time.monotonic(), self.client.sim_time())

    def _settle_pending(self) -> None:
        for handle in self.pending:
            status, _ = self.client.result(handle, timeout=300)
            assert status in (GoalStatus.STATUS_ABORTED, GoalStatus.STATUS_CANCELED,
                              GoalStatus.STATUS_SUCCEEDED)
        self.pending.clear()

    def watch_progress(self) -> None:
        """Count a stall when sim time stood still for ``stall_after`` s while running."""
        now, sim = time.monotonic(), self.client.sim_time()
        since, last = self._progress
        if sim != last or self.paused:
            self._progress = (now, sim)
        elif now - since > self.stall_after:
            self.stalls += 1
            self._progress = (now, sim)

    def run_one(self) -> None:
        action = self.rng.choices(
            [self.command, self.goal, self.reset, self.step, self.parameters],
            weights=[10, 4, 1, 2, 2])[0]
        action()
        self.client.executor.spin_once(timeout_sec=0.01)
        self.watch_progress()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--minutes', type=float, default=10.0,
                        help='length of the soak, wall minutes (default 10)')
    parser.add_argument('--seed', type=int, default=1, help='random seed (default 1)')
    parser.add_argument('--stall', type=float, default=20.0,
                        help='wall s without sim progress that count as a stall')
    options = parser.parse_args()

    domain = pick_domain_id(90)
    node = node_process({'real_time_factor': 0.0}, env=ros_environment(domain)).start()
    client = SimClient(domain, name='soak_client')
    soak = Soak(client, random.Random(options.seed), options.stall)
    crashed = False
    try:
        client.wait_ready(180)
        pid = node.process.pid
        duration = options.minutes * 60.0
        start = time.monotonic()
        warm_up = min(60.0, 0.1 * duration)
        rss_start = None
        cpu_start = sim_start = None
        sim_total = 0.0
        last_sim = client.sim_time()
        while time.monotonic() - start < duration:
            if not node.running:
                crashed = True
                break
            if rss_start is None and time.monotonic() - start >= warm_up:
                rss_start = rss_bytes(pid)
                cpu_start, sim_start = cpu_seconds(pid), sim_total
            try:
                soak.run_one()
            except TimeoutError_ as err:
                print(f'no answer: {err}')
                soak.stalls += 1
            sim_now = client.sim_time()
            sim_total += max(0.0, sim_now - last_sim)   # resets start again at 0
            last_sim = sim_now
        crashed = crashed or not node.running
        rss_end = rss_bytes(pid) if not crashed else 0
        cpu_end = cpu_seconds(pid) if not crashed else math.nan
    finally:
        client.close()
        code = node.stop()
    traceback = 'Traceback' in node.log()
    growth = (rss_end - rss_start) / rss_start if rss_start else math.nan
    sim_seconds = sim_total - (sim_start or 0.0)
    print(f'soak: {options.minutes:g} min wall, seed {options.seed}, real_time_factor 0, '
          f'default fruit; {sum(soak.counts.values())} requests')
    print('  ' + ', '.join(f'{name} {count}' for name, count in sorted(soak.counts.items())))
    print(f'crashes: {int(crashed)} (node exit code {code}; traceback in its log: '
          f'{traceback})')
    print(f'stalls: {soak.stalls} seen by the client (no sim progress for {options.stall:g} '
          f's while running, or no answer), {soak.reported_stalls} reported by the node')
    print(f'node RSS: {rss_start / 2**20:.1f} MiB after {warm_up:.0f} s warm-up, '
          f'{rss_end / 2**20:.1f} MiB at the end: growth {growth:+.2%}')
    print('slowest answers (wall, as the client saw them): ' + ', '.join(
        f'{name} {seconds * 1e3:.0f} ms' for name, seconds in sorted(
            soak.slowest.items(), key=lambda item: -item[1])))
    if sim_seconds > 0:
        print(f'node CPU time (user + system) after warm-up: {cpu_end - cpu_start:.1f} s for '
              f'{sim_seconds:.1f} s of sim time ({(cpu_end - cpu_start) / sim_seconds:.2f} '
              'CPU s per sim s)')
    ok = (not crashed and not traceback and soak.stalls == 0 and soak.reported_stalls == 0
          and growth < RSS_GROWTH_LIMIT)
    print('PASS' if ok else 'FAIL')
    return 0 if ok else 1


if __name__ == '__main__':
    raise SystemExit(main())
