"""``parknss fidelity`` (parknss.experiments.fidelity): one cell under chain and truth,
the run folder, its resume and the refusals."""

from __future__ import annotations

import json

import pytest

from parknss.cli import main
from parknss.errors import ConfigError
from parknss.experiments.fidelity import fidelity_specs


def test_one_cell_is_scored_drawn_reported_and_resumed(tmp_path, capsys):
    out = tmp_path / "fid"
    assert main(["fidelity", "--scene", "26", "--out", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (cell,) = doc["per_cell"]
    c = cell["fidelity"]
    assert cell["plannable"] and cell["seed"] != 0
    assert c["truth_reason"] == "completed"
    assert c["duration_ratio"] == pytest.approx(c["chain_duration_s"] / c["truth_duration_s"])
    assert 0 <= c["iso_vx"] <= 1 and 0 <= c["iso_yaw_rate"] <= 1
    s = doc["summary"]
    assert s["executed"] == 1 and len(s["targets"]) == 7
    assert s["duration_dev_median"] == pytest.approx(abs(c["duration_ratio"] - 1))
    for name in ("fidelity.json", "fidelity_cells.csv", "fidelity.md", "fidelity.html"):
        assert (out / name).is_file()
    assert (out / "cells" / f"fidelity_{cell['scene']}.png").stat().st_size > 10_000
    assert "fidelity_" in (out / "fidelity.html").read_text()
    # the same run again: every cell from the run folder's cache, the same numbers
    assert main(["fidelity", "--scene", "26", "--out", str(out), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["per_cell"] == doc["per_cell"]
    # another run into the same folder is refused in one line
    assert main(["fidelity", "--scene", "25", "--out", str(out)]) == 2
    assert "parknss: error:" in capsys.readouterr().err


def test_scene_sources(tmp_path):
    assert fidelity_specs(grid="36", cells="0-2") == ["0", "1", "2"]
    assert fidelity_specs(grid="252", cells="5") == ["robust:5"]
    for n in (10, 2, 1):
        (tmp_path / f"Case{n}.csv").write_text("")
    (tmp_path / "notes.csv").write_text("")
    names = [p.rsplit("/", 1)[1] for p in fidelity_specs(tpcap=tmp_path)]
    assert names == ["Case1.csv", "Case2.csv", "Case10.csv"]
    with pytest.raises(ConfigError):
        fidelity_specs(grid="36", scenes=["3"])
    with pytest.raises(ConfigError):
        fidelity_specs()
    with pytest.raises(ConfigError):
        fidelity_specs(tpcap=tmp_path / "empty")


def test_the_ceiling_scores_the_truth_against_itself_under_another_seed(tmp_path, capsys):
    out = tmp_path / "ceil"
    args = ["fidelity", "--scene", "26", "--candidate", "reference", "--no-figures"]
    assert main([*args, "--out", str(out), "--json"]) == 0
    c = json.loads(capsys.readouterr().out)["per_cell"][0]["fidelity"]
    assert c["chain_reason"] == c["truth_reason"] == "completed"
    assert c["gear_sequence_agree"] and abs(c["duration_ratio"] - 1) < 0.05
    assert 0.5 < c["iso_vx"] < 1.0  # another noise draw: close, never identical
    assert main(["fidelity", "--scene", "26", "--candidate", "kinematic", "--out",
                 str(tmp_path / "bad")]) == 2  # fmt: skip
    assert "--candidate" in capsys.readouterr().err
