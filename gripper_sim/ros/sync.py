"""Synchronisation inside the node: the simulation lock and the ownership of the jaws.

``SimLock`` guards the simulation; it is fair to the threads that wait for it (the
physics thread steps back to back and would otherwise keep it). ``JawOwnership``
records which action drives the jaws: one at a time, the newest goal preempts the
active one. ``ActiveGoal`` is what such a goal looks like to the node.
No rclpy import here.
"""
from __future__ import annotations

import math
import threading
import time


class SimLock:
    """The simulation lock: re-entrant, and fair to the threads that wait for it.

    The physics thread steps back to back at ``real_time_factor`` 0 (or whenever it
    cannot keep up), releasing the lock only for a moment between steps. A plain lock
    then nearly always goes straight back to it: a callback waiting for the lock
    (``~/reset``, ``~/pause``, an action, a recording switch) could wait for seconds or
    for ever. The physics thread calls ``yield_to_waiters`` before each step, so a
    thread already waiting gets the lock first. Use it like ``threading.RLock``.
    """

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._state = threading.Condition(threading.Lock())
        self._waiting = 0

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        if self._lock.acquire(False):   # free, or held by this thread
            return True
        if not blocking:
            return False
        with self._state:
            self._waiting += 1
        try:
            return self._lock.acquire(True, timeout)
        finally:
            with self._state:
                self._waiting -= 1
                if not self._waiting:
                    self._state.notify_all()

    def release(self) -> None:
        self._lock.release()

    def __enter__(self) -> 'SimLock':
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    @property
    def waiting(self) -> int:
        """How many threads are blocked waiting for the lock."""
        return self._waiting

    def yield_to_waiters(self, timeout: float) -> None:
        """Until every thread waiting for the lock got it (at most ``timeout`` s).

        Call it without holding the lock (it would be a deadlock otherwise, bounded by
        ``timeout``).
        """
        with self._state:
            if self._waiting:
                self._state.wait_for(lambda: not self._waiting, timeout)


# How long a canceled run waits for rclpy to mark its goal as canceling.
CANCEL_CONFIRM_TIMEOUT = 2.0   # s


class JawOwner:
    """What an action that drives the jaws implements so the node can stop it."""

    kind = 'action'

    def abort(self, reason: str) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def preempt(self, reason: str) -> None:
        """Stop it for a newer goal (``JawOwnership.claim``); an abort unless the owner
        tells the two apart."""
        self.abort(reason)


class ActiveGoal(JawOwner):
    """An executing action goal that drives the jaws.

    Attributes:
        goal_handle: the rclpy goal handle.
        finished: set when the goal should stop waiting (done, canceled, aborted).
        abort_reason: why it was stopped from outside (reset, failure, shutdown,
            preemption), or None.
        preempted: whether that was a newer goal (``preempt``).
        error: why its own motion failed, or None.
        last_feedback: (sim time, wall time) of the last feedback sent, s.
        ticket: ``JawOwnership.ticket()`` of its acceptance.
    """

    def __init__(self, goal_handle, ticket: int):
        self.goal_handle = goal_handle
        self.ticket = ticket
        self.finished = threading.Event()
        self.abort_reason: str | None = None
        self.error: str | None = None
        self.last_feedback = (-math.inf, -math.inf)
        self.preempted = False
        self._cancel_requested = False

    def abort(self, reason: str) -> None:
        """Stop from outside: non-blocking (the executing callback finishes the goal)."""
        if self.abort_reason is None:
            self.abort_reason = reason
        self.finished.set()

    def preempt(self, reason: str) -> None:
        """Stop for a newer goal: as ``abort``, and the goal ends canceled."""
        if self.abort_reason is None:
            self.preempted = True
        self.abort(reason)

    def cancel(self) -> None:
        """The client asked to cancel (from the cancel callback, before rclpy marks the
        goal as canceling: ``canceled`` is true from now on)."""
        self._cancel_requested = True
        self.finished.set()

    @property
    def canceled(self) -> bool:
        return self._cancel_requested or self.goal_handle.is_cancel_requested

    def cancel_confirmed(self, timeout: float = CANCEL_CONFIRM_TIMEOUT) -> bool:
        """Whether rclpy has moved the goal to CANCELING, waiting up to ``timeout`` s.

        It does so just after the cancel callback accepted, but this run may already
        be finishing: ``goal_handle.canceled()`` before that is an invalid transition.
        """
        deadline = time.monotonic() + timeout
        while not self.goal_handle.is_cancel_requested:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.001)
        return True


class JawOwnership:
    """Which action drives the jaws: at most one, and none once the node shuts down."""

    def __init__(self) -> None:
        self._changed = threading.Condition(threading.Lock())
        self._owner: JawOwner | None = None
        self._closed = False
        self._newest = 0   # ticket of the newest goal accepted

    def ticket(self) -> int:
        """A number for a goal just accepted: later goals get larger ones. Goals start
        executing in any order; ``claim`` uses the ticket so the newest one wins."""
        with self._changed:
            self._newest += 1
            return self._newest

    @property
    def owner(self) -> JawOwner | None:
        return self._owner

    def claim(self, owner: JawOwner, ticket: int) -> str | None:
        """Make ``owner`` (accepted with ``ticket``) the only driver of the jaws; the
        reason it cannot, or None.

        An active owner is preempted by ``owner`` (its goal ends canceled, see
        ``ros.goal_end``): the newest goal always
        wins, as in ros2_controllers' gripper action controller, so a goal whose client
        has gone (killed, disconnected) never blocks the jaws. A goal that starts after
        a newer one was accepted never drives them.
        """
        with self._changed:
            if self._closed:   # nothing would ever finish it
                return 'the simulator is shutting down'
            if ticket < self._newest:
                return 'preempted by a newer goal before it started'
            current = self._owner
            if current is not None:
                current.preempt(f'preempted by a new {owner.kind} goal')
            self._owner = owner
            return None

    def release(self, owner: JawOwner) -> None:
        with self._changed:
            if self._owner is owner:
                self._owner = None
                self._changed.notify_all()

    def abort_owner(self, reason: str) -> None:
        """Abort the active owner, if any (it releases the jaws when it has finished)."""
        with self._changed:
            owner = self._owner
        if owner is not None:
            owner.abort(reason)

    def close(self, reason: str, timeout: float) -> None:
        """Refuse new owners; abort the active one and wait (``timeout`` s) until it ends."""
        with self._changed:
            self._closed = True
            owner = self._owner
        if owner is not None:
            owner.abort(reason)
            with self._changed:
                self._changed.wait_for(lambda: self._owner is None, timeout)
