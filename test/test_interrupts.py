"""``gripper_sim.interrupts``: a Ctrl-C is raised only in frames that can take it."""
import signal
import sys

import pytest

from gripper_sim import interrupts


def _frame_in(path: str):
    """A live frame whose code comes from a file at ``path`` (called from this one)."""
    namespace: dict = {}
    exec(compile('import sys\ndef here():\n    return sys._getframe()\n', path, 'exec'),
         namespace)
    return namespace['here']()


def test_a_frame_of_our_own_is_interruptible_and_takes_the_interrupt_at_once():
    frame = sys._getframe()
    assert interrupts.interruptible(frame)
    with pytest.raises(KeyboardInterrupt):
        interrupts.interrupt(frame)
    assert signal.getitimer(signal.ITIMER_REAL)[0] == 0.0


@pytest.mark.parametrize('path', ['/venv/site-packages/numba/core/caching.py',
                                  '/venv/site-packages/llvmlite/binding/executionengine.py',
                                  '<frozen importlib._bootstrap>',
                                  '/usr/lib/python3.11/ctypes/__init__.py'])
def test_in_numba_llvmlite_an_import_or_ctypes_the_interrupt_waits_for_the_timer(path):
    frame = _frame_in(path)
    assert not interrupts.interruptible(frame)
    previous = signal.signal(signal.SIGALRM, lambda *_: None)
    try:
        interrupts.interrupt(frame)   # no raise: the timer looks again
        remaining, _ = signal.getitimer(signal.ITIMER_REAL)
        assert 0.0 < remaining <= interrupts.RETRY
    finally:
        interrupts.cancel()
        signal.signal(signal.SIGALRM, previous)
    assert signal.getitimer(signal.ITIMER_REAL)[0] == 0.0


def test_install_routes_the_signals_and_the_timer_and_restore_puts_them_back():
    def handler(signum, frame):
        pass
    before = {number: signal.getsignal(number) for number in (signal.SIGINT, signal.SIGALRM)}
    previous = interrupts.install(handler)
    try:
        assert signal.getsignal(signal.SIGINT) is handler
        assert signal.getsignal(signal.SIGALRM) is handler
    finally:
        interrupts.restore(previous)
    assert {number: signal.getsignal(number) for number in before} == before
