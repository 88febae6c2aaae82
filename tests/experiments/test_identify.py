"""``parknss identify`` on a tiny campaign with tiny budgets: the stages run and write the
model card, a rerun skips them, an interrupted stage resumes, a campaign lacking a channel
is refused before any work, hostile names are escaped in the card, and a given NSS whose
data or config differ is never reused."""

from __future__ import annotations

import json
import os
import signal

import pytest
import torch
import yaml

from helpers.actuators import tiny_campaign, tiny_config
from helpers.kills import run_killed
from helpers.synth import drop
from parknss.cli import main
from parknss.data.io import write_campaign
from parknss.data.trial import Campaign, Trial
from parknss.experiments.identify import pipeline as pipeline_mod
from parknss.experiments.identify.card_html import card_html
from parknss.experiments.identify.config import IdentifyInputs
from parknss.experiments.identify.pipeline import run_identify
from parknss.experiments.identify.reuse import config_mismatch
from parknss.outputs import interrupt_note

torch.set_num_threads(1)

NSS_SET = ["model.state_units=8", "model.state_layers=1", "model.output_units=8",
           "model.output_layers=1", "train.epochs=2", "train.checkpoint_every=1"]
STAGES = "data,nss,selection,chain,rating,card"


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    root = tmp_path_factory.mktemp("identify")
    write_campaign(tiny_campaign(), root / "data")
    (root / "act.yaml").write_text(yaml.safe_dump(json.loads(tiny_config().model_dump_json())))
    return root


def _args(env, out, *extra):
    """A tiny paper-recipe run (``--recipe`` in ``extra`` replaces it)."""
    sets = [x for s in NSS_SET for x in ("--set", s)]
    recipe = [] if "--recipe" in extra else ["--recipe", "paper"]
    return ["identify", "--data", str(env / "data"), "--out", str(out), "--actuator-config",
            str(env / "act.yaml"), "--stages", STAGES, *sets, *recipe, *extra]


def _inputs(env, out, **kw):
    from parknss.nss.config import cli_overrides

    kw.setdefault("recipe", "paper")
    return IdentifyInputs(out=out, data=env / "data", actuator_config=env / "act.yaml",
                          stages=tuple(STAGES.split(",")), nss_overrides=cli_overrides(NSS_SET),
                          **kw)


@pytest.fixture(scope="module")
def car(env, tmp_path_factory):
    """One finished run (module scope: the stages take a few seconds)."""
    out = tmp_path_factory.mktemp("car") / "car"
    assert main(_args(env, out, "--json")) == 0
    return out


