"""``procedures.held_signals.signals_held``: a block an abort signal does not cut short."""

from __future__ import annotations

import signal
import threading
import time

import pytest

from fbs.signals import aborting_on_signals
from procedures.held_signals import signals_held


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_a_signal_another_thread_takes_is_held_until_the_block_ends(signum):
    """The kernel hands a process's signal to any thread that does not block it (a process
    pool's manager thread, a CAN notifier): ``pthread_sigmask`` in the main thread held nothing
    then, and an interrupted campaign's curves missed the run whose line it had just written."""
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, name="blocks-nothing")
    other.start()
    reached = False
    try:
        with (
            aborting_on_signals(),
            pytest.raises(KeyboardInterrupt, match=signal.Signals(signum).name),
        ):
            with signals_held():
                signal.pthread_kill(other.ident, signum)  # the signal lands on the other thread
                time.sleep(0.05)  # an unheld signal raises here
                reached = True
            time.sleep(1.0)  # a hang guard: it has been raised before
    finally:
        stop.set()
        other.join()
    assert reached


def test_only_the_first_signal_acts_and_the_handlers_come_back():
    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP)}
    calls = []
    with aborting_on_signals():
        inside = signal.getsignal(signal.SIGTERM)
        signal.signal(signal.SIGHUP, lambda s, f: calls.append(s))
        signal.signal(signal.SIGTERM, lambda s, f: calls.append(s))
        with signals_held():
            signal.raise_signal(signal.SIGHUP)
            signal.raise_signal(signal.SIGTERM)
            assert calls == []
        assert calls == [signal.SIGHUP]
        signal.signal(signal.SIGTERM, inside)
    assert {s: signal.getsignal(s) for s in before} == before


def test_outside_the_main_thread_the_block_just_runs():
    ran = []

    def body():
        with signals_held():
            ran.append(signal.getsignal(signal.SIGTERM))

    t = threading.Thread(target=body)
    t.start()
    t.join()
    assert ran == [signal.getsignal(signal.SIGTERM)]
