"""A stalled call's helper thread, abandoned just as the call returned, ends quietly: the Stalled raised into it
lands between two calls and is not a thread's traceback on the user's terminal (seen in the live view under a
GUI flood)."""

import threading
import time

import pytest

from twin.guard import _Helper


def _ends(helper: _Helper, within_s: float = 5.0) -> bool:
    helper.thread.join(within_s)
    return not helper.thread.is_alive()


@pytest.mark.quick
def test_an_idle_helper_abandoned_between_two_calls_ends_without_a_traceback() -> None:
    seen: list[threading.ExceptHookArgs] = []
    old = threading.excepthook
    threading.excepthook = seen.append
    try:
        helper = _Helper()
        helper.job = (lambda x: x + 1, 1)
        helper.go.set()
        assert helper.done.wait(5.0)
        assert helper.result == (True, 2)
        time.sleep(0.05)  # the thread is back in its wait for the next call
        helper.abandon()
        assert _ends(helper), "the abandoned helper thread did not end"
    finally:
        threading.excepthook = old
    assert seen == [], f"the helper thread printed {seen[0].exc_type.__name__}"


@pytest.mark.quick
def test_a_busy_call_abandoned_ends_with_stalled_and_its_thread_ends() -> None:
    helper = _Helper()
    started = threading.Event()

    def spin(_: object) -> None:
        started.set()
        while True:
            pass

    helper.job = (spin, None)
    helper.go.set()
    assert started.wait(5.0)
    helper.abandon()
    assert _ends(helper), "a busy call abandoned kept its thread"
    ok, exc = helper.result
    assert not ok and type(exc).__name__ == "Stalled"
