"""Bounded background computation with a wall-clock budget.

Planning and closed-loop runs take from a fraction of a second to tens of seconds of
CPU. They run on a small thread pool (``workers``) so the event loop keeps answering;
a request waits at most its budget (s) and then gets HTTP 504 while the computation
finishes in the background (Python threads cannot be interrupted). At most
``max_pending`` computations are queued or running; beyond that requests get HTTP 503.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

from parknss.web.errors import BusyError, OverBudgetError, WebError

T = TypeVar("T")


class ComputeRunner:
    """A thread pool with admission control and per-call budgets."""

    def __init__(self, workers: int, max_pending: int) -> None:
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="parknss-web")
        self._max = max_pending
        self._pending = 0
        self._lock = threading.Lock()

    @property
    def pending(self) -> int:
        """Computations queued or running now."""
        return self._pending

    def _done(self, _fut) -> None:
        with self._lock:
            self._pending -= 1

    async def run(self, budget_s: float, what: str, fn: Callable[..., T], *args) -> T:
        """``fn(*args)`` on the pool; BusyError when full, OverBudgetError after ``budget_s`` s."""
        with self._lock:
            if self._pending >= self._max:
                raise BusyError(f"server busy: {self._pending} computations pending, try again")
            self._pending += 1
        fut = self._pool.submit(fn, *args)
        fut.add_done_callback(self._done)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(fut), budget_s)
        except MemoryError as exc:  # a scene too large for this server is the user's input
            raise WebError(
                f"{what} ran out of memory on the server: make the map (bounds) smaller", 422
            ) from exc
        except TimeoutError as exc:
            raise OverBudgetError(
                f"{what} exceeded the server's budget of {budget_s:g} s; it finishes in the "
                "background (a plan is then cached), so retry in a while"
            ) from exc

    def shutdown(self) -> None:
        """Stop taking work; running computations finish in the background."""
        self._pool.shutdown(wait=False, cancel_futures=True)
