"""The store's lineage and content digests (parknss.experiments.lineage, store): fits of a
code version recorded equivalent are answered; others stay stale; a tampered score is
reported; resumed fits record every sitting."""

from __future__ import annotations

import json
from pathlib import Path

from parknss.cli import main
from parknss.executor import Job
from parknss.experiments.lineage import (
    CanaryRecord,
    accepted_versions,
    migrate,
    read_lineage,
)
from parknss.experiments.store import ResultStore, entries, listing, seal
from parknss.nss.train_state import FORMAT, META

PROBE = "parknss.experiments.probe:probe_fit"


def _can(digest: str, cpu: str = "CPU A", spec: str = "s1") -> CanaryRecord:
    return CanaryRecord(digest, spec, cpu, "linux", "3.11", "2.13", "rev", "t", 1.0)


def _store(root: Path, code: str) -> ResultStore:
    store = ResultStore(root, log=lambda msg: None)
    store.code = code
    store._data_hashes[None] = "d0"
    return store


def test_equivalence_needs_the_same_digest_cpu_and_spec_and_is_transitive(tmp_path):
    migrate(tmp_path, "v0", _can("aaa"))
    assert migrate(tmp_path, "v1", _can("aaa", cpu="CPU B")).equivalent == []  # other CPU
    assert migrate(tmp_path, "v2", _can("aaa", spec="s2")).equivalent == []  # other canary
    m = migrate(tmp_path, "v3", _can("bbb"))
    assert m.equivalent == [] and m.differs == {"v0": "aaa"} and m.accepted == ["v3"]
    assert migrate(tmp_path, "v4", _can("aaa")).accepted == ["v4", "v0"]
    # v5 equals v4 on CPU B only: still reaches v0 through v4
    migrate(tmp_path, "v4", _can("ccc", cpu="CPU B"))
    assert migrate(tmp_path, "v5", _can("ccc", cpu="CPU B")).accepted == ["v5", "v0", "v4"]
    assert accepted_versions(tmp_path, "v3") == ["v3"]
    assert sorted(read_lineage(tmp_path)) == ["v0", "v1", "v2", "v3", "v4", "v5"]


def test_the_store_answers_from_an_equivalent_version_only(tmp_path):
    job = Job(PROBE, {"seed": 0, "steps": 20}, name="probe 0")
    old = _store(tmp_path, "v0")
    old.put(job, {"a": 0.5}, 1.0, 1.0)
    assert old.get(job) == (True, {"a": 0.5})
    assert _store(tmp_path, "v1").get(job) == (False, None)  # new code, no lineage
    migrate(tmp_path, "v0", _can("aaa"))
    migrate(tmp_path, "v1", _can("bbb"))  # numerics changed
    assert _store(tmp_path, "v1").get(job) == (False, None)
    migrate(tmp_path, "v2", _can("aaa"))
    new = _store(tmp_path, "v2")
    assert new.get(job) == (True, {"a": 0.5})
    rows, bad = listing(tmp_path)  # this checkout's code is none of v0..v2: stale
    assert not bad and " stale " in rows[0]


def test_verify_reports_a_tampered_score_and_seal_adds_missing_digests(tmp_path, capsys):
    job = Job(PROBE, {"seed": 0, "steps": 20}, name="probe 0")
    _store(tmp_path, "v0").put(job, {"a": 0.5}, 1.0, 1.0)
    assert main(["results", "verify", "--store", str(tmp_path)]) == 0
    (p, _e), = entries(tmp_path)
    doc = json.loads(p.read_text())
    doc["result"]["a"] = 0.25  # a score edited by hand
    p.write_text(json.dumps(doc))
    assert main(["results", "verify", "--store", str(tmp_path)]) == 2
    assert "edited after it was stored" in capsys.readouterr().err
    assert _store(tmp_path, "v0").get(job) == (False, None)  # and the lookup refits it
    del doc["digest"]  # an entry stored before digests: verify asks for seal, seal adds it
    p.write_text(json.dumps(doc))
    assert "no content digest" in entries(tmp_path)[0][1]
    assert seal(tmp_path) == (1, 0) and seal(tmp_path) == (0, 1)
    assert main(["results", "verify", "--store", str(tmp_path)]) == 0


def test_a_resumed_fit_records_every_sitting(tmp_path):
    state = tmp_path / "run" / "state" / "f"
    job = Job(PROBE, {"seed": 0, "steps": 20, "state_dir": str(state)}, name="probe 0")
    store = _store(tmp_path / "store", "v0")
    store.resume(job)
    (state / META).write_text(json.dumps({"format": FORMAT, "epoch": 7}))
    store.resume(job)  # a second sitting, from step 7 (the state's step as read_step reads it)
    store.put(job, {"a": 0.5}, 1.0, 1.0)
    (_p, e), = entries(tmp_path / "store")
    rows = e.provenance.sittings
    assert [r["from_step"] for r in rows] == [0, 7]
    assert {"machine", "python", "torch", "git_revision", "code_version"} <= set(rows[0])


def test_migrate_command_exits_2_when_the_numbers_change(tmp_path, monkeypatch, capsys):
    from parknss.experiments import canary
    from parknss.experiments.store import Machine

    migrate(tmp_path, "v0", _can("aaa", cpu=Machine.here().cpu, spec=canary.spec_digest()))
    for digest, rc in (("bbb", 2), ("aaa", 0)):
        res = canary.CanaryResult(digest, {"x": digest}, canary.spec_digest(), 0.1)
        monkeypatch.setattr(canary, "run_canary", lambda res=res: res)
        assert main(["results", "migrate", "--store", str(tmp_path)]) == rc
    out = capsys.readouterr().out
    assert "differs from the canary of v0" in out and "equals the canary of v0" in out
