"""The physics thread: steps back to back, paced to ``real_time_factor``, pausable.

The thread calls the node's ``step`` (apply queued commands, take one step, publish)
until stopped. Paused, it runs queued commands and the steps a ``~/step`` request
asked for (``request_steps``), one at a time, so ``~/pause`` and ``~/reset`` can stop
such a request between two steps. With a positive real-time factor it waits so that
sim time advances ``real_time_factor`` s per wall second, in waits of at most
``MAX_WAIT`` (any factor in the declared range works, and a new factor acts at once);
falling further behind than ``MAX_LAG`` re-anchors the pacing instead of racing.

No exception ends the thread: it is logged, the simulation is reset, the loop goes
on. ``heartbeat`` tells a watchdog when the loop last made progress.
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
# Longest single wait (pacing, pause): the loop then checks for news and beats.
MAX_WAIT = 0.5   # s of wall time
# Shorter pacing waits than this are not worth a wait: the step is taken at once.
MIN_WAIT = 0.002   # s of wall time
# Stepping back to back, the thread sleeps SHARE_PAUSE every SHARE_PERIOD of wall time.
# CPython hands the GIL over only when its holder is idle or after a switch interval,
# and a holder that releases and retakes it at every publish starves the other threads:
# a parameter change or a service call (each logs, which reads files) took 3-8 s at
# real_time_factor 0 with every topic built each step; with the pause, milliseconds.
SHARE_PERIOD = 0.02   # s of wall time
SHARE_PAUSE = 0.001   # s of wall time (5 % of the time, and a wait, not CPU)


def pacing_delay(ahead: float, factor: float) -> float:
    """Wall s to wait, at most ``MAX_WAIT``, when sim time is ``ahead`` s ahead of a
    schedule of ``factor`` sim s per wall s (> 0). Never overflows: ``ahead / factor``
    is only computed when it is below ``MAX_WAIT``."""
    if ahead <= 0.0:
        return 0.0
    if ahead >= factor * MAX_WAIT:
        return MAX_WAIT
    return ahead / factor


class StepRequest:
    """A ``~/step`` request: ``steps`` steps taken by the physics thread while paused.

    Attributes:
        taken: steps taken so far.
        stopped_by: why it ended early (``interrupt``, a failed step), or None.
        done: set when it ended (all steps taken, or stopped).
    """

    def __init__(self, steps: int):
        self.steps = steps
        self.taken = 0
        self.stopped_by: str | None = None
        self.done = threading.Event()

    def finish(self, stopped_by: str | None = None) -> None:
        if not self.done.is_set():
            self.stopped_by = stopped_by
            self.done.set()


class PhysicsLoop:
    """Runs the physics in its own thread.

    Args:
        lock: the simulation lock (a waiting callback gets it before the next step).
        step: takes one step unless paused (checked under the lock); returns None if
            the step failed or none was taken.
        force_step: takes one step even while paused (``~/step``); None if it failed.
        run_commands: applies queued commands (under the lock) while paused.
        has_commands: whether commands are queued.
        sim_time: the current sim time, s.
        recover: called with a reason when ``step`` raised.
        logger: the node's logger.
        real_time_factor: sim s per wall s; 0 = as fast as possible.

    Attributes:
        paused: no step is taken but those of a ``~/step`` request (set it under
            ``lock``, then ``wake``).
        achieved_rtf: sim s per wall s over the last ``SPEED_WINDOW`` s (NaN at first).
        heartbeat: ``time.monotonic()`` when the loop last made progress (a step, a
            wait, a wake-up while paused).
        errors: exceptions the loop caught (and survived).
        restarts: times ``restart`` started a new thread after one had ended.
        started: ``start`` was called (the thread is expected to run).
    """

    def __init__(self, *, lock: SimLock, step: Callable[[], object],
                 force_step: Callable[[], object], run_commands: Callable[[], None],
                 has_commands: Callable[[], bool], sim_time: Callable[[], float],
                 recover: Callable[[str], None], logger, real_time_factor: float):
        self._lock = lock
        self._step = step
        self._force_step = force_step
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
        self._request: StepRequest | None = None
        self.achieved_rtf = math.nan
        self.heartbeat = time.monotonic()
        self._shared_at = self.heartbeat
        self.errors = 0
        self.restarts = 0
        self.started = False
        self._thread = self._new_thread()

    def _new_thread(self) -> threading.Thread:
        return threading.Thread(target=self._run, name='physics', daemon=True)

    def start(self) -> None:
        self.heartbeat = time.monotonic()
        self.started = True
        self._thread.start()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def restart(self) -> None:
        """Start a new physics thread if the current one has ended (not when stopped)."""
        if self._stop.is_set() or self._thread.is_alive():
            return
        self.restarts += 1
        self._thread = self._new_thread()
        self.start()

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

    # -------------------------------------------------------------- ~/step
    def request_steps(self, steps: int) -> StepRequest | str:
        """Queue ``steps`` steps for the (paused) thread: the request, or why not."""
        with self._lock:
            if not self.paused:
                return 'the simulation is running; pause it first (~/pause)'
            current = self._request
            if current is not None and not current.done.is_set():
                return (f'a ~/step request is in progress ({current.taken} of '
                        f'{current.steps} steps taken); wait for its answer')
            self._request = StepRequest(steps)
            request = self._request
        self.wake()
        return request

    def interrupt_steps(self, reason: str) -> None:
        """End the active ``~/step`` request before its next step (call under ``lock``)."""
        request = self._request
        if request is not None:
            request.finish(reason)

    @property
    def step_request(self) -> StepRequest | None:
        return self._request

    # ------------------------------------------------------------ lifecycle
    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def stop(self, timeout: float) -> None:
        self._stop.set()
        self._wake.set()
        self.interrupt_steps('the simulator is shutting down')
        if self._thread.is_alive():
            self._thread.join(timeout=timeout)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self._iterate()
            except Exception as err:   # the thread reports and survives any exception
                self.errors += 1
                self._logger.error(f'physics loop raised {type(err).__name__}: {err}; '
                                   'resetting the simulation')
                try:
                    self._recover(f'{type(err).__name__}: {err}')
                except Exception as again:   # pragma: no cover - defensive
                    self._logger.error(f'recovery raised {type(again).__name__}: {again}')
                    self._wake.wait(MAX_WAIT)
            self.heartbeat = time.monotonic()

    def _iterate(self) -> None:
        """One pass: a step, a step of a ``~/step`` request, or a bounded wait."""
        if self.paused:
            request = self._request
            if request is not None and not request.done.is_set():
                self._take_requested_step(request)
                return
            if self._has_commands():   # validated and set now; they act at the next step
                with self._lock:
                    self._run_commands()
            self._wait(MAX_WAIT)
            return
        delay = self._pacing_delay()
        if delay > MIN_WAIT:
            self._wait(delay)
            return
        # A callback waiting for the lock (reset, pause, an action) goes first.
        self._lock.yield_to_waiters(LOCK_YIELD_TIMEOUT)
        self._step()
        self._watch_speed(self.real_time_factor)
        self._share_interpreter()

    def _share_interpreter(self) -> None:
        """Sleep ``SHARE_PAUSE`` once per ``SHARE_PERIOD`` of back-to-back steps."""
        now = time.monotonic()
        if now - self._shared_at >= SHARE_PERIOD:
            time.sleep(SHARE_PAUSE)
            self._shared_at = time.monotonic()

    def _take_requested_step(self, request: StepRequest) -> None:
        self._lock.yield_to_waiters(LOCK_YIELD_TIMEOUT)
        with self._lock:
            if request.done.is_set():   # interrupted while this thread waited
                return
            if self._force_step() is None:
                if not request.done.is_set():
                    request.finish('the step failed and the simulation was reset (see '
                                   'the log)')
                return
            request.taken += 1
            if request.taken >= request.steps:
                request.finish()

    def _wait(self, seconds: float) -> None:
        self._wake.wait(seconds)
        self._wake.clear()

    def _pacing_delay(self) -> float:
        """Wall s to wait before the next step (0 = now), at most ``MAX_WAIT``."""
        factor = self.real_time_factor
        if factor <= 0.0:
            return 0.0
        wall0, sim0 = self._anchor
        ahead = (self._sim_time() - sim0) - (time.monotonic() - wall0) * factor
        if ahead < -MAX_LAG * factor:
            self.reanchor()
        return pacing_delay(ahead, factor)

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
