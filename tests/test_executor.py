import json

import pytest

from parknss.errors import ConfigError, MissingResultsError
from parknss.executor import Job, ResultCache, Tally, run_jobs

PROBE = "parknss.experiments.probe:probe_fit"


def _jobs(n=4):
    return [Job(PROBE, {"seed": s, "steps": 20}, name=f"s{s}") for s in range(n)]


def test_local_pool_equals_in_process():
    serial = run_jobs(_jobs(), workers=1, progress=False)
    pooled = run_jobs(_jobs(), workers=2, progress=False)
    assert serial == pooled
    assert [r["seed"] for r in serial] == [0, 1, 2, 3]
    assert len({r["a"] for r in serial}) == 4  # seeds matter


def test_cache_resumes_without_recomputing(tmp_path):
    jobs = _jobs(3)
    first = run_jobs(jobs[:2], workers=1, cache_dir=tmp_path, progress=False)
    # poison the cached value: a resumed sweep must read it, not recompute
    path = tmp_path / f"{jobs[0].key()}.json"
    doc = json.loads(path.read_text())
    doc["result"]["a"] = 123.0
    path.write_text(json.dumps(doc))
    again = run_jobs(jobs, workers=1, cache_dir=tmp_path, progress=False)
    assert again[0]["a"] == 123.0
    assert again[1] == first[1]
    assert ResultCache(tmp_path).get(jobs[2])[0]


def test_cache_hits_a_job_whose_arguments_hold_tuples(tmp_path):
    """The cache file holds the arguments as JSON (tuples become lists): the job that wrote
    it must still find it (an actuator envelope's bounds are tuples)."""
    job = Job(PROBE, {"seed": 1, "steps": 20, "n": 64}, name="t")
    tupled = Job(PROBE, {"seed": 1, "steps": 20, "n": 64, "unused": (1.5, -2.0)}, name="t")
    ResultCache(tmp_path).put(tupled, {"a": 1.0})
    assert ResultCache(tmp_path).get(tupled) == (True, {"a": 1.0})
    assert not ResultCache(tmp_path).get(job)[0]


def test_torn_cache_file_is_recomputed(tmp_path):
    job = _jobs(1)[0]
    (tmp_path / f"{job.key()}.json").write_text('{"fn": "x", "res')
    (res,) = run_jobs([job], workers=1, cache_dir=tmp_path, progress=False)
    assert res["seed"] == 0


def test_bad_job_path_is_a_clear_error():
    with pytest.raises(ConfigError, match="module:function"):
        run_jobs([Job("no_colon_here", {})], workers=1, progress=False)
    with pytest.raises(ConfigError, match="executor"):
        run_jobs(_jobs(1), executor="dask", progress=False)


def test_ray_matches_local():
    pytest.importorskip("ray")
    local = run_jobs(_jobs(3), workers=1, progress=False)
    remote = run_jobs(_jobs(3), executor="ray", workers=2, progress=False)
    assert local == remote


def test_a_store_behind_the_cache(tmp_path):
    class DictStore:
        fit_missing = True

        def __init__(self):
            self.docs, self.times, self.resumed = {}, {}, []

        def get(self, job):
            return (job.key() in self.docs), self.docs.get(job.key())

        def put(self, job, result, wall_s, cpu_s):
            self.docs[job.key()], self.times[job.key()] = result, (wall_s, cpu_s)

        def resume(self, job):
            self.resumed.append(job.key())

    store, jobs = DictStore(), _jobs(2)
    tally = Tally()
    first = run_jobs(jobs, workers=1, cache_dir=tmp_path / "a", progress=False, store=store,
                     tally=tally)
    assert tally.to_json() == {"cache": 0, "store": 0, "computed": 2}
    assert store.resumed == [j.key() for j in jobs]  # each computed job, before it ran
    assert all(w >= 0 and c >= 0 for w, c in store.times.values())
    assert ResultCache(tmp_path / "a").get(jobs[0])[0]  # computed: in the cache and the store
    again = run_jobs(jobs, workers=1, cache_dir=tmp_path / "b", progress=False, store=store,
                     tally=tally)
    assert again == first and tally.to_json() == {"cache": 0, "store": 2, "computed": 2}
    assert len(store.resumed) == 2  # stored jobs are not resumed
    assert not ResultCache(tmp_path / "b").get(jobs[0])[0]  # a stored result is not copied
    store.fit_missing = False  # --stored-only: what the store lacks is an error, not a fit
    assert run_jobs(jobs, workers=1, progress=False, store=store) == first
    more = [*jobs, *_jobs(3)[2:]]
    with pytest.raises(MissingResultsError, match="1 of 3 fits are not stored"):
        run_jobs(more, workers=1, progress=False, store=store, desc="probe")
    assert len(store.docs) == 2  # nothing was fitted


def test_pool_stores_each_result_as_soon_as_it_finishes():
    """A long first job does not hold back the store writes of the short ones behind it
    (a study killed mid-way keeps every fit that completed); results keep job order."""

    class Recorder:
        fit_missing = True

        def __init__(self):
            self.order = []

        def get(self, job):
            return False, None

        def put(self, job, result, wall_s, cpu_s):
            self.order.append(job.kwargs["seed"])

        def resume(self, job):
            pass

    jobs = [Job(PROBE, {"seed": 0, "steps": 5000}), *(
        Job(PROBE, {"seed": s, "steps": 20}) for s in (1, 2, 3))]  # fmt: skip
    store = Recorder()
    res = run_jobs(jobs, workers=2, progress=False, store=store)
    assert [r["seed"] for r in res] == [0, 1, 2, 3]
    assert store.order[-1] == 0 and sorted(store.order) == [0, 1, 2, 3]