def test_pipeline_writes_the_chain_and_the_card(car):
    assert (car / "chain" / "chain.json").is_file()
    assert (car / "nss" / "model" / "model.json").is_file()
    card = json.loads((car / "model_card.json").read_text())
    assert card["format"] == "parknss-model-card/1"
    assert card["data"]["trials"] == 8
    assert set(card["data"]["classes"]) == {"park_in_left", "park_in_right", "park_out_left",
                                            "park_out_right"}
    assert card["data"]["channels_absent"] == []
    assert card["data"]["ranges"]["steer_cmd"]["max"] > card["data"]["ranges"]["steer_cmd"]["min"]
    assert {"all_measured", "cotuned_target", "monolithic"} <= set(card["table4"]["rows"])
    assert 0.0 <= card["iso"]["mean_raw"] <= 1.0
    nss = card["open_loop"]["nss_open_loop"]["logged"]
    assert nss["vx_mse_moving_kmh2"] >= 0 and "seed" in card["open_loop"]["seed_spread"]
    assert card["not_for"] and any("speeds above" in x for x in card["not_for"])
    st = {s["stage"]: s["status"] for s in card["stages"]}
    assert st["chain"] == "done" and st["grid"] == "not run"
    page = (car / "model_card.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and "Table IV" in page
    assert "<script" not in page and "http" not in page.replace("http-equiv", "")


@pytest.mark.slow
def test_the_default_recipe_is_the_coarse_one(env, tmp_path, capsys):
    """No --recipe: the NSS is fitted with train.recipe coarse (its own section read)."""
    from parknss.experiments.identify.config import IdentifyConfig, load_identify_config

    assert IdentifyConfig().recipe == load_identify_config(None).recipe == "coarse"
    assert IdentifyConfig().kernels == load_identify_config(None).kernels == "native"
    out = tmp_path / "car"
    coarse = ["coarse.factor=4", "coarse.epochs=3", "coarse.val_every=2", "coarse.finish_epochs=2"]
    sets = [x for s in [*NSS_SET, *coarse] for x in ("--set", s)]
    assert main(["identify", "--data", str(env / "data"), "--out", str(out), "--stages",
                 "data,nss", *sets, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["recipe"] == "coarse"
    meta = json.loads((out / "nss" / "model" / "model.json").read_text())
    text = json.dumps(meta)
    assert '"recipe": "coarse"' in text and '"factor": 4' in text
    assert meta["config"]["model"]["fused_kernels"] == "native"  # identify's default kernels


def test_phase_a_fitted_beside_the_nss_gives_the_same_chain(env, car, tmp_path, monkeypatch):
    """With --workers 2 the actuator study's Phase A runs in a background process while the
    NSS fits (here the fit waits until two Phase A fits are cached, so the overlap is
    certain); the selection and the chain equal the one-worker run's bit for bit."""
    import time

    from parknss.experiments import training

    out = tmp_path / "car"
    real = training.train_deployment

    def after_two_phase_a_fits(inputs):
        end = time.monotonic() + 180
        while len(list((out / "phase_a").glob("*/*.json"))) < 2:
            assert time.monotonic() < end, "no Phase A fit ahead"
            time.sleep(0.05)
        return real(inputs)

    monkeypatch.setattr(training, "train_deployment", after_two_phase_a_fits)
    said: list[str] = []
    doc = run_identify(_inputs(env, out, workers=2), said.append)
    assert doc["stages"]["selection"]["action"] == "ran"
    done = [m for m in said if "fits done beside the NSS fit" in m]
    assert len(done) == 1 and int(done[0].split("Phase A ahead: ")[1].split()[0]) >= 2
    sel = json.loads((out / "selection" / "study.json").read_text())
    ref = json.loads((car / "selection" / "study.json").read_text())
    def scores(doc):
        return [{k: v for k, v in r.items() if k != "fit_s"} for r in doc["phase_a"]]

    assert sel["winners"] == ref["winners"] and scores(sel) == scores(ref)
    assert len(list((out / "phase_a").glob("*/*.json"))) == len(ref["phase_a"])
    # the selection stage read them: every Phase A job of this campaign is a cache hit
    from parknss.actuators.config import load_actuator_config
    from parknss.chain.selection import phase_a_plan
    from parknss.data.io import read_campaign
    from parknss.executor import Tally, run_jobs

    data = str((env / "data").resolve())
    plan = phase_a_plan(read_campaign(data), data, load_actuator_config(env / "act.yaml"))
    tally = Tally()
    (cache,) = (out / "phase_a").iterdir()
    run_jobs(plan.jobs, workers=1, cache_dir=cache, progress=False, tally=tally)
    assert tally.to_json() == {"cache": len(plan.jobs), "store": 0, "computed": 0}
    for name in ("chain/actuators.safetensors", "nss/model/model.safetensors"):
        assert (out / name).read_bytes() == (car / name).read_bytes()


@pytest.mark.parametrize("change", [{"workers": 1}, {"executor": "ray"},
                                    {"selection": "sel.json"},
                                    {"stages": ("data", "nss")},
                                    {"overrides": {"phase_a_ahead": False}},
                                    {"nss_set": ["train.processes=2"]}])
def test_phase_a_runs_ahead_only_when_it_can_help(env, tmp_path, change):
    """Not for one worker, ray, given winners, no selection stage, turned off, or when the
    NSS fit takes every worker (data-parallel over 2 processes of 2 workers)."""
    import contextlib
    import dataclasses

    from parknss.experiments.identify.config import load_identify_config
    from parknss.nss.config import cli_overrides

    change = dict(change)
    if "nss_set" in change:
        change = {"nss_overrides": cli_overrides([*NSS_SET, *change.pop("nss_set")])}
    inputs = dataclasses.replace(_inputs(env, tmp_path / "car", workers=2), **change)
    pipe = pipeline_mod.Pipeline(inputs, load_identify_config(None, **inputs.overrides),
                                 lambda m: None)
    assert isinstance(pipe.phase_a_ahead(), contextlib.nullcontext)


def test_rerun_skips_finished_stages(env, car, capsys):
    before = {p.name: p.stat().st_mtime_ns for p in (car / "stages").iterdir()}
    assert main(_args(env, car, "--json")) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    assert {doc["stages"][s]["action"] for s in STAGES.split(",") if s != "card"} == {"skipped"}
    assert "skipped" in cap.err
    after = {p.name: p.stat().st_mtime_ns for p in (car / "stages").iterdir()}
    assert before == after


def test_rerun_from_another_working_folder_skips_every_stage(env, tmp_path, monkeypatch,
                                                               capsys):
    """Relative --data/--out spelled from two working folders name the same run: the
    records hold absolute paths, so the second run finds the campaign and skips."""
    sets = [x for s in NSS_SET for x in ("--set", s)]
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    data = os.path.relpath(env / "data", work)
    act = os.path.relpath(env / "act.yaml", work)
    monkeypatch.chdir(work)
    rest = ["--stages", STAGES, *sets, "--json"]
    assert main(["identify", "--actuator-config", act, "--data", data, "--out", "car",
                 *rest]) == 0
    capsys.readouterr()
    monkeypatch.chdir(tmp_path)
    assert main(["identify", "--actuator-config", os.path.join("a", "b", act),
                 "--data", os.path.join("a", "b", data), "--out", "a/b/car", *rest]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert {doc["stages"][s]["action"] for s in STAGES.split(",") if s != "card"} == {"skipped"}


def test_changed_input_reruns_that_stage_and_later_ones(env, car, tmp_path, capsys):
    import shutil

    out = tmp_path / "car"
    shutil.copytree(car, out)
    args = _args(env, out, "--json")
    args[args.index("train.epochs=2")] = "train.epochs=3"
    assert main(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["stages"]["data"]["action"] == "skipped"
    assert doc["stages"]["nss"]["action"] == "ran"
    assert doc["stages"]["chain"]["action"] == "ran"


def test_interrupted_stage_resumes(env, tmp_path, monkeypatch):
    out = tmp_path / "car"
    # a kill between a finished chain stage and its record: the next run redoes it only
    code = run_killed(lambda: run_identify(_inputs(env, out)), crash="identify.stage:4")
    assert code == signal.SIGKILL
    rec = json.loads((out / "stages" / "chain.json").read_text())
    assert rec["status"] == "running"
    assert json.loads((out / "stages" / "nss.json").read_text())["status"] == "done"
    doc = run_identify(_inputs(env, out))
    assert doc["stages"]["nss"]["action"] == "skipped"
    assert doc["stages"]["chain"]["action"] == "resumed"
    assert json.loads((out / "stages" / "chain.json").read_text())["sittings"] == 2

    # Ctrl-C inside a stage: one resume line naming identify, the stage and the folder
    def boom(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline_mod.Pipeline, "stage_rating", boom)
    os.environ.pop("PARKNSS_CRASH_AT", None)
    out2 = tmp_path / "car2"
    with pytest.raises(KeyboardInterrupt):
        run_identify(_inputs(env, out2))
    note = interrupt_note(clear=True)
    assert "stage rating" in note and "resume with `parknss identify" in note
    assert str(out2) in note


def test_killed_once_in_each_stage_and_resumed(env, car, tmp_path):
    """SIGKILL once in every stage (after its work, before its record: the worst instant),
    each rerun redoes that stage only and goes on; the final chain is bit-identical to the
    uninterrupted run's."""
    out = tmp_path / "car"
    stages = STAGES.split(",")
    for i, stage in enumerate(stages):
        # the first run dies in its first stage; each rerun redoes the killed stage (hit 1)
        # and dies in the next one (hit 2)
        crash = "identify.stage:1" if i == 0 else "identify.stage:2"
        assert run_killed(lambda: run_identify(_inputs(env, out)), crash=crash) == signal.SIGKILL
        recs = {s: json.loads((out / "stages" / f"{s}.json").read_text())["status"]
                for s in stages[: i + 1]}
        assert recs[stage] == "running"
        assert all(recs[s] == "done" for s in stages[:i])
    doc = run_identify(_inputs(env, out))
    assert [doc["stages"][s]["action"] for s in stages[:-1]] == ["skipped"] * (len(stages) - 1)
    assert doc["stages"][stages[-1]]["action"] == "resumed"
    for name in ("chain/actuators.safetensors", "nss/model/model.safetensors"):
        assert (out / name).read_bytes() == (car / name).read_bytes()


def test_nss_stage_kept_across_accepted_code_versions_and_record_formats(env, car, tmp_path,
                                                                         capsys, monkeypatch):
    """A finished NSS stage recorded under a training-code version the canary lineage
    accepts as equal, with its config written in full (older records), is still the same
    stage; a version outside the lineage is a change."""
    import shutil

    from parknss.config import REPO_ROOT
    from parknss.experiments.identify.stages import digest_of
    from parknss.experiments.lineage import accepted_versions
    from parknss.experiments.store import code_version, store_dir
    from parknss.nss.config import NSSConfig
    from parknss.outputs import plain_json as plain

    store = tmp_path / "store"  # the checkout's lineage, read from a copy
    shutil.copytree(REPO_ROOT / "results" / "lineage", store / "lineage")
    monkeypatch.setenv("PARKNSS_RESULTS", str(store))
    versions = accepted_versions(store_dir(None), code_version())
    if len(versions) < 2:
        pytest.skip("the store's lineage accepts no other version of this code")
    out = tmp_path / "car"

    def rerun_with(version):
        shutil.rmtree(out, ignore_errors=True)
        shutil.copytree(car, out)
        p = out / "stages" / "nss.json"
        rec = json.loads(p.read_text())
        full = NSSConfig.model_validate(rec["inputs"]["config"]).model_dump(mode="json")
        rec["inputs"].update(code_version=version, config=full)
        rec["digest"] = digest_of(plain(rec["inputs"]))
        p.write_text(json.dumps(rec))
        assert main(_args(env, out, "--json")) == 0
        return json.loads(capsys.readouterr().out)["stages"]["nss"]["action"]

    assert rerun_with(versions[1]) == "skipped"
    assert rerun_with("0123456789abcdef") == "ran"


def test_campaign_lacking_a_channel_is_refused_before_any_work(env, tmp_path, capsys):
    from parknss.data.io import read_campaign

    part = drop(read_campaign(env / "data"), ["decel_cmd"])
    write_campaign(part, tmp_path / "part")
    out = tmp_path / "car"
    args = _args(env, out)
    args[args.index("--data") + 1] = str(tmp_path / "part")
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("parknss: error:") and "decel_cmd" in err[0]
    assert not (out / "nss").exists()


def test_hostile_names_are_escaped(env, tmp_path):
    from parknss.data.io import read_campaign
    from parknss.experiments.identify.card import ModelCard

    base = read_campaign(env / "data")
    evil = '<script>alert("x")</script>'
    camp = Campaign([Trial(t.id, t.maneuver, t.repetition, t.channels) for t in base],
                    name=evil)
    from parknss.experiments.identify.data_stage import campaign_facts

    facts = campaign_facts(camp)
    card = ModelCard(format="f", generated_utc="t", parknss_git="g", car=evil, chain=evil,
                     recipe="paper", data=facts, nss={"reused": evil}, open_loop={"note": evil},
                     table4=None, iso=None, closed_loop=None, fidelity={"skipped": evil},
                     domain={"seen": {}}, not_for=[evil], stages=[])
    page = card_html(card)
    assert "<script>" not in page and "&lt;script&gt;" in page


def test_given_nss_is_reused_only_when_it_matches(env, car, tmp_path, capsys):
    model = car / "nss" / "model"
    ok = tmp_path / "ok"
    assert main(_args(env, ok, "--nss", str(model), "--json")) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["stages"]["nss"]["action"] == "reused"
    assert "match" in doc["stages"]["nss"]["reused"]
    # another config: refused in one line, nothing reused
    bad = tmp_path / "bad"
    args = _args(env, bad, "--nss", str(model))
    args[args.index("train.epochs=2")] = "train.epochs=5"
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "train.epochs" in err and "not reused" in err
    # another campaign: refused
    other = tmp_path / "other"
    from parknss.data.io import read_campaign

    camp = read_campaign(env / "data")
    write_campaign(Campaign(camp.trials[:-1], name="other"), other)
    args = _args(env, tmp_path / "bad2", "--nss", str(model))
    args[args.index("--data") + 1] = str(other)
    assert main(args) == 2
    assert "fitted on data" in capsys.readouterr().err


def test_config_mismatch_rules():
    rec = {"train": {"epochs": 3200, "lr": 0.002}, "model": {"state_units": 128}}
    want = {"train": {"epochs": 3200, "lr": 0.002, "recipe": "paper"},
            "model": {"state_units": 128}, "fast": {"updates": 2000}}
    assert config_mismatch(rec, want) is None
    assert "train.recipe" in config_mismatch(rec, {**want, "train": {**want["train"],
                                                                     "recipe": "fast"}})
    assert "state_units" in config_mismatch(rec, {**want, "model": {"state_units": 64}})
    # a fast model from before the coarse recipe: the coarse section is inert for it
    fast = {"train": {"recipe": "fast"}, "fast": {"updates": 2000}}
    assert config_mismatch(fast, {**fast, "coarse": {"factor": 16}}) is None
    assert "fast.updates" in config_mismatch(fast, {**fast, "fast": {"updates": 10}})
    coarse = {"train": {"recipe": "coarse"}, "coarse": {"factor": 16}}
    assert config_mismatch(coarse, {**coarse, "fast": {"updates": 2000}}) is None
    assert "coarse.factor" in config_mismatch(
        {"train": {"recipe": "coarse"}}, {**coarse})  # its own section must be recorded
    # the fused kernels decide a fit's rounding only: a reference fit serves a native run
    native = {**coarse, "model": {"fused_kernels": "native"}}
    assert config_mismatch(coarse, native) is None
    assert config_mismatch({**coarse, "model": {"fused_kernels": "fast"}}, native) is None


def test_from_a_folder_of_logs(env, tmp_path, capsys):
    from parknss.data.io import read_campaign, write_trial

    logs = tmp_path / "logs"
    logs.mkdir()
    for tr in read_campaign(env / "data"):
        write_trial(tr, logs / f"{tr.id}.csv")
    out = tmp_path / "car"
    assert main(["identify", str(logs), "--out", str(out), "--stages", "data", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["stages"]["data"]["action"] == "ran"
    assert read_campaign(out / "data").data_hash() == read_campaign(env / "data").data_hash()
    card = json.loads((out / "model_card.json").read_text())
    assert card["data"]["trials"] == 8 and card["data"]["truth"] is None
    assert any(s["stage"] == "fidelity" and s["status"] == "not run" for s in card["stages"])
    # the logs' digest is their content: rewriting a file unchanged keeps the stage
    (logs / "park_in_left_r1.csv").write_text((logs / "park_in_left_r1.csv").read_text())
    assert main(["identify", str(logs), "--out", str(out), "--stages", "data", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["stages"]["data"]["action"] == "skipped"


def test_truth_is_found_only_for_the_recorded_vehicle():
    from parknss.experiments.identify.reuse import truth_vehicle
    from parknss.reference.params import load_vehicle_params

    digest = load_vehicle_params(None).digest()
    meta = {"synthetic": True, "vehicle_yaml": None, "vehicle_params_digest": digest}
    assert truth_vehicle(meta) is not None and truth_vehicle(meta)[0] is None
    assert truth_vehicle({**meta, "vehicle_params_digest": "0" * 16}) is None
    assert truth_vehicle({**meta, "synthetic": False}) is None
    from parknss.config import CONFIG_DIR

    alt = load_vehicle_params(CONFIG_DIR / "reference_vehicle_alt.yaml").digest()
    found = truth_vehicle({"synthetic": True, "vehicle_yaml": "configs/reference_vehicle_alt.yaml",
                           "vehicle_params_digest": alt})
    assert found is not None and found[0].name == "reference_vehicle_alt.yaml"


def test_given_interface_gains_are_recorded_not_tuned(env, car, tmp_path, capsys):
    import shutil

    from parknss.config import CONFIG_DIR

    out = tmp_path / "car"
    shutil.copytree(car, out)
    args = _args(env, out, "--interface", str(CONFIG_DIR / "interface.yaml"), "--json")
    args[args.index("--stages") + 1] = STAGES + ",tune"
    assert main(args) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["stages"]["chain"]["action"] == "skipped"
    assert doc["stages"]["tune"]["action"] == "reused"
    assert "not tuned here" in doc["stages"]["tune"]["reused"]
    card = json.loads((out / "model_card.json").read_text())
    assert {s["stage"]: s["status"] for s in card["stages"]}["tune"] == "done"
