"""The physics thread: steps back to back, paced to ``real_time_factor``, pausable.

The thread calls the node's ``step`` (apply queued commands, take one step, publish)
until stopped. Paused, it only runs queued commands. With a positive real-time factor
it waits so that sim time advances ``real_time_factor`` s per wall second; falling
further behind than ``MAX_LAG`` re-anchors the pacing instead of racing to catch up.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Callable

from gripper_sim.ros.sync import SimLock

# Falling further behind real time than this re-anchors the pacing instead of racing.
MAX_LAG = 0.25   # s of wall time
SPEED_WINDOW = 5.0   # s of wall time over which the achieved real-time factor is measured
# The physics thread waits at most this long for callbacks waiting for the lock.
LOCK_YIELD_TIMEOUT = 0.5   # s


class PhysicsLoop:
    """Runs the physics in its own thread.

    Args:
        lock: the simulation lock (a waiting callback gets it before the next step).
        step: takes one step unless paused (checked under the lock); the thread calls
            it back to back.
        run_commands: applies queued commands (under the lock) while paused.
        has_commands: whether commands are queued.
        sim_time: the current sim time, s.
        recover: called with a reason when ``step`` raised.
        logger: the node's logger.
        real_time_factor: sim s per wall s; 0 = as fast as possible.

    Attributes:
        paused: no step is taken (set it under ``lock``, then ``wake``).
        achieved_rtf: sim s per wall s over the last ``SPEED_WINDOW`` s (NaN at first).
    """

    def __init__(self, *, lock: SimLock, step: Callable[[], object],
                 run_commands: Callable[[], None], has_commands: Callable[[], bool],
                 sim_time: Callable[[], float], recover: Callable[[str], None], logger,
                 real_time_factor: float):
        self._lock = lock
        self._step = step
        self._run_commands = run_commands
        self._has_commands = has_commands
        self._sim_time = sim_time
        self._recover = recover
        self._logger = logger
        self.real_time_factor = real_time_factor
        self.paused = False
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._anchor = (time.monotonic(), sim_time())
        self._speed_window = self._anchor
        self._speed_warned = -math.inf
        self.achieved_rtf = math.nan
        self._thread = threading.Thread(target=self._run, name='physics', daemon=True)

    def start(self) -> None:
        self._thread.start()

    def wake(self) -> None:
        """Wake the thread from a pause or a pacing wait (e.g. a command arrived)."""
        self._wake.set()

    def reanchor(self) -> None:
        """Pace from now on (after a pause, a reset or a new real-time factor)."""
        self._anchor = (time.monotonic(), self._sim_time())

    def set_real_time_factor(self, factor: float) -> None:
        self.real_time_factor = factor
        self.reanchor()
        self.wake()

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def stop(self, timeout: float) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=timeout)

    def _run(self) -> None:
        while not self._stop.is_set():
            if self.paused:
                if self._has_commands():   # validated and set now; they act at the next step
                    with self._lock:
                        self._run_commands()
                self._wake.wait(0.5)
                self._wake.clear()
                continue
            # A callback waiting for the lock (reset, pause, an action) goes first.
            self._lock.yield_to_waiters(LOCK_YIELD_TIMEOUT)
            try:
                self._step()
            except Exception as err:   # never let the physics thread die silently
                self._logger.error(f'physics step raised {type(err).__name__}: {err}; '
                                   'resetting the simulation')
                self._recover(f'{type(err).__name__}: {err}')
                continue
            rtf = self.real_time_factor
            self._watch_speed(rtf)
            if rtf <= 0.0:
                continue
            wall0, sim0 = self._anchor
            delay = wall0 + (self._sim_time() - sim0) / rtf - time.monotonic()
            if delay > 0.002:
                self._wake.wait(delay)
                self._wake.clear()
            elif delay < -MAX_LAG:
                self.reanchor()

    def _watch_speed(self, rtf: float) -> None:
        """Measure the achieved real-time factor; warn when it misses the target."""
        now, sim_now = time.monotonic(), self._sim_time()
        wall0, sim0 = self._speed_window
        if now - wall0 < SPEED_WINDOW:
            return
        self._speed_window = (now, sim_now)
        if sim_now < sim0:   # reset in between
            return
        self.achieved_rtf = (sim_now - sim0) / (now - wall0)
        if 0.0 < rtf and self.achieved_rtf < 0.9 * rtf and now - self._speed_warned > 60.0:
            self._speed_warned = now
            self._logger.warning(
                f'running at {self.achieved_rtf:.2f}x real time, below real_time_factor '
                f'{rtf:g}: the physics cannot keep up (fewer nodes or a larger '
                'physics.sim.dt would)')
