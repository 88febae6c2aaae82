"""One way to run many independent fits or simulations: a local pool or Ray (layer L0).

A :class:`Job` names a top-level function by import path (``"package.module:function"``)
and its keyword arguments, which must be JSON-serialisable; the function returns a
JSON-serialisable result. Because jobs and results are plain JSON, the same sweep runs
identically on a local joblib (loky) process pool, in-process (``workers=1``), or on a Ray
cluster, and every finished job is cached on disk under the hash of its (function,
arguments), so an interrupted sweep resumes where it stopped. Nothing is ever pickled to
disk. Each worker uses one torch thread (training is per-op overhead bound).

A second, longer-lived lookup can sit behind the cache: any object with the :class:`Store`
methods (the experiments' result store in the repository, :mod:`parknss.experiments.store`).
A job is read from the cache, else from the store, else computed; a computed result is
written to both (with the wall and CPU time its worker spent).
A :class:`Tally` counts where the results came from.

:class:`Prefetch` computes jobs into such a cache in background processes while the
caller does other work (``parknss identify`` fits the actuator study's Phase A beside the
NSS fit); the later :func:`run_jobs` with the same cache finds them done.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import json
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from tqdm import tqdm

from parknss.errors import ConfigError, MissingResultsError, ParknssError

EXECUTORS = ("local", "ray")


@dataclass(frozen=True)
class Job:
    """One unit of work: ``fn`` is ``"module:function"``, ``kwargs`` JSON-serialisable."""

    fn: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    name: str = ""

    def key(self) -> str:
        """Content hash of the function path and its arguments (the cache key)."""
        blob = json.dumps({"fn": self.fn, "kwargs": self.kwargs}, sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:24]


def resolve(path: str) -> Callable[..., Any]:
    """Import ``"module:function"`` and return the function."""
    module, _, attr = path.partition(":")
    if not module or not attr:
        raise ConfigError(f"job function {path!r} is not of the form 'module:function'")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"job function {path!r} cannot be imported: {exc}") from exc


def execute(job: Job, torch_threads: int = 1) -> Any:
    """Run one job in the current process with ``torch_threads`` intra-op threads."""
    os.environ.setdefault("OMP_NUM_THREADS", str(torch_threads))
    import torch

    torch.set_num_threads(torch_threads)
    result = resolve(job.fn)(**job.kwargs)
    json.dumps(result)  # results must be plain JSON: fail here, not in the cache
    return result


def execute_timed(job: Job, torch_threads: int = 1) -> tuple[Any, float, float]:
    """(result, wall s, CPU s) of :func:`execute`, timed in the process that runs it."""
    wall0, cpu0 = time.perf_counter(), time.process_time()
    result = execute(job, torch_threads)
    return result, time.perf_counter() - wall0, time.process_time() - cpu0


class Store(Protocol):
    """A lookup behind the run cache: ``get`` is ``(hit, result)``; ``put`` records a
    computed result with the wall and CPU seconds its worker spent on it;
    ``fit_missing`` False makes a job the cache and the store lack an error, not a fit
    (:class:`~parknss.errors.MissingResultsError`, raised before anything is fitted)."""

    fit_missing: bool

    def get(self, job: Job) -> tuple[bool, Any]: ...

    def put(self, job: Job, result: Any, wall_s: float, cpu_s: float) -> None: ...

    def resume(self, job: Job) -> None:
        """Called for each job about to be computed, before any runs: a store may
        prepare it (seed its resumable state from one an earlier sitting parked)."""


@dataclass
class Tally:
    """Where the results of one or more :func:`run_jobs` calls came from."""

    cache: int = 0
    store: int = 0
    computed: int = 0
    planned: int = 0
    """Jobs asked for so far (counted when a :func:`run_jobs` call starts; the others
    as results arrive, so an interrupted call's finished jobs are counted)."""

    @property
    def total(self) -> int:
        return self.cache + self.store + self.computed

    def to_json(self) -> dict[str, int]:
        return {"cache": self.cache, "store": self.store, "computed": self.computed}


class ResultCache:
    """A folder of ``<key>.json`` results, written atomically."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def _path(self, job: Job) -> Path:
        return self.root / f"{job.key()}.json"

    def get(self, job: Job) -> tuple[bool, Any]:
        p = self._path(job)
        if not p.is_file():
            return False, None
        try:
            doc = json.loads(p.read_text())
        except json.JSONDecodeError:
            return False, None  # a torn write from a killed run: recompute
        # compared as JSON, as the key is: a tuple argument is cached as a list
        if doc.get("fn") != job.fn or doc.get("kwargs") != json.loads(json.dumps(job.kwargs)):
            return False, None
        return True, doc["result"]

    def put(self, job: Job, result: Any) -> None:
        """Keep ``result`` durably (flushed to disk before the next job's result)."""
        from parknss import durable

        doc = {"fn": job.fn, "kwargs": job.kwargs, "name": job.name, "result": result}
        durable.write_bytes(self._path(job), json.dumps(doc).encode())


def run_jobs(
    jobs: Sequence[Job],
    executor: str = "local",
    workers: int | None = None,
    cache_dir: str | Path | None = None,
    address: str | None = None,
    progress: bool = True,
    desc: str = "jobs",
    store: Store | None = None,
    tally: Tally | None = None,
) -> list[Any]:
    """Run ``jobs`` and return their results in the order given.

    Args:
        executor: "local" (joblib loky pool; in-process when workers == 1) or "ray".
        workers: parallel workers (default: the machine's cores).
        cache_dir: if given, finished results are read from / written to this folder.
        address: Ray cluster address (``None`` starts a local Ray with ``workers`` CPUs).
        store: if given, asked for what the cache lacks; computed results are put in it.
        tally: if given, counts the results from the cache, the store and computed.
    """
    if executor not in EXECUTORS:
        raise ConfigError(f"executor {executor!r} is not one of {EXECUTORS}")
    workers = max(1, workers or os.cpu_count() or 1)
    cache = ResultCache(cache_dir) if cache_dir is not None else None
    results: list[Any] = [None] * len(jobs)
    todo: list[int] = []
    count = Tally()
    tally = tally if tally is not None else Tally()
    tally.planned += len(jobs)
    for i, job in enumerate(jobs):
        hit, value = cache.get(job) if cache else (False, None)
        if hit:
            results[i] = value
            count.cache += 1
            tally.cache += 1
            continue
        hit, value = store.get(job) if store else (False, None)
        if hit:  # not copied into the cache: it holds what this run computed
            results[i] = value
            count.store += 1
            tally.store += 1
        else:
            todo.append(i)
    if todo and store is not None and not store.fit_missing:
        raise MissingResultsError(desc, [jobs[i].name or jobs[i].fn for i in todo], len(jobs))
    for i in todo if store is not None else ():
        store.resume(jobs[i])
    bar = tqdm(
        total=len(jobs),
        initial=len(jobs) - len(todo),
        desc=desc,
        disable=not progress,
        file=sys.stderr,
    )
    runner = _run_ray if executor == "ray" else _run_local
    stream = runner([jobs[i] for i in todo], todo, workers, address)
    try:
        for i, (value, wall_s, cpu_s) in stream:
            results[i] = value
            if cache:
                cache.put(jobs[i], value)
            if store:
                store.put(jobs[i], value, wall_s, cpu_s)
            count.computed += 1
            tally.computed += 1
            bar.update(1)
    finally:  # an interrupt or error between results: stop the pool's workers now, and
        stream.close()  # end the bar's line before the command's last line is printed
        bar.close()
    if progress and store is not None:
        print(f"{desc}: {count.cache} from the run cache, {count.store} from the store, "
              f"{count.computed} computed", file=sys.stderr)
    return results


Timed = tuple[Any, float, float]  # (result, wall s, CPU s) of execute_timed


def _run_local(
    jobs: list[Job], index: list[int], workers: int, address: str | None
) -> Iterable[tuple[int, Timed]]:
    if workers == 1 or len(jobs) <= 1:
        for i, job in zip(index, jobs, strict=True):
            yield i, execute_timed(job)
        return
    from joblib import Parallel, delayed, parallel_config

    # results as they finish (not in submission order), so each is cached and stored as
    # soon as it exists: a long study killed mid-way keeps every fit that completed
    # closing this generator early (an interrupt, SIGTERM, an error) closes joblib's, which
    # kills the pool's workers in this thread before the exception goes on
    with parallel_config(backend="loky", inner_max_num_threads=1):
        run = Parallel(n_jobs=workers, return_as="generator_unordered")
        try:
            yield from run(delayed(_execute_indexed)(i, j)
                           for i, j in zip(index, jobs, strict=True))
        except Exception as exc:
            interrupt = _interrupt_behind(exc)
            if interrupt is None:
                raise
            _kill_pool_workers()
            raise interrupt from None


def _interrupt_behind(exc: BaseException) -> KeyboardInterrupt | None:
    """The SIGINT/SIGTERM interrupt ``exc`` was raised while handling, if any. loky's
    abort fails ("cannot join thread before it is started") when the signal lands while
    its pool is still starting; the command must still stop as interrupted."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return seen
        seen = seen.__context__
    return None


def _kill_pool_workers(timeout_s: float = 5.0) -> None:
    """Kill this process's pool workers (what loky's failed abort left running) and reap
    them, so none outlives an interrupted command."""
    import multiprocessing
    import signal

    children = multiprocessing.active_children()
    for proc in children:  # loky's Popen has no kill(): signal the pid
        if proc.pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.pid, signal.SIGKILL)
    for proc in children:
        proc.join(timeout_s)


def _execute_indexed(i: int, job: Job) -> tuple[int, Timed]:
    return i, execute_timed(job)


def _run_ray(
    jobs: list[Job], index: list[int], workers: int, address: str | None
) -> Iterable[tuple[int, Timed]]:
    try:
        import ray
    except ImportError as exc:
        raise ParknssError(
            "executor 'ray' needs the optional extra: pip install 'parknss[ray]'"
        ) from exc
    started = not ray.is_initialized()
    if started:
        env = {"env_vars": {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}}
        kwargs = {"address": address} if address else {"num_cpus": workers}
        if not address:
            # a local Ray starts its workers at niceness 15 by default, which starves them
            # on a shared machine; run them at the driver's priority, like the local pool
            os.environ.setdefault("RAY_worker_niceness", str(max(0, os.nice(0))))
        ray.init(include_dashboard=False, log_to_driver=False, runtime_env=env, **kwargs)
    try:
        remote = ray.remote(num_cpus=1)(execute_timed)
        # results come back in completion order; they are stored by index
        refs = {remote.remote(job): i for i, job in zip(index, jobs, strict=True)}
        pending = list(refs)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield refs[ref], ray.get(ref)
    finally:
        if started:
            ray.shutdown()


class Prefetch:
    """Compute ``jobs`` into the :class:`ResultCache` at ``cache_dir`` in ``workers``
    background processes while the caller does other work (a context manager).

    The processes are spawned (a fresh interpreter each, one torch thread, SIGINT ignored:
    the caller decides when they stop) and take the jobs in the order given from a shared
    counter, skipping those the cache already holds. :meth:`stop` asks them to stop and
    waits for each to finish and cache the job it holds, so no fit is thrown away (at most
    ``timeout_s``, then they are killed); leaving the ``with`` block by an exception (an
    interrupt, SIGTERM) kills them at once, and a caller killed outright (SIGKILL) leaves
    none running past the job it holds. A job that fails in the background is left
    out of the cache: the caller's :func:`run_jobs` computes it again and raises its error
    in the caller's process. Results are the cache's, so a job gives the same result
    wherever it ran (jobs must be deterministic in their arguments, as every parknss job
    is)."""

    def __init__(self, jobs: Sequence[Job], cache_dir: str | Path, workers: int = 1) -> None:
        if workers < 1:
            raise ConfigError(f"prefetch workers must be >= 1, got {workers}")
        self.jobs = list(jobs)
        self.cache_dir = Path(cache_dir)
        self.workers = workers
        self._procs: list[Any] = []
        self._stop: Any = None
        self._next: Any = None
        self._done: Any = None

    def __enter__(self) -> Prefetch:
        import multiprocessing

        ResultCache(self.cache_dir)  # create the folder here, not racing in the workers
        ctx = multiprocessing.get_context("spawn")
        self._stop, self._next, self._done = ctx.Event(), ctx.Value("i", 0), ctx.Value("i", 0)
        docs = [{"fn": j.fn, "kwargs": j.kwargs, "name": j.name} for j in self.jobs]
        for _ in range(min(self.workers, len(self.jobs))):
            proc = ctx.Process(target=_prefetch_worker, daemon=True,
                               args=(docs, str(self.cache_dir), self._next, self._done,
                                     self._stop))
            proc.start()
            self._procs.append(proc)
        return self

    @property
    def computed(self) -> int:
        """Jobs the background processes have computed and cached so far."""
        return 0 if self._done is None else int(self._done.value)

    def stop(self, timeout_s: float = 600.0) -> int:
        """Let each process finish its job, then stop; returns :attr:`computed`."""
        if self._stop is not None:
            self._stop.set()
        deadline = time.monotonic() + timeout_s
        for proc in self._procs:
            proc.join(max(0.0, deadline - time.monotonic()))
        self._kill()
        return self.computed

    def _kill(self) -> None:
        for proc in self._procs:
            if proc.is_alive():
                proc.kill()
            proc.join(5.0)
        self._procs = []

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.stop()
        else:
            if self._stop is not None:
                self._stop.set()
            self._kill()


def _prefetch_worker(docs: list[dict], cache_dir: str, next_job, done, stop) -> None:
    """One :class:`Prefetch` process: take the next job, compute it unless cached, cache
    it; until the jobs run out or the caller says stop."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = os.getppid()
    cache = ResultCache(cache_dir)
    while not stop.is_set() and os.getppid() == parent:  # a killed caller orphans no work
        with next_job.get_lock():
            i = next_job.value
            next_job.value += 1
        if i >= len(docs):
            return
        job = Job(**docs[i])
        if cache.get(job)[0]:
            continue
        try:
            result = execute(job)
        except Exception:  # left to the caller's run_jobs, which raises it there
            continue
        cache.put(job, result)
        with done.get_lock():
            done.value += 1
