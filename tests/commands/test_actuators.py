"""``parknss actuators`` study / build / ladder / stress: --json smoke tests with tiny
budgets, and one-line user errors."""

from __future__ import annotations

import json

import pytest
import torch
import yaml

from helpers.actuators import tiny_config
from parknss.cli import main
from parknss.data.io import write_campaign
from parknss.nss.checkpoint import save_model

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def env(tmp_path_factory, actuator_campaign, actuator_nss):
    root = tmp_path_factory.mktemp("act")
    write_campaign(actuator_campaign, root / "data")
    model, cfg = actuator_nss
    save_model(root / "nss", model, cfg, {})
    (root / "act.yaml").write_text(yaml.safe_dump(json.loads(tiny_config().model_dump_json())))
    return root


def _run(capsys, args):
    code = main(args)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_study_build_stress_json(env, capsys):
    base = ["--nss", str(env / "nss"), "--data", str(env / "data"), "--config",
            str(env / "act.yaml")]
    code, out, _ = _run(capsys, ["actuators", "study", *base, "--out", str(env / "study"),
                                 "--json"])
    assert code == 0
    doc = json.loads(out)
    assert {"phase_a", "phase_b", "winners", "cotune", "fig6", "selected_variants"} <= set(doc)
    assert len(doc["phase_a"]) == 3 * 2 * 2 + 2  # 3 channels x 2 archs x 2 variants + narx1s
    assert set(doc["winners"]) == {"drive", "brake", "steering"}
    assert (env / "study" / "fig6_fidelity.png").is_file()
    assert (env / "study" / "fig3_replay.png").is_file()
    sel = env / "study" / "selection.json"
    code, out, _ = _run(capsys, ["actuators", "build", *base, "--selection", str(sel),
                                 "--out", str(env / "chain"), "--json"])
    assert code == 0
    doc = json.loads(out)
    assert {"all_measured", "signal_target", "cotuned_target", "static_affine"} <= set(doc["rows"])
    assert (env / "chain" / "chain.json").is_file()
    code, out, _ = _run(capsys, ["actuators", "stress", "--chain", str(env / "chain"),
                                 "--data", str(env / "data"), "--config", str(env / "act.yaml"),
                                 "--json"])
    assert code == 0
    doc = json.loads(out)
    assert doc["ok"] and {r["scenario"] for r in doc["rows"]} >= {"nan", "inf", "torque_x3"}


def test_ladder_json_has_every_row(env, capsys, tmp_path):
    sel = tmp_path / "sel.json"
    sel.write_text(json.dumps({"winners": {"drive": "drive/lag1/uniform",
                                           "brake": "brake/lag1/cmd",
                                           "steering": "steering/lag1/cmd"}}))
    code, out, _ = _run(capsys, ["actuators", "ladder", "--nss", str(env / "nss"), "--data",
                                 str(env / "data"), "--config", str(env / "act.yaml"),
                                 "--selection", str(sel), "--json"])
    assert code == 0
    rows = json.loads(out)["rows"]
    assert set(rows) == {"all_measured", "selected_assembly", "signal_target",
                         "cotuned_target", "static_affine", "monolithic"}


@pytest.mark.parametrize("args,msg", [
    (["actuators", "build", "--nss", "/nonexistent", "--out", "/tmp/x"], "model file not found"),
    (["actuators", "stress", "--chain", "/nonexistent"], "chain folder not found"),
])
def test_user_errors_are_one_line(capsys, args, msg):
    code, _, err = _run(capsys, args)
    assert code == 2
    assert msg in err and err.count("\n") == 1


def test_bad_selection_file_is_a_one_line_error(env, capsys, tmp_path):
    bad = tmp_path / "sel.json"
    bad.write_text("{}")
    code, _, err = _run(capsys, ["actuators", "build", "--nss", str(env / "nss"), "--data",
                                 str(env / "data"), "--selection", str(bad), "--out",
                                 str(tmp_path / "c")])
    assert code == 2 and "no winners" in err


@pytest.mark.slow
def test_phase_a_through_a_process_pool_equals_in_process(env, actuator_config):
    """The study's Phase A fits are executor jobs: a 2-worker pool gives the very models
    and scores the in-process run gives (each fit seeds itself from its name)."""
    from parknss.actuators.envelopes import identify_envelope
    from parknss.actuators.phase_a import Fanout, phase_a_jobs, run_phase_a
    from parknss.actuators.spec import CandidateSpec
    from parknss.data.io import read_campaign

    camp = read_campaign(env / "data")
    cfg = actuator_config
    train, val = [t.id for t in camp][:5], [t.id for t in camp][5:7]
    envl = identify_envelope([t for t in camp if t.id in train], cfg.envelope)
    specs = [CandidateSpec.parse(n) for n in ("drive/narx/uniform", "brake/gru/cmd")]
    args = (specs, str(env / "data"), train, val, cfg, envl)
    one = run_phase_a(phase_a_jobs(*args), cfg, fanout=Fanout(workers=1))
    two = run_phase_a(phase_a_jobs(*args), cfg, fanout=Fanout(workers=2))
    for a, b in zip(one, two, strict=True):
        assert a.label == b.label and a.score.mse == b.score.mse
        for k, v in a.model.state_dict().items():
            assert torch.equal(v, b.model.state_dict()[k]), k


def test_build_refuses_an_existing_chain_unless_overwrite(env, capsys, tmp_path):
    sel = tmp_path / "sel.json"
    sel.write_text(json.dumps({"winners": {"drive": "drive/lag1/cmd", "brake": "brake/lag1/cmd",
                                           "steering": "steering/lag1/cmd"}}))
    out = tmp_path / "chain"
    base = ["actuators", "build", "--nss", str(env / "nss"), "--data", str(env / "data"),
            "--config", str(env / "act.yaml"), "--selection", str(sel), "--out", str(out)]
    assert _run(capsys, base)[0] == 0
    first = (out / "chain.json").read_bytes()
    code, _, err = _run(capsys, base)
    assert code == 2 and "holds a chain (chain.json) already; pass --overwrite" in err
    assert (out / "chain.json").read_bytes() == first
    assert _run(capsys, [*base, "--overwrite"])[0] == 0
    assert (out / "chain.json").is_file()
