"""Waiting on state, the one way every realtime test waits (docs/testing.md).

A test of anything timed waits for the state it needs (an event in a recording, a device's own
report, a HUD's state) with a generous deadline, never for a fixed stretch of wall-clock time:
on a busy machine every thread runs late, and only the state says when something happened. The
deadline only bounds a hang; when it passes, the failure says what was awaited and what was seen.
"""
import time


def wait_until(predicate, timeout, what, seen=None, poll=0.005, each=None):
    """Poll `predicate()` until it returns something true (returned), or fail after `timeout`
    seconds with an AssertionError naming `what` was awaited and what `seen()` shows then
    (default: the predicate's last value). `each(elapsed)`, if given, is called before every
    look with the seconds since the wait began: what Blender's timer would do meanwhile (a live
    session's tick)."""
    start = time.monotonic()
    deadline = start + timeout
    while True:
        if each is not None:
            each(time.monotonic() - start)
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            shown = seen() if seen is not None else value
            raise AssertionError(f"waited {timeout:g} s for {what}; saw: {shown!r}")
        time.sleep(poll)
