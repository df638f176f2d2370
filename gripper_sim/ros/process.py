"""Start the ``gripper_sim`` node (or the controller) in a subprocess, on loopback only.

Used by the demo, the benchmark and the integration tests: every process gets
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, its own ``ROS_DOMAIN_ID`` and a Fast DDS
profile with frequent initial announcements (fast, reliable discovery on loopback).
No rclpy import here.
"""
from __future__ import annotations

import fcntl
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterable, Mapping

# Initial announcements every 100 ms, 30 times: discovery in 0.25-0.5 s on loopback.
FASTDDS_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="gripper_sim_loopback" is_default_profile="true">
    <rtps>
      <builtin>
        <discovery_config>
          <initialAnnouncements>
            <count>30</count>
            <period><sec>0</sec><nanosec>100000000</nanosec></period>
          </initialAnnouncements>
        </discovery_config>
      </builtin>
    </rtps>
  </participant>
</profiles>
"""


def fastdds_profile() -> str:
    """Path of the loopback discovery profile (written once per user to a temp dir)."""
    path = Path(tempfile.gettempdir()) / f'gripper_sim_fastdds_{os.getuid()}.xml'
    if not path.is_file() or path.read_text() != FASTDDS_PROFILE:
        tmp = path.with_suffix(f'.{os.getpid()}.tmp')
        tmp.write_text(FASTDDS_PROFILE)
        tmp.replace(path)
    return str(path)


DOMAIN_IDS = range(1, 102)
#: the domains this process handed out, the oldest first (``free_domain_id``)
_handed_out: dict[int, None] = {}
#: domains this process never hands out (``reserve_domain_id``)
_reserved: set[int] = set()
#: the lock files this process holds, one per domain among the last it handed out
#: (``_claim``), the oldest first
_claims: dict[int, int] = {}
#: how many of the domains it handed out last a process keeps claimed: a claim guards a
#: domain between its pick and its node's first port; a test session hands out about as
#: many domains as there are, and claims it kept on all of them would leave none to
#: another run of ours (the demo, another session) nor to its own next pick
KEPT_CLAIMS = 8


def domain_in_use(domain_id: int, participants: int = 4) -> bool:
    """Whether a DDS participant of this machine holds a unicast port of ``domain_id``.

    RTPS ports: 7400 + 250 * domain + 10 + 2 * participant (+1 for user traffic).
    """
    base = 7400 + 250 * domain_id + 10
    for port in range(base, base + 2 * participants):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(('127.0.0.1', port))
            except OSError:
                return True
    return False


def _claims_folder() -> Path:
    folder = Path(tempfile.gettempdir()) / f'gripper_sim_domains_{os.getuid()}'
    folder.mkdir(mode=0o700, exist_ok=True)
    return folder


def _claim(domain_id: int) -> bool:
    """Take ``domain_id`` for this process until it exits: an exclusive lock on its file
    in ``_claims_folder``, which another process of ours handing out domains (a test
    session, the demo, the benchmark) then skips. Between its pick and its node's first
    port a domain shows no use, so two concurrent runs could otherwise pick the same
    one. False if another process holds it (``free_domain_id`` never asks twice: a
    claimed domain is handed out)."""
    handle = os.open(_claims_folder() / f'{domain_id}.lock', os.O_RDWR | os.O_CREAT, 0o600)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(handle)
        return False
    _claims[domain_id] = handle
    while len(_claims) > KEPT_CLAIMS:
        os.close(_claims.pop(next(iter(_claims))))
    return True


def free_domain_id(start: int) -> int:
    """A domain id in 1..101 that no process on this machine uses, that no other process
    of ours has claimed (``_claim``) and that this process has not handed out before,
    searched from ``start`` (modulo 101); once this process has handed out every free
    one, the one it handed out longest ago that is free again (``_recycled``)."""
    for offset in range(len(DOMAIN_IDS)):
        candidate = DOMAIN_IDS[(start + offset) % len(DOMAIN_IDS)]
        if candidate not in _handed_out and _taken_now(candidate):
            break
    else:
        candidate = _recycled(start)
    _handed_out.pop(candidate, None)
    _handed_out[candidate] = None
    return candidate


def _recycled(start: int) -> int:
    """The domain this process handed out longest ago that no process uses now and no
    process of ours claims (``free_domain_id`` found none it had not handed out), claimed
    again; ``DOMAIN_IDS[start % 101]`` if there is none."""
    for candidate in list(_handed_out):
        if candidate not in _claims and _taken_now(candidate):
            return candidate
    return DOMAIN_IDS[start % len(DOMAIN_IDS)]


def _taken_now(domain_id: int) -> bool:
    """Whether ``domain_id`` is not reserved, no process uses it, and this process has
    just claimed it (``_claim``)."""
    return (domain_id not in _reserved and not domain_in_use(domain_id)
            and _claim(domain_id))


def reserve_domain_id(domain_id: int) -> None:
    """Never hand out ``domain_id`` (it is taken, e.g. by a session set by hand)."""
    _reserved.add(domain_id)


def pick_domain_id(offset: int = 0) -> int:
    """A free domain id (``free_domain_id``), searched from the process id + ``offset``:
    concurrent runs start far apart, and a node of another run is never a namesake."""
    return free_domain_id(os.getpid() + offset)


def ros_environment(domain_id: int | None = None,
                    base: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for ROS processes: loopback discovery, own domain, Fast DDS profile."""
    env = dict(os.environ if base is None else base)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(domain_id)
    elif 'ROS_DOMAIN_ID' not in env:
        env['ROS_DOMAIN_ID'] = str(pick_domain_id())
    env.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    env.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', fastdds_profile())
    env['PYTHONUNBUFFERED'] = '1'
    # A process that hangs on stop gets SIGABRT before SIGKILL: its log then shows where
    # every thread was (faulthandler).
    env.setdefault('PYTHONFAULTHANDLER', '1')
    return env


