"""Kill a computation with SIGKILL, in a forked child, at a named crash point of the
writers (``PARKNSS_CRASH_AT``, :mod:`parknss.durable`) or after a delay; the kill-anywhere
tests of training states use it (forking skips a fresh interpreter's imports)."""

from __future__ import annotations

import contextlib
import os
import signal
import time
from collections.abc import Callable

from parknss import durable


def run_killed(body: Callable[[], object], crash: str | None = None,
               after_s: float | None = None) -> int:
    """Run ``body`` in a forked child that dies at the crash point ``crash`` (``NAME:N``)
    or is SIGKILLed by this process after ``after_s`` seconds; the signal that ended it
    (0: it finished before, -1: it raised)."""
    pid = os.fork()
    if pid == 0:  # the child: never returns into the test runner
        code = 0
        try:
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
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        return os.WTERMSIG(status)
    return 0 if os.WEXITSTATUS(status) == 0 else -1


KILL_SCHEDULE: tuple[str, ...] = (
    *(f"{p}:{n}" for n in (1, 2, 3) for p in durable.CRASH_POINTS if p.startswith("train_state")),
)
"""Crash points inside the state write, each hit at the 1st, 2nd and 3rd write of a child
(15 kills; the first hits kill before the child has committed anything)."""
