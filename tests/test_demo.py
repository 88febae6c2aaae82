"""`parknss demo` needs the shipped plant: a missing artefact is one line and exit 2."""

from __future__ import annotations

from parknss.cli import main
from parknss.config import SHIPPED_CHAIN, SHIPPED_NSS


def test_demo_names_a_missing_shipped_model(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path / "run"), "--nss", str(tmp_path / "no_nss")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "no_nss" in err[0] and "shipped NSS model is missing" in err[0]


def test_the_shipped_plant_is_in_the_checkout():
    # the demo (README's main job) runs on these; they are committed artefacts
    assert (SHIPPED_NSS / "model.json").is_file() and (SHIPPED_NSS / "model.safetensors").is_file()
    assert (SHIPPED_CHAIN / "chain.json").is_file()


def test_summary_is_tidy_and_keyed_by_plant():
    """summary.json's pieces: floats at 6 significant digits, no horizon nulls for the
    chain (it has no training window), the closed loop keyed by plant with no plant's
    numbers at the top level."""
    import math

    from parknss.chain.deployed import load_chain
    from parknss.config import BUNDLED_CAMPAIGN
    from parknss.data.io import read_campaign
    from parknss.experiments.demo import _errors, closed_loop_doc, summary_text, tidy
    from parknss.sim.session import simulate_scene

    assert tidy({"a": [3.1100000000000003, 1], "b": {"c": 2.0 / 3.0}, "d": None}) == {
        "a": [3.11, 1], "b": {"c": 0.666667}, "d": None}
    trials = list(read_campaign(BUNDLED_CAMPAIGN))[:1]
    errs = _errors(load_chain(SHIPPED_CHAIN).predict_trials(trials), trials, None)
    assert set(errs) == {"logged", "truth"}
    for e in errs.values():
        assert "vx_mse_within_kmh2" not in e and "horizon" not in e
        assert "within" not in e["counts"]
        assert all(v is not None for v in e.values())
        assert math.isfinite(e["vx_mse_moving_kmh2"])
    run = simulate_scene("26", ["kinematic"])
    cl = closed_loop_doc(run)
    assert set(cl["runs"]) == {"kinematic"} and "goal_error_cm" not in cl
    assert cl["runs"]["kinematic"]["completed"] and cl["scene"] == "angled-left-t1-open"
    text = summary_text({"nss": {}, "chain": errs, "closed_loop": cl})
    assert "kinematic" in text and "chain vs truth channels" in text


def test_demo_json_prints_one_document(tmp_path, capsys, monkeypatch):
    """--json: stdout is exactly the summary document; progress and tables go to stderr."""
    import json

    import parknss.experiments.demo as demo

    def fake(inputs, log, show):
        log("progress line")
        show("a table")
        return {"wall_s": 1.0, "closed_loop": {"runs": {}}}

    monkeypatch.setattr(demo, "run_demo", fake)
    assert main(["demo", "--out", str(tmp_path / "run"), "--json"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out) == {"wall_s": 1.0, "closed_loop": {"runs": {}}}
    assert "a table" in cap.err and "progress line" in cap.err