def apply_ros_environment(domain_id: int | None = None) -> dict[str, str]:
    """Set ``ros_environment`` in this process (before ``rclpy.init``); returns it."""
    env = ros_environment(domain_id)
    for key in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID', 'RMW_IMPLEMENTATION',
                'FASTRTPS_DEFAULT_PROFILES_FILE'):
        os.environ[key] = env[key]
    return env


class RosProcess:
    """A ROS process (``python -m module ...``) with its output in a log file.

    Args:
        module: Python module to run with ``-m``.
        args: its arguments (e.g. ``['--ros-args', '-p', 'real_time_factor:=0.0']``).
        env: environment (default ``ros_environment()``).
        log_path: where stdout and stderr go (default a temp file).
    """

    def __init__(self, module: str, args: Iterable[str] = (), env: Mapping[str, str] | None = None,
                 log_path: str | os.PathLike | None = None):
        self.command = [sys.executable, '-m', module, *args]
        self.env = dict(env) if env is not None else ros_environment()
        if log_path is None:
            handle, log_path = tempfile.mkstemp(prefix='gripper_sim_', suffix='.log')
            os.close(handle)
        self.log_path = Path(log_path)
        self.process: subprocess.Popen | None = None

    def start(self) -> 'RosProcess':
        log = open(self.log_path, 'wb')
        try:
            self.process = subprocess.Popen(self.command, env=self.env, stdout=log,
                                            stderr=subprocess.STDOUT,
                                            stdin=subprocess.DEVNULL)
        finally:
            log.close()
        return self

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors='replace')
        except OSError:
            return ''

    def wait_for_log(self, text: str, timeout: float = 60.0) -> bool:
        """Wait until ``text`` appears in the output (or the process ends)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.log():
                return True
            if self.process is None or self.process.poll() is not None:
                return text in self.log()
            time.sleep(0.05)
        return False

    @property
    def running(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def stop(self, timeout: float = 20.0) -> int | None:
        """SIGINT (a clean ROS shutdown), then SIGTERM, SIGABRT, SIGKILL if it hangs.

        SIGABRT makes a Python process started with ``ros_environment()`` write the
        traceback of every thread to its log (``PYTHONFAULTHANDLER``) before it goes.
        """
        if self.process is None:
            return None
        if self.process.poll() is None:
            for signum, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 5.0),
                                 (signal.SIGABRT, 5.0), (signal.SIGKILL, None)):
                self.process.send_signal(signum)
                try:
                    self.process.wait(wait)
                    break
                except subprocess.TimeoutExpired:
                    continue
        return self.process.returncode

    def __enter__(self) -> 'RosProcess':
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def node_process(parameters: Mapping[str, object] | None = None, *, fruit: str | None = None,
                 env: Mapping[str, str] | None = None, log_path=None,
                 extra: Iterable[str] = ()) -> RosProcess:
    """A ``gripper_sim`` node process with ``-p name:=value`` for each parameter.

    The Foxglove live view is off (``foxglove_port`` 0) unless ``parameters`` set it:
    tests and benchmarks start many nodes at once, which would all ask for its port.
    """
    parameters = {'foxglove_port': 0, **(parameters or {})}
    args: list[str] = []
    if fruit:
        args += ['--fruit', fruit]
    ros_args = list(extra)
    for name, value in parameters.items():
        if isinstance(value, bool):
            value = 'true' if value else 'false'
        ros_args += ['-p', f'{name}:={value}']
    if ros_args:
        args += ['--ros-args', *ros_args]
    return RosProcess('gripper_sim.ros.node', args, env=env, log_path=log_path)


def controller_process(args: Iterable[str] = (), env: Mapping[str, str] | None = None,
                       log_path=None) -> RosProcess:
    """An example force controller process (``gripper-sim controller`` arguments)."""
    return RosProcess('gripper_sim.ros.controller', list(args), env=env, log_path=log_path)