def _sleep(seconds: float) -> None:
    import time

    time.sleep(seconds)


def test_an_interrupt_behind_a_failed_pool_abort_stops_as_interrupted(monkeypatch):
    """SIGINT landing while loky's pool starts makes its abort fail with a RuntimeError
    raised while handling the KeyboardInterrupt: run_jobs raises the interrupt itself
    (the CLI's exit 130) and no pool worker outlives it."""
    import multiprocessing

    import joblib

    started: list = []

    class StartingPool:  # what joblib.Parallel does when the signal lands mid-start
        def __init__(self, **kwargs):
            pass

        def __call__(self, tasks):
            proc = multiprocessing.get_context("spawn").Process(target=_sleep, args=(60,))
            proc.start()
            started.append(proc)
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt:
                raise RuntimeError("cannot join thread before it is started")  # noqa: B904
            yield  # a generator, like Parallel(return_as="generator_unordered")

    monkeypatch.setattr(joblib, "Parallel", StartingPool)
    jobs = [Job("math:sqrt", {"x": 4.0}), Job("math:sqrt", {"x": 9.0})]
    with pytest.raises(KeyboardInterrupt):
        run_jobs(jobs, workers=2, progress=False)
    assert started and not started[0].is_alive()
    monkeypatch.undo()  # any other error still goes on as itself

    class FailingPool(StartingPool):
        def __call__(self, tasks):
            raise RuntimeError("a worker broke")
            yield

    monkeypatch.setattr(joblib, "Parallel", FailingPool)
    with pytest.raises(RuntimeError, match="a worker broke"):
        run_jobs(jobs, workers=2, progress=False)


def _wait_for(cond, timeout_s=120.0):
    import time

    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.05)


def test_prefetch_fills_the_cache_that_run_jobs_reads(tmp_path):
    """Jobs computed in background processes are the cache's: a later run_jobs reads every
    one of them and returns what an in-process run computes."""
    from parknss.executor import Prefetch

    jobs = _jobs(3)
    with Prefetch(jobs, tmp_path, workers=2) as pre:
        _wait_for(lambda: pre.computed == 3)
    assert pre.computed == 3
    tally = Tally()
    got = run_jobs(jobs, workers=1, cache_dir=tmp_path, progress=False, tally=tally)
    assert tally.to_json() == {"cache": 3, "store": 0, "computed": 0}
    assert got == run_jobs(jobs, workers=1, progress=False)


def test_prefetch_stopped_early_leaves_the_rest_to_run_jobs(tmp_path):
    from parknss.executor import Prefetch

    jobs = _jobs(4)
    with Prefetch(jobs, tmp_path, workers=1) as pre:
        pass  # stop at once: the one process finishes at most the job it holds
    assert pre.computed <= 1
    assert len(list(tmp_path.glob("*.json"))) == pre.computed
    tally = Tally()
    got = run_jobs(jobs, workers=1, cache_dir=tmp_path, progress=False, tally=tally)
    assert tally.cache == pre.computed and tally.computed == 4 - pre.computed
    assert got == run_jobs(jobs, workers=1, progress=False)


def test_prefetch_skips_cached_jobs_and_leaves_failures_to_the_caller(tmp_path):
    from parknss.executor import Prefetch

    good = _jobs(2)
    run_jobs(good[:1], workers=1, cache_dir=tmp_path, progress=False)
    bad = Job(PROBE, {"seed": 0, "steps": "many"}, name="bad")
    with Prefetch([good[0], bad, good[1]], tmp_path, workers=1) as pre:
        _wait_for(lambda: ResultCache(tmp_path).get(good[1])[0])
    assert pre.computed == 1  # good[1]: good[0] was cached, bad failed
    assert not ResultCache(tmp_path).get(bad)[0]
    with pytest.raises(TypeError):
        run_jobs([bad], workers=1, cache_dir=tmp_path, progress=False)


def test_prefetch_left_by_an_interrupt_kills_its_processes_at_once(tmp_path):
    import multiprocessing
    import time

    from parknss.executor import Prefetch

    jobs = [Job(PROBE, {"seed": s, "steps": 200_000}, name=f"s{s}") for s in range(2)]
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt), Prefetch(jobs, tmp_path, workers=2) as pre:
        _wait_for(lambda: len(pre._procs) == 2 and all(p.is_alive() for p in pre._procs))
        raise KeyboardInterrupt
    assert time.monotonic() - t0 < 30
    assert not [p for p in multiprocessing.active_children() if p.is_alive()]
    assert pre.computed == 0 and not list(tmp_path.glob("*.json"))


def test_prefetch_of_a_killed_caller_stops_after_the_job_it_holds(tmp_path):
    """SIGKILL of the caller: its background processes notice the lost parent between jobs
    and exit, instead of fitting the rest of the list for nobody."""
    import os
    import subprocess
    import sys
    import time

    script = f"""
import os, signal, sys, time
from parknss.executor import Job, Prefetch
jobs = [Job({PROBE!r}, {{"seed": s, "steps": 400}}, name=str(s)) for s in range(400)]
pre = Prefetch(jobs, {str(tmp_path)!r}, workers=2).__enter__()
while pre.computed < 2:
    time.sleep(0.02)
print(" ".join(str(p.pid) for p in pre._procs), flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == -9
    pids = [int(p) for p in proc.stdout.split()]
    assert len(pids) == 2

    def running(pid):
        try:
            with open(f"/proc/{pid}/stat") as f:
                return f.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
        except FileNotFoundError:
            return False

    _wait_for(lambda: not any(running(p) for p in pids), timeout_s=30)
    n = len(list(tmp_path.glob("*.json")))
    time.sleep(0.5)
    assert len(list(tmp_path.glob("*.json"))) == n < 400
