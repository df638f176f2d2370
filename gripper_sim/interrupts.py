"""Ctrl-C (a KeyboardInterrupt raised by a signal handler) only where it breaks nothing.

Python raises a signal handler's exception in whatever Python frame the main thread is
in, and some frames cannot take one:

- numba's and llvmlite's compiling and cache loading run Python as ctypes callbacks of
  LLVM; ctypes swallows the exception there and LLVM goes on with broken state (a
  segmentation fault: the node, stopped while it loaded a cached kernel, in CI);
- an extension module's import turns it into its own ImportError (pymetis' pybind11 init
  did, in CI).

``interrupt(frame)``, called by a handler with the frame the signal came in, raises
KeyboardInterrupt there if no frame of ``UNINTERRUPTIBLE`` is on the stack, else arms a
timer (SIGALRM every ``RETRY``) whose handler calls it again from wherever the main
thread then is. Whoever installs a handler that calls ``interrupt`` routes SIGALRM to it
too (``install``) and ``cancel``s the timer when an interrupt is no longer wanted.
"""
from __future__ import annotations

import signal
from collections.abc import Callable

#: parts of the file paths of the frames an interrupt must not be raised in
UNINTERRUPTIBLE = ('/numba/', '/llvmlite/', 'importlib', '/ctypes/')
#: s, how often a deferred interrupt looks again for a frame it may be raised in
RETRY = 0.02


def interruptible(frame) -> bool:
    """Whether a KeyboardInterrupt may be raised in ``frame`` (a signal handler's: the
    main thread's frame the signal came in; None: unknown, taken as yes): none of its
    frames runs code of ``UNINTERRUPTIBLE``."""
    while frame is not None:
        name = frame.f_code.co_filename
        if any(part in name for part in UNINTERRUPTIBLE):
            return False
        frame = frame.f_back
    return True


def interrupt(frame) -> None:
    """Raise KeyboardInterrupt in ``frame`` if it is ``interruptible``, else look again
    in ``RETRY`` s (SIGALRM: its handler, ``install``'s, calls this again)."""
    if interruptible(frame):
        cancel()
        raise KeyboardInterrupt
    signal.setitimer(signal.ITIMER_REAL, RETRY)


def cancel() -> None:
    """Stop a deferred interrupt's timer (none running: nothing)."""
    signal.setitimer(signal.ITIMER_REAL, 0.0)


def install(handler: Callable, signals=(signal.SIGINT,)) -> dict:
    """Route ``signals`` and the retry timer's SIGALRM to ``handler(signum, frame)``
    (which calls ``interrupt`` where it wants one); the handlers before, by signal
    (``restore``)."""
    return {number: signal.signal(number, handler) for number in (*signals, signal.SIGALRM)}


def restore(previous: dict) -> None:
    """Cancel the timer and put back the handlers ``install`` replaced."""
    cancel()
    for number, handler in previous.items():
        signal.signal(number, handler)
