"""Kill a computation with SIGKILL, in a forked child, at a named crash point of the
writers (``PARKNSS_CRASH_AT``, :mod:`parknss.durable`) or after a delay; the kill-anywhere
tests of training states use it (forking skips a fresh interpreter's imports)."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable

from parknss import durable

HANG_S = 300.0
"""A child still running this long after its kill time is hung: it is killed and the test
fails (never a test run that waits forever)."""


def run_killed(body: Callable[[], object], crash: str | None = None,
               after_s: float | None = None) -> int:
    """Run ``body`` in a forked child that dies at the crash point ``crash`` (``NAME:N``)
    or is SIGKILLed by this process after ``after_s`` seconds; the signal that ended it
    (0: it finished before, -1: it raised).

    The child gets its own tqdm lock: tqdm's default one is a multiprocessing semaphore
    shared with the parent and every other child, and a child SIGKILLed while it holds it
    (building a progress bar) would leave it taken for the next child, which then waits
    forever (seen under pytest-xdist)."""
    pid = os.fork()
    if pid == 0:  # the child: never returns into the test runner
        code = 0
        try:
            from tqdm import tqdm

            tqdm.set_lock(threading.RLock())
            os.environ.pop(durable.CRASH_ENV, None)
            if crash:
                os.environ[durable.CRASH_ENV] = crash
            durable._hits.clear()
            body()
        except BaseException:  # reported through the exit status
            code = 3
        os._exit(code)
    if after_s is not None:
        time.sleep(after_s)
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    status = _wait(pid, HANG_S)
    if os.WIFSIGNALED(status):
        return os.WTERMSIG(status)
    return 0 if os.WEXITSTATUS(status) == 0 else -1


def _wait(pid: int, limit_s: float) -> int:
    """The wait status of child ``pid``; kill it and fail if it runs over ``limit_s``."""
    end = time.monotonic() + limit_s
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status
        if time.monotonic() > end:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise AssertionError(f"forked child {pid} hung for {limit_s:.0f} s")
        time.sleep(0.005)


KILL_SCHEDULE: tuple[str, ...] = (
    *(f"{p}:{n}" for n in (1, 2, 3) for p in durable.CRASH_POINTS if p.startswith("train_state")),
)
"""Crash points inside the state write, each hit at the 1st, 2nd and 3rd write of a child
(15 kills; the first hits kill before the child has committed anything)."""
