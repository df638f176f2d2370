"""Test-session set-up: the ROS environment, applied before anything imports rclpy.

At import (pytest imports this before any test module) this process gets the
environment of ``scripts/env.sh``: ROS from the venv's wheels, discovery on loopback
only (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, no static peers), the Fast DDS
profile ``config/fastdds_localhost.xml``, ``RMW_IMPLEMENTATION=rmw_fastrtps_cpp``, and a
``ROS_DOMAIN_ID`` of its own for the session: one no other process on this machine is
using, so parallel test runs don't see each other. Subprocesses inherit it all; the
``ros_env`` fixture gives a copy to pass as ``env=`` (e.g. with a per-test domain).
"""
from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gripper_sim.ros import process as ros_process

ROOT = Path(__file__).resolve().parent.parent
ENV_SH = ROOT / 'scripts' / 'env.sh'
ROS_KEYS = ('AMENT_PREFIX_PATH', 'RMW_IMPLEMENTATION', 'ROS_AUTOMATIC_DISCOVERY_RANGE',
            'FASTRTPS_DEFAULT_PROFILES_FILE', 'ROS_DOMAIN_ID', 'GRIPPER_SIM_ROOT',
            'GRIPPER_SIM_VENV', 'PATH')
UNSET_KEYS = ('ROS_STATIC_PEERS', 'ROS_LOCALHOST_ONLY')


def free_domain_id() -> int:
    """A domain id in 1..101 that no process on this machine is using and that this
    session has not handed out before; the search starts from our pid, so concurrent
    test sessions start far apart."""
    return ros_process.free_domain_id(os.getpid())


def pick_domain_id() -> int:
    """The session's domain: GRIPPER_SIM_TEST_DOMAIN_ID if set, else a free one."""
    requested = os.environ.get('GRIPPER_SIM_TEST_DOMAIN_ID')
    domain = int(requested) if requested else free_domain_id()
    ros_process.reserve_domain_id(domain)   # the session's throughout: never recycled
    return domain


def env_sh(domain_id: int) -> dict[str, str]:
    """The variables ``scripts/env.sh`` sets, for this interpreter's venv and this domain."""
    base = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), GRIPPER_SIM_VENV=sys.prefix)
    done = subprocess.run(['bash', '-c', 'source "$0" && env -0', str(ENV_SH)], env=base,
                          capture_output=True, check=True)
    pairs = (item.split('=', 1) for item in done.stdout.decode().split('\0') if '=' in item)
    sourced = dict(pairs)
    env = {key: sourced[key] for key in ROS_KEYS}
    if not (Path(sys.prefix) / 'share' / 'ament_index').is_dir():
        # Not the pip-wheels venv (e.g. a sourced colcon/apt install): keep its prefixes.
        env['AMENT_PREFIX_PATH'] = os.environ.get('AMENT_PREFIX_PATH', env['AMENT_PREFIX_PATH'])
    return env


SESSION_DOMAIN_ID = pick_domain_id()
SESSION_ENV = env_sh(SESSION_DOMAIN_ID)
os.environ.update(SESSION_ENV)
for _key in UNSET_KEYS:
    os.environ.pop(_key, None)
os.environ.setdefault('PYTHONUNBUFFERED', '1')


def pytest_report_header(config):
    return (f'ROS: ROS_DOMAIN_ID={SESSION_DOMAIN_ID}, ROS_AUTOMATIC_DISCOVERY_RANGE='
            f"{os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']}, FASTRTPS_DEFAULT_PROFILES_FILE="
            f"{os.environ['FASTRTPS_DEFAULT_PROFILES_FILE']}")


@pytest.fixture(scope='session', autouse=True)
def physics_kernels(request):
    """The kernels of the node's default configuration in numba's on-disk cache before
    the session's first node starts, if the session has a ``ros`` test.

    A node warms its kernels before it offers any interface
    (``compile_kernels.warm_kernels``). From the cache that takes ~0.4 s; from a cold
    cache (a fresh checkout without ``make install``) ~110 s of CPU for the default 2D
    apple, past the nodes' 120 s start-up timeouts under load. Compiled here once
    instead, under pytest's per-test timeout.
    """
    if any(item.get_closest_marker('ros') for item in request.session.items):
        from gripper_sim.configuration import load_config
        from gripper_sim.workflows.compile_kernels import warm_kernels
        warm_kernels(load_config())


@pytest.fixture(scope='session')
def new_domain_id():
    """``new_domain_id()`` -> a ROS domain id no process uses and no test got before.

    Session-scoped, so module-scoped fixtures can use it too: give each node under
    test a domain of its own, e.g.
    ``env = dict(os.environ, ROS_DOMAIN_ID=str(new_domain_id()))``.
    """
    return free_domain_id


@pytest.fixture
def ros_env() -> dict[str, str]:
    """The full environment for a ROS subprocess (a copy: change it freely).

    It carries the session's ROS_DOMAIN_ID; set another one in the copy to isolate a
    test's processes from the rest of the session.
    """
    env = dict(os.environ)
    for key in UNSET_KEYS:
        env.pop(key, None)
    return env


@contextlib.contextmanager
def _node_and_client(parameters: dict, domain_id: int, log_path, client_name: str | None = None,
                     cwd=None, timeout: float = 120.0, extra=(), node_path='/gripper_sim'):
    """The gripper_sim node in a subprocess and a ``SimClient`` that has seen it ready.

    Args:
        parameters: the node's ``-p name:=value`` parameters.
        domain_id: ROS domain of the node and the client.
        log_path: the node's log file.
        client_name: the client's node name (default ``SimClient``'s).
        cwd: working directory the node starts in (default this process's).
        timeout: seconds for the node to come up.
        extra: more ``--ros-args`` arguments (e.g. ``['-r', '__ns:=/a']``).
        node_path: the node's full name, as the client addresses it.

    Yields:
        (process, client). On exit the client closes and the node stops; it must have
        exited with code 0 and no traceback in its log.
    """
    from gripper_sim.ros.process import node_process, ros_environment
    from ros_client import SimClient
    process = node_process(parameters, env=ros_environment(domain_id), log_path=log_path,
                           extra=extra)
    here = os.getcwd()
    if cwd is not None:
        os.chdir(cwd)   # the child inherits it
    try:
        process.start()
    finally:
        os.chdir(here)
    client = (SimClient(domain_id, node_path) if client_name is None
              else SimClient(domain_id, node_path, name=client_name))
    try:
        client.wait_ready(timeout=timeout)
        yield process, client
    finally:
        client.close()
        code = process.stop()
        text = process.log()
        assert 'Traceback' not in text, text
        assert code == 0, text


@pytest.fixture(scope='session')
def node_and_client():
    """``with node_and_client(parameters, domain_id, log_path, ...) as (process, client)``:
    a node subprocess and a ready client for module-scoped fixtures (see
    ``_node_and_client`` for the arguments and the checks on exit)."""
    return _node_and_client


@pytest.fixture(scope='session')
def restarted():
    """``restarted(running)`` -> the client of a module's ``(process, client)``, after
    checking the node still runs and resetting it while paused (a fast node would
    otherwise have moved on, and its reset state dropped from the history, before the
    client sees it); then running again."""
    def restart(process_and_client):
        process, client = process_and_client
        assert process.running, process.log()
        client.restart()
        return client
    return restart
