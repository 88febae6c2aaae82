"""The report's stored results that are not fits (parknss.experiments.derived): their
store keys follow the content of what they read (chain bytes, configs), a tampered
entry is refused, and a ladder job refuses a chain without a recorded selection."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from parknss import durable
from parknss.cli import main
from parknss.config import SHIPPED_CHAIN
from parknss.errors import CheckpointError, ConfigError
from parknss.executor import Job
from parknss.experiments.derived import ladder_inputs, recorded_selection
from parknss.experiments.store import (
    DERIVED,
    NO_DATA,
    PACKAGE_DIR,
    ResultStore,
    entries,
    job_code_version,
)

CELL = "parknss.sim.grid:cell_job"


def _chain(tmp_path: Path) -> Path:
    dst = tmp_path / "chain"
    shutil.copytree(SHIPPED_CHAIN, dst)
    return dst


def _cell(closed_loop: Path, **extra) -> Job:
    kw = {"grid": "36", "index": 0, "plants": ["kinematic", "chain"],
          "closed_loop_config": str(closed_loop), "interface_config": None,
          "interface_overrides": None, "planning_config": None, "scenarios_config": None,
          "vehicle": None, **extra}
    return Job(CELL, kw, name="cell 0")


def _key(tmp_path: Path, job: Job) -> str:
    return ResultStore(tmp_path / "store", log=lambda m: None).entry_key(job)[0]


def test_derived_code_globs_name_files():
    for d in DERIVED.values():
        for pattern in d.code:  # a renamed file must be renamed in the table too
            assert list(PACKAGE_DIR.glob(pattern)), pattern


def test_a_cell_key_follows_the_chain_bytes_and_the_configs(tmp_path):
    chain = _chain(tmp_path)
    yaml = tmp_path / "closed_loop.yaml"
    yaml.write_text(f"chain_path: {chain}\n")
    job = _cell(yaml)
    store = ResultStore(tmp_path / "store", log=lambda m: None)
    k1, kw, dh = store.entry_key(job)
    assert dh == NO_DATA and kw["inputs"]["chain"].startswith("sha256:")
    assert _key(tmp_path, job) == k1  # the same inputs: the same key
    # another chain (re-saved with its manifest): another key
    meta = chain / "chain.json"
    meta.write_text(meta.read_text() + "\n")
    durable.write_manifest(chain)
    k2 = _key(tmp_path, job)
    assert k2 != k1
    # a chain edited behind its manifest is refused, not keyed
    meta.write_text(meta.read_text() + "\n")
    with pytest.raises(CheckpointError):
        _key(tmp_path, job)
    durable.write_manifest(chain)
    k3 = _key(tmp_path, job)
    # a config value: another key; the same values spelled in another file: the same
    yaml.write_text(f"chain_path: {chain}\nplant_seed: 7\n")
    assert _key(tmp_path, job) != k3
    other = tmp_path / "same.yaml"
    other.write_text(f"chain_path: {chain}\nplant_seed: 7\n")
    assert (ResultStore(tmp_path / "s", log=lambda m: None).entry_key(_cell(other))[1]["inputs"]
            == ResultStore(tmp_path / "s", log=lambda m: None).entry_key(job)[1]["inputs"])
    assert _key(tmp_path, _cell(yaml, interface_overrides={"kp": 2.0})) != \
        _key(tmp_path, job)
    assert job_code_version(CELL) != job_code_version("parknss.experiments.folds:fold_job")


def test_a_ladder_key_holds_the_chain_the_nss_and_the_actuator_config(tmp_path):
    chain = _chain(tmp_path)
    a = ladder_inputs({"chain": str(chain)})
    assert set(a) == {"chain", "nss", "actuators"}
    meta = chain / "chain.json"
    doc = json.loads(meta.read_text())
    doc["build"]["selection"]["drive"] = "drive/gru/phys"
    meta.write_text(json.dumps(doc))
    durable.write_manifest(chain)
    b = ladder_inputs({"chain": str(chain)})
    assert b["chain"] != a["chain"] and b["nss"] == a["nss"]
    assert recorded_selection(chain)["drive"] == "drive/gru/phys"
    del doc["build"]["selection"]
    meta.write_text(json.dumps(doc))
    durable.write_manifest(chain)
    with pytest.raises(ConfigError, match="records no Phase B selection"):
        recorded_selection(chain)


def test_a_tampered_cell_entry_is_refused_by_verify_and_the_store(tmp_path, capsys):
    chain = _chain(tmp_path)
    yaml = tmp_path / "closed_loop.yaml"
    yaml.write_text(f"chain_path: {chain}\n")
    job = _cell(yaml)
    root = tmp_path / "store"
    logged: list[str] = []
    store = ResultStore(root, log=logged.append)
    rows = [{"plant": "kinematic", "goal_error_cm": 3.5, "completed": True}]
    store.put(job, rows, 1.0, 1.0)
    (path, entry), = entries(root)
    assert not isinstance(entry, str) and entry.result == rows
    assert store.get(job) == (True, rows)
    assert main(["results", "verify", "--store", str(root)]) == 0
    listed = capsys.readouterr().out
    assert "1 fits" in listed
    assert main(["results", "list", "--store", str(root)]) == 0
    assert " current " in capsys.readouterr().out  # its code and inputs are this checkout's
    doc = json.loads(path.read_text())
    doc["result"][0]["goal_error_cm"] = 1.0  # a better score, edited in
    path.write_text(json.dumps(doc))
    assert "does not match its digest" in entries(root)[0][1]
    assert main(["results", "verify", "--store", str(root)]) == 2
    assert "not valid store entries" in capsys.readouterr().err
    assert store.get(job) == (False, None) and "ignored, refitting" in logged[-1]
