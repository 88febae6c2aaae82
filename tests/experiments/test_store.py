"""The result store (parknss.experiments.store): keys, code version, where it is, and
``parknss study``/``reproduce``/``results`` reading and writing it, on a tiny campaign."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from parknss.cli import main
from parknss.config import PACKAGE_DIR, REPO_ROOT
from parknss.executor import Job, Tally, run_jobs
from parknss.experiments.config import load_experiments_config
from parknss.experiments.jobs import FOLD_JOB
from parknss.experiments.store import (
    CODE_FILES,
    ResultStore,
    code_files,
    code_tokens,
    code_version,
    entries,
    fit_key,
    open_store,
    store_dir,
)
from parknss.experiments.studies import StudyInputs, run_study

PROBE = "parknss.experiments.probe:probe_fit"


def _store(root: Path, data_hash: str = "d0", **kw) -> ResultStore:
    store = ResultStore(root, log=lambda msg: None, **kw)
    store._data_hashes[None] = data_hash  # the probe reads no campaign
    return store


def _job(seed: int = 0) -> Job:
    return Job(PROBE, {"seed": seed, "steps": 20}, name=f"probe {seed}")


def test_code_version_follows_the_listed_files_only(tmp_path):
    for pattern in CODE_FILES:  # a renamed file must be renamed in the list too
        assert list(PACKAGE_DIR.glob(pattern)), pattern
    for p in code_files():
        dst = tmp_path / p.relative_to(PACKAGE_DIR)
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(p, dst)
    assert code_version(tmp_path) == code_version()
    (tmp_path / "experiments" / "findings.py").write_text("# not training code\n")
    (tmp_path / "sim").mkdir()
    (tmp_path / "sim" / "grid.py").write_text("x = 1\n")
    assert code_version(tmp_path) == code_version()
    (tmp_path / "nss" / "config.py").write_text("# defaults: in the key, resolved\n")
    assert code_version(tmp_path) == code_version()
    losses = tmp_path / "nss" / "losses.py"
    text = losses.read_text()
    losses.write_text(text.replace('"""', '"""Reworded. ', 1) + "\n\n# a comment\n")
    assert code_version(tmp_path) == code_version()  # docstrings and comments are not code
    losses.write_text(text + "\nEPS_UNUSED = 1e-9\n")
    assert code_version(tmp_path) != code_version()


def test_code_tokens_keep_code_and_drop_what_does_not_run():
    a = '''"""Module doc."""
import math  # why


def f(x):
    """Doc of f in °/s,
    two lines: σ."""  # after

    return math.sqrt(x)  # root


class C:
    "one" "joined"
    y = "not a docstring"
'''
    b = '''import math
def f(x):
    return math.sqrt(x)
class C:
    y = "not a docstring"
'''
    assert code_tokens(a) == code_tokens(b)
    assert code_tokens(b) != code_tokens(b.replace("sqrt", "exp"))
    assert code_tokens(b) != code_tokens(b.replace("not a docstring", "other"))


def test_where_the_store_is(tmp_path):
    assert store_dir(None, "auto", env={}) == REPO_ROOT / "results"  # the checkout's
    assert store_dir(None, "auto", env={"PARKNSS_RESULTS": str(tmp_path)}) == tmp_path
    assert store_dir(None, "auto", env={"PARKNSS_RESULTS": "off"}) is None
    assert store_dir(str(tmp_path), "off", env={"PARKNSS_RESULTS": "off"}) == tmp_path
    assert store_dir("off", "auto", env={}) is None
    cfg = load_experiments_config()
    assert cfg.store.dir == "auto" and not cfg.store.write_quick
    quick = open_store(tmp_path, cfg, quick=True, refit=False)
    assert quick.read and not quick.write  # quick runs read the store, never write it
    refit = open_store(tmp_path, cfg, quick=False, refit=True)
    assert refit.write and not refit.read


def test_lookup_order_tally_and_misses(tmp_path):
    jobs = [_job(0), _job(1)]
    store = _store(tmp_path / "store")
    tally = Tally()
    first = run_jobs(jobs, workers=1, progress=False, cache_dir=tmp_path / "c1", store=store,
                     tally=tally)
    assert tally.to_json() == {"cache": 0, "store": 0, "computed": 2}
    assert len(list((tmp_path / "store" / "probe_fit").glob("*.json"))) == 2
    tally = Tally()
    again = run_jobs([*jobs, _job(2)], workers=1, progress=False, cache_dir=tmp_path / "c1",
                     store=store, tally=tally)
    assert again[:2] == first and tally.to_json() == {"cache": 2, "store": 0, "computed": 1}
    tally = Tally()  # a new run folder: from the store
    again = run_jobs(jobs, workers=1, progress=False, cache_dir=tmp_path / "c2", store=store,
                     tally=tally)
    assert again == first and tally.to_json() == {"cache": 0, "store": 2, "computed": 0}
    # another campaign or another training code: every stored fit misses
    assert not _store(tmp_path / "store", data_hash="d1").get(jobs[0])[0]
    other_code = _store(tmp_path / "store")
    other_code.code = "0123456789abcdef"
    assert not other_code.get(jobs[0])[0]
    # a refit ignores the stored result but records the new one
    assert not _store(tmp_path / "store", read=False).get(jobs[0])[0]


def test_entry_is_plain_json_with_provenance(tmp_path):
    store = _store(tmp_path)
    job = Job(PROBE, {"seed": 3, "steps": 20, "save_dir": "/elsewhere", "progress": False})
    res = {"a": 0.5, "seed": 3}
    store.put(job, res, wall_s=1.25, cpu_s=1.0)
    ((path, entry),) = entries(tmp_path)
    assert entry.key == path.stem
    doc = json.loads(path.read_text())
    assert doc["key"] == path.stem and doc["result"] == res
    # the function's defaults filled in (n), where a model goes dropped
    assert doc["job"] == {"fn": PROBE, "kwargs": {"seed": 3, "n": 256, "steps": 20}, "name": ""}
    assert doc["data_hash"] == "d0" and doc["code_version"] == code_version()
    prov = doc["provenance"]
    assert {"git_revision", "dirty", "machine", "python", "torch", "wall_s", "cpu_s",
            "finished_utc", "config"} <= set(prov)
    assert prov["wall_s"] == 1.25 and prov["cpu_s"] == 1.0 and prov["machine"]["cores"] >= 1
    # where a model was saved does not decide the scores, nor spelling out a default
    assert store.get(Job(PROBE, {"seed": 3, "steps": 20}))[0]
    assert store.get(Job(PROBE, {"seed": 3, "steps": 20, "n": 256}))[0]


def test_corrupt_file_is_ignored_with_a_warning_and_refitted(tmp_path, capsys):
    store = ResultStore(tmp_path)
    store._data_hashes[None] = "d0"
    job = _job(0)
    run_jobs([job], workers=1, progress=False, store=store)
    path = store.path(job)
    path.write_text('{"key": "abc", "res')
    tally = Tally()
    (res,) = run_jobs([job], workers=1, progress=False, store=store, tally=tally)
    err = capsys.readouterr().err
    assert "not a store entry" in err and "refitting" in err and len(err.splitlines()) == 1
    assert tally.computed == 1 and json.loads(path.read_text())["result"] == res
    path.write_text('{"key": "abc", "res')
    assert main(["results", "verify", "--store", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    assert "INVALID probe_fit/" in captured.out
    assert len(captured.err.strip().splitlines()) == 1 and "not valid store entries" in captured.err


def _study(data: Path, cfg: Path, out: Path, store: Path, **kw) -> dict:
    inputs = StudyInputs(name="seed-noise", out=out, data=data, config=cfg, workers=1,
                         progress=False, store=str(store), **kw)
    return run_study(inputs).doc


def test_a_study_runs_again_from_the_store(tmp_path, tiny_study, capsys):
    data, cfg = tiny_study
    store = tmp_path / "results"
    first = _study(data, cfg, tmp_path / "a", store)
    n = first["sources"]["fitted"]
    assert n == 3 and first["sources"]["store"] == 0
    # each fit kept its resumable training state in the run folder, under its fit key
    assert len(list((tmp_path / "a" / "state").iterdir())) == n
    second = _study(data, cfg, tmp_path / "b", store)  # another sitting, another folder
    assert second["sources"] == {"run_cache": 0, "store": n, "fitted": 0}
    assert second["result"] == first["result"] and second["findings"] == first["findings"]
    refit = _study(data, cfg, tmp_path / "c", store, refit=True)
    assert refit["sources"] == {"run_cache": 0, "store": 0, "fitted": n}
    assert len(list((store / "fold_job").glob("*.json"))) == n  # overwritten, not added
    assert main(["results", "verify", "--store", str(store)]) == 0
    assert f"{n} fits and 0 parked states in {store}: all valid" in capsys.readouterr().out
    assert main(["results", "list", "--store", str(store), "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert len(listed["entries"]) == n and all(" current " in e for e in listed["entries"])
    entry = entries(store)[0][1]
    assert entry.provenance.config["model"]["state_units"] == 4  # the resolved NSS config
    assert entry.data_hash and entry.provenance.data == str(data)


def test_reproduce_reads_the_store_and_quick_runs_do_not_write(tmp_path, tiny_study, capsys):
    data, cfg = tiny_study
    store = tmp_path / "results"
    base = ["reproduce", "seed_noise", "--workers", "1", "--data", str(data), "--config",
            str(cfg), "--store", str(store), "--json"]
    assert main([*base, "--quick", "--out", str(tmp_path / "q")]) == 0
    quick = json.loads(capsys.readouterr().out)
    assert not store.exists() and quick["store_writes"] is False
    # the seed-noise fold's seeds and the per-fold floor fits of the other folds
    # (floor_seeds 0-2 on fold 0; the quick budget has one fold, the seed-noise fold's 2)
    assert quick["sources"]["seed_noise"]["fitted"] == 2 + 3
    assert main([*base, "--out", str(tmp_path / "a")]) == 0
    first = json.loads(capsys.readouterr().out)
    n = 3 + 3  # folds 0 and 1 of the full budget, three seeds each
    assert first["sources"]["seed_noise"] == {"run_cache": 0, "store": 0, "fitted": n}
    assert main([*base, "--out", str(tmp_path / "b")]) == 0
    captured = capsys.readouterr()
    second = json.loads(captured.out)
    assert second["sources"]["seed_noise"] == {"run_cache": 0, "store": n, "fitted": 0}
    assert f"{n} from the store, 0 fitted" in captured.err
    assert second["verdicts"] == first["verdicts"]
    run_json = json.loads((tmp_path / "b" / "run.json").read_text())
    assert run_json["sources"]["seed_noise"]["store"] == n
    assert main([*base, "--out", str(tmp_path / "c"), "--refit"]) == 0
    assert json.loads(capsys.readouterr().out)["sources"]["seed_noise"]["fitted"] == n


@pytest.mark.parametrize("argv", [["results", "list", "--store", "off"]])
def test_no_store_is_one_line(argv, capsys):
    assert main(argv) == 2
    assert "no result store" in capsys.readouterr().err


def test_table2_from_the_store_notes_the_missing_fold_model(tmp_path, tiny_study, capsys):
    data, cfg = tiny_study
    base = ["reproduce", "table2", "--workers", "1", "--data", str(data), "--config", str(cfg),
            "--store", str(tmp_path / "results"), "--json"]
    assert main([*base, "--out", str(tmp_path / "a")]) == 0
    first = json.loads(capsys.readouterr().out)
    n = first["sources"]["table2"]["fitted"]
    assert n > 0 and "fig5_rollouts.png" in first["files"]
    shutil.rmtree(tmp_path / "a")  # the fold models are gone; the store keeps no weights
    assert main([*base, "--out", str(tmp_path / "b")]) == 0
    second = json.loads(capsys.readouterr().out)
    assert second["sources"]["table2"] == {"run_cache": 0, "store": n, "fitted": 0}
    assert "fig5_rollouts.png" not in second["files"]
    assert "Fig. 5 is not drawn" in (tmp_path / "b" / "report.html").read_text()


def test_an_nss_fit_is_keyed_by_the_config_it_resolves_to(tmp_path):
    store = _store(tmp_path)
    fold = "parknss.experiments.folds:fold_job"

    def key(overrides, **kw):
        return store.entry_key(Job(fold, {"split": "cv", "index": 0, "model": "nss",
                                          "overrides": overrides, **kw}))[0]  # fmt: skip

    paper = key({})
    assert key({"train": {"epochs": 3200}}) == paper  # the shipped default, spelled out
    assert key({}, save_dir="a", state_dir="b", progress=True) == paper
    assert key({"train": {"threads": 2}}) == paper  # threads do not change the numbers
    assert key({"fast": {"batch": 7}}) == paper  # nor the fast section, for a paper fit
    assert key({"train": {"epochs": 3000}}) != paper
    fast = key({"train": {"recipe": "fast"}})
    assert fast != paper and key({"train": {"recipe": "fast"}, "fast": {"batch": 7}}) != fast
    assert key({"coarse": {"factor": 4}}) == paper  # a section its recipe does not read
    assert key({"train": {"recipe": "fast"}, "coarse": {"factor": 4}}) == fast
    coarse = key({"train": {"recipe": "coarse"}})
    assert coarse not in (paper, fast)
    assert key({"train": {"recipe": "coarse"}, "coarse": {"factor": 4}}) != coarse


def test_time_to_accuracy_shares_the_paper_fits_with_table2(tmp_path, tiny_study, capsys):
    data, cfg = tiny_study
    base = ["--workers", "1", "--data", str(data), "--config", str(cfg),
            "--store", str(tmp_path / "results"), "--json"]  # fmt: skip
    assert main(["reproduce", "table2", *base, "--out", str(tmp_path / "a")]) == 0
    capsys.readouterr()
    stored = len(entries(tmp_path / "results"))
    # --stored-only fits nothing: the fast fits are missing, so the artefact is not measured
    assert main(["reproduce", "time_to_accuracy", *base, "--stored-only",
                 "--out", str(tmp_path / "s")]) == 0  # fmt: skip
    only = json.loads(capsys.readouterr().out)
    assert list(only["verdicts"].values()) == ["not measured"]
    assert len(entries(tmp_path / "results")) == stored
    assert "6 of 8 fits" in (tmp_path / "s" / "report.html").read_text()
    assert main(["reproduce", "time_to_accuracy", *base, "--out", str(tmp_path / "b")]) == 0
    doc = json.loads(capsys.readouterr().out)
    # the paper recipe's fold fits are Table II's (same resolved config): read, not refitted
    assert doc["sources"]["time_to_accuracy"] == {"run_cache": 0, "store": 2, "fitted": 6}
    assert "time_to_accuracy.png" in doc["files"]
    fast = [e for _, e in entries(tmp_path / "results")
            if not isinstance(e, str) and e.kwargs["nss"]["train"].get("recipe") == "fast"]
    assert len(fast) == 2 and all(e.result["recipe"] == "fast" for e in fast)
    coarse = [e for _, e in entries(tmp_path / "results")
              if not isinstance(e, str) and e.kwargs["nss"]["train"].get("recipe") == "coarse"]
    assert len(coarse) == 4 and all(e.result["recipe"] == "coarse" for e in coarse)
    native = [e for e in coarse if e.kwargs["nss"].get("model", {}).get("fused_kernels")]
    assert len(native) == 2  # the coarse+native challenger: its own fits, keyed apart
    assert all(e.kwargs["nss"]["model"]["fused_kernels"] == "native" for e in native)
    hist = fast[0].result["history"]
    assert len(hist["cpu_s"]) == len(hist["raw"]) and fast[0].result["cpu_s"] > 0.0
    assert main(["reproduce", "time_to_accuracy", *base, "--stored-only",
                 "--out", str(tmp_path / "t")]) == 0  # fmt: skip
    again = json.loads(capsys.readouterr().out)  # now the store holds it all
    assert again["sources"]["time_to_accuracy"] == {"run_cache": 0, "store": 8, "fitted": 0}
    assert "not measured" not in again["verdicts"].values()
    off = [*base[:-3], "--store", "off", "--stored-only", "--out", str(tmp_path / "u")]
    assert main(["reproduce", "time_to_accuracy", *off]) != 0
    assert "--stored-only reads the result store" in capsys.readouterr().err


def test_sweep_fold_jobs_keep_their_training_state(tmp_path):
    from parknss.experiments.sweep import Sweep, fold_spec

    plain = fold_spec(Sweep(), "cv", 1, {"train": {"epochs": 5}})
    kept = fold_spec(Sweep(state_root=tmp_path), "cv", 1, {"train": {"epochs": 5}})
    assert "state_dir" not in plain.kwargs
    assert kept.kwargs["state_dir"] == str(tmp_path / fit_key(FOLD_JOB, plain.kwargs))
    other = fold_spec(Sweep(state_root=tmp_path), "cv", 2, {"train": {"epochs": 5}})
    assert other.kwargs["state_dir"] != kept.kwargs["state_dir"]
    store = _store(tmp_path)  # where the state is kept does not decide the numbers
    assert store.entry_key(kept)[0] == store.entry_key(plain)[0]
    probe = fold_spec(Sweep(state_root=tmp_path), "cv", 1, {}, fn=PROBE)
    assert "state_dir" not in probe.kwargs  # only fold jobs take one


def test_a_fit_keeps_its_state_folder_under_any_spelling_and_loses_it_when_retuned(tmp_path):
    from parknss.experiments.sweep import Sweep, fold_spec

    sw = Sweep(state_root=tmp_path)

    def state(overrides):
        return fold_spec(sw, "cv", 1, overrides).kwargs["state_dir"]

    paper = state({})
    assert state({"train": {"epochs": 3200, "recipe": "paper"}}) == paper  # defaults spelled
    assert state({"fast": {"window": 64}}) == paper  # a paper fit does not read the fast section
    fast = state({"train": {"recipe": "fast"}})
    assert fast != paper
    assert state({"train": {"recipe": "fast"}, "fast": {"window": 64}}) != fast  # retuned


def test_time_to_accuracy_of_two_known_curves():
    from parknss.errors import DataError
    from parknss.experiments.sweep import FoldScore
    from parknss.experiments.time_to_accuracy import Challenger, Curve, FoldTTA, TTAResult

    def fit(cpu, smooth):
        return {"history": {"raw": smooth, "smooth": smooth, "cpu_s": cpu}, "cpu_s": cpu[-1]}

    paper = Curve.from_result(fit([100.0, 400.0, 800.0], [0.3, 0.2, 0.1]))
    fast = Curve.from_result(fit([10.0, 20.0, 50.0], [0.2, 0.1, 0.08]))
    coarse = Curve.from_result(fit([5.0, 40.0, 100.0], [0.09, 0.2, 0.2]))
    score = FoldScore(1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1, 12)
    f = FoldTTA(0, paper, score, [Challenger("fast", fast, score),
                                  Challenger("coarse", coarse, score)])
    assert (f.target, f.reach_cpu_s("fast")) == (0.1, 20.0)  # the fast fit's first point at 0.1
    assert (f.speedup_reach("fast"), f.speedup_total("fast")) == (40.0, 16.0)
    assert (f.reach_cpu_s("coarse"), f.speedup_reach("coarse"), f.speedup_total("coarse")) == (
        5.0, 160.0, 8.0)
    assert TTAResult([f], 8.0).met() and TTAResult([f], 50.0).met()  # coarse: 160x
    assert TTAResult([f], 50.0).met_by("coarse") and not TTAResult([f], 50.0).met_by("fast")
    assert not TTAResult([f], 200.0).met()
    doc = f.to_json()
    assert doc["paper"]["best"] == 0.1 and doc["challengers"]["fast"]["curve"]["best"] == 0.08
    assert doc["paper"]["best_cpu_s"] == 800.0 and doc["challengers"]["coarse"]["reach_cpu_s"] == 5
    assert TTAResult([f], 50.0).to_json()["met_by"] == ["coarse"]
    rows = TTAResult([f], 8.0).rows()
    assert [r[:2] for r in rows] == [["fold 0", "fast"], ["fold 0", "coarse"]]
    # a paper fit that peaks early: the speed-up is against its CPU time to its best
    early = Curve.from_result(fit([100.0, 400.0, 800.0], [0.3, 0.1, 0.2]))
    e = FoldTTA(0, early, score, [Challenger("fast", fast, score)])
    assert (early.best_cpu_s, e.reach_cpu_s("fast")) == (400.0, 20.0)
    assert (e.speedup_reach("fast"), e.speedup_total("fast")) == (20.0, 16.0)
    assert TTAResult([e], 20.0).met() and not TTAResult([e], 21.0).met()
    slow = FoldTTA(0, fast, score, [Challenger("fast", paper, score)])  # never reaches 0.08
    assert slow.reach_cpu_s("fast") is None and not TTAResult([slow], 1.0).met()
    assert "not reached" in TTAResult([slow], 1.0).rows()[0][11]
    old = fit([10.0, 20.0], [0.2, 0.1])
    old["history"]["cpu_s"] = [None, None]
    with pytest.raises(DataError, match="no CPU times"):
        Curve.from_result(old)


def test_progress_names_each_fit_of_a_run_folder_from_its_plan(tmp_path, tiny_study, capsys):
    from parknss.errors import ConfigError
    from parknss.experiments.studies import run_progress_of

    data, cfg = tiny_study
    _study(data, cfg, tmp_path / "a", tmp_path / "results")
    rows = run_progress_of(tmp_path / "a")
    assert sorted(r.name for r in rows) == ["seed 0", "seed 1", "seed 2"]
    assert all(r.done and r.step == r.steps == 2 and r.cpu_s > 0 for r in rows)
    assert all(r.phases == [("paper", 2)] and r.cpu_left_s == 0.0 for r in rows)  # done
    assert all(r.rates["paper"] == pytest.approx(r.cpu_s / 2, rel=0.2) for r in rows)
    assert main(["study", "progress", str(tmp_path / "a")]) == 0
    assert "3 fits with a training state, 3 done" in capsys.readouterr().out
    (tmp_path / "a" / "state" / rows[0].folder / "train_state.json").write_text("{")
    bad = next(r for r in run_progress_of(tmp_path / "a") if r.folder == rows[0].folder)
    assert bad.error.startswith("JSONDecodeError") and not bad.done
    queued = tmp_path / "a" / "state" / rows[1].folder
    (queued / "train_state.json").unlink()  # labelled by the executor, not yet started
    (queued / "job.json").write_text("{}")
    q = next(r for r in run_progress_of(tmp_path / "a") if r.folder == rows[1].folder)
    assert q.queued and not q.error and not q.done and q.cpu_left_s is None
    assert main(["study", "progress", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "not started" in out and "2 fits with a training state, 1 done, 1 queued" in out
    with pytest.raises(ConfigError, match="not a run folder manifest"):
        run_progress_of(tmp_path / "nowhere")


def test_cpu_left_prices_each_phase_at_its_own_cost_per_step():
    from parknss.experiments.progress import FitProgress, borrow_rates, phase_rates

    paper = FitProgress("f", "seed 1", step=50, steps=200, cpu_s=100.0,
                        phases=[("paper", 200)], rates={"paper": 2.0})
    assert paper.cpu_left_s == 300.0 and paper.to_json()["cpu_left_s"] == 300.0
    assert " 300 " in paper.line()
    assert FitProgress("f", "?", step=50, cpu_s=100.0).cpu_left_s is None  # plan unknown
    new = FitProgress("f", "new", steps=200, phases=[("paper", 200)], rates={"paper": 2.0})
    assert new.cpu_left_s is None  # not started
    # a fast fit: 20 updates at 1 s, then 5 finish epochs at 4 s (cumulative CPU per row)
    rows = [{"epoch": k, "phase": "short", "cpu_s": 1.0 * k} for k in range(1, 21)]
    rows += [{"epoch": 20 + k, "phase": "full", "cpu_s": 20.0 + 4.0 * k} for k in (1, 2)]
    assert phase_rates(rows) == {"short": 1.0, "full": 4.0}
    assert phase_rates([{"cpu_s": 3.0}, {"cpu_s": 5.0}]) == {"paper": 2.5}
    assert phase_rates([{"phase": "short"}, {"phase": "short", "cpu_s": 9.0}]) == {}
    phases = [("short", 20), ("full", 5)]
    done = FitProgress("a", "fast f0", step=22, steps=25, cpu_s=28.0, phases=phases,
                       rates=phase_rates(rows), engine=("rk4", "eager"))
    assert done.steps_left() == {"short": 0, "full": 3} and done.cpu_left_s == 12.0
    early = FitProgress("b", "fast f1", step=5, steps=25, cpu_s=10.0, phases=phases,
                        rates={"short": 2.0}, engine=("rk4", "eager"))
    other = FitProgress("c", "fast f2", step=5, steps=25, cpu_s=10.0, phases=phases,
                        rates={"short": 2.0}, engine=("euler", "eager"))
    assert early.cpu_left_s is None  # its finish epochs have no measured cost yet
    borrow_rates([done, early, other])
    assert early.borrowed == ["full"] and early.cpu_left_s == 15 * 2.0 + 5 * 4.0
    assert "~50 " in early.line() and not done.borrowed
    assert other.cpu_left_s is None and not other.borrowed  # no fit of its engine ran it


def test_the_listing_gives_a_resumed_fit_its_whole_cpu_time(tmp_path):
    from parknss.experiments.jobs import LIMITER_JOB
    from parknss.experiments.store import fit_cpu_s, listing

    store = _store(tmp_path)
    # a fit resumed from its training state: its result holds the whole fit's CPU time
    store.put(_job(1), {"seed": 1, "cpu_s": 3696.5}, 2579.3, 1504.0)
    store.put(_job(2), {"seed": 2, "cpu_s": 12.0}, 13.0, 12.0)  # not resumed: one number
    rows, bad = listing(tmp_path)
    assert not bad and len(rows) == 2
    assert any("cpu 1504.0 s (fit 3696 s; earlier sittings not recorded)" in r for r in rows)
    assert any("cpu 12.0 s  " in r and "(fit" not in r for r in rows)
    # a limiter result carries its fit as the fold result it answers (ALIASES)
    assert fit_cpu_s(LIMITER_JOB, {"fold": {"cpu_s": 3696.5}, "cpu_s": 1.0}) == 3696.5
    assert fit_cpu_s(FOLD_JOB, {"cpu_s": 5}) == 5.0 and fit_cpu_s(FOLD_JOB, {"a": 1}) is None
    assert fit_cpu_s(FOLD_JOB, [1, 2]) is None and fit_cpu_s(LIMITER_JOB, {"fold": None}) is None


def test_a_dirty_entry_says_whether_its_code_is_its_revisions():
    """``results list``/``verify`` compare a dirty fit's recorded code version with the
    training code committed at its revision (git, mechanically)."""
    import subprocess

    from parknss.experiments.store import Machine, Provenance, StoreEntry, dirty_note
    from parknss.experiments.store import revision_code_version as at_rev

    head = subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    if not head:
        pytest.skip("not a git checkout")
    committed = at_rev(head)
    assert committed is not None and len(committed) == 16

    def entry(code: str, rev: str, dirty: bool = True) -> StoreEntry:
        prov = Provenance(rev, dirty, Machine("p", "cpu", 1), "3.11", "2", 1.0, 1.0, "t",
                          None, None)
        return StoreEntry("k", FOLD_JOB, {}, "n", "d", code, {}, prov)

    assert dirty_note(entry(committed, head)) == "code as committed"
    assert dirty_note(entry("0" * 16, head)) == "code not as committed"
    assert dirty_note(entry(committed, "f" * 40)) == "revision unknown here"
    assert dirty_note(entry(committed, head, dirty=False)) == ""


def test_time_to_accuracy_challengers_are_recipes_optionally_with_kernels(tmp_path):
    from parknss.errors import ConfigError
    from parknss.experiments.config import load_experiments_config
    from parknss.experiments.time_to_accuracy import challenger_overrides

    assert "coarse+native" in load_experiments_config().full.tta_recipes
    assert challenger_overrides("fast") == {"train": {"recipe": "fast"}}
    assert challenger_overrides("coarse+native") == {"train": {"recipe": "coarse"},
                                                     "model": {"fused_kernels": "native"}}
    for bad, msg in [("[paper]", "'paper' is not fast or coarse"),
                     ("[coarse+turbo]", "'coarse\\+turbo' is not"),
                     ("[coarse, coarse]", "named twice")]:
        path = tmp_path / "e.yaml"
        path.write_text(f"full:\n  tta_recipes: {bad}\n")
        with pytest.raises(ConfigError, match=msg):
            load_experiments_config(path)
