"""Stack-driven identification trials: held out from the fidelity grids, valid campaign
trials, deterministic under their seed (parknss.sim.stack_trials)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from parknss.cli import main
from parknss.config import BUNDLED_CAMPAIGN, CONFIG_DIR
from parknss.data.io import read_campaign, write_campaign
from parknss.data.splits import cv_plan
from parknss.data.validate import validate_trial
from parknss.errors import DataError
from parknss.reference.params import load_vehicle_params
from parknss.reference.vehicle import TRUTH_CHANNELS
from parknss.signals import REQUIRED_CHANNELS
from parknss.sim import scenarios as sc
from parknss.sim import stack_trials as st

# one short cell: an angled bay whose first draw is planned and parked at once (38 s)
BAY, REP = "angled", 1


@pytest.fixture(scope="module")
def grid_scenes():
    return st.fidelity_scenes()


@pytest.fixture(scope="module")
def trial(grid_scenes):
    return st.generate_stack_trial(BAY, REP, seed=0, grid_scenes=grid_scenes)


def test_the_grids_are_all_288_scenes_and_each_is_not_held_out(grid_scenes):
    cfg = st.StackTrialsConfig()
    assert len(grid_scenes) == sc.N_CELLS + sc.N_ROBUST == 288
    assert len({g.meta.name for g in grid_scenes}) == 288
    for g in grid_scenes[:: 17]:
        assert st.scene_distance(g, g) == 0.0
        assert not st.held_out(g, grid_scenes, cfg)
        # a grid scene moved by 1 cm is still that cell: not held out either
        x, y, th = g.start
        assert not st.held_out(replace(g, start=(x + 0.01, y, th)), grid_scenes, cfg)


def test_drawn_scenes_lie_away_from_every_fidelity_scene(grid_scenes):
    cfg = st.StackTrialsConfig()
    for bay in sc.BAYS:
        for rep in range(1, cfg.repetitions + 1):
            scene = st.draw_scene(0, bay, rep)
            dist, near = st.nearest_grid_scene(scene, grid_scenes)
            assert dist > cfg.min_separation_m, (bay, rep, near, dist)
            assert scene.meta.cell is None and scene.meta.perturbation == "stack"
    # deterministic under the seed, different under another seed or attempt
    a, b = st.draw_scene(0, "angled", 2), st.draw_scene(0, "angled", 2)
    assert st.scene_distance(a, b) == 0.0
    assert st.scene_distance(a, st.draw_scene(1, "angled", 2)) > 0.0
    assert st.scene_distance(a, st.draw_scene(0, "angled", 2, attempt=1)) > 0.0


def test_the_trial_is_a_valid_campaign_trial_of_a_held_out_scene(trial, grid_scenes):
    validate_trial(trial, "stack trial")
    assert trial.id == f"stack_{BAY}_r{REP}" and trial.maneuver == f"stack_{BAY}"
    assert set(REQUIRED_CHANNELS) <= set(trial.channels)
    assert set(TRUTH_CHANNELS) <= set(trial.channels)
    # starts at rest in park, ends parked at rest, as the campaign's trials
    assert trial["gear"][0] == 0 and trial["gear"][-1] == 0
    assert trial.truth("vx")[0] == 0.0 and abs(trial.truth("vx")[-1]) < 1e-3
    assert np.any(trial["gear"] != 0) and np.max(np.abs(trial["vx"])) > 0.3  # it drove
    prov = json.loads(trial.provenance)
    assert prov["generator"] == st.GENERATOR and prov["synthetic"] is True
    assert prov["conditions"]["profile"] == "typical"  # the YAML's, as the bundled campaign
    assert prov["outcome"]["duration_s"] == pytest.approx(trial.duration_s, abs=0.02)
    scene = sc.Scene.from_json(prov["scene"])
    dist, _ = st.nearest_grid_scene(scene, grid_scenes)
    assert dist > st.StackTrialsConfig().min_separation_m
    assert dist == pytest.approx(prov["nearest_grid_scene"]["distance_m"], abs=1e-6)


def test_the_trial_is_deterministic_under_its_seed(trial, grid_scenes):
    again = st.generate_stack_trial(BAY, REP, seed=0, grid_scenes=grid_scenes)
    assert again.provenance == trial.provenance
    assert set(again.channels) == set(trial.channels)
    for name, values in trial.channels.items():
        assert np.array_equal(again.channels[name], values), name


def test_campaign_of_bundled_and_stack_trials_round_trips_and_stays_stratified(trial, tmp_path):
    base = read_campaign(BUNDLED_CAMPAIGN)
    params = load_vehicle_params(None)
    # the shape of the default run: 3 stack classes x 4 repetitions (copies of one trial)
    trials = [
        replace(trial, id=f"stack_{bay}_r{r}", maneuver=f"stack_{bay}", repetition=r)
        for bay in sc.BAYS
        for r in range(1, 5)
    ]
    camp = st.stack_campaign(trials, params, base, seed=0)
    assert camp.ids[:16] == base.ids and len(camp) == 28
    assert camp.meta["stack_trials"]["n_trials"] == 12
    assert camp.meta["conditions_profile"] == base.meta["conditions_profile"]
    plan = cv_plan(camp)
    assert plan.stratified
    assert all(len(f.val) == 7 for f in plan.folds)  # one trial of each of the 7 classes
    # the stack trials alone are a campaign too; through the campaign's own writer/reader
    alone = st.stack_campaign(trials[8:10], params)  # stack_angled_r1, r2
    assert alone.meta["vehicle_geometry"] == base.meta["vehicle_geometry"]
    back = read_campaign(write_campaign(alone, tmp_path / "c"))
    assert back.ids == alone.ids and back.meta["stack_trials"] == alone.meta["stack_trials"]
    assert np.array_equal(back[trial.id]["vx"], trial["vx"])
    assert back[trial.id].provenance == trial.provenance
    with pytest.raises(DataError, match="repeats"):
        st.stack_campaign([trial, trial], params)


def test_another_vehicles_campaign_is_refused(trial):
    base = read_campaign(BUNDLED_CAMPAIGN)
    alt = load_vehicle_params(CONFIG_DIR / "reference_vehicle_alt.yaml")
    with pytest.raises(DataError, match="parameter digest"):
        st.stack_campaign([trial], alt, base)


def test_command_refuses_base_with_no_base(tmp_path, capsys):
    code = main(["campaign", "stack", "--out", str(tmp_path / "c"), "--no-base",
                 "--base", str(BUNDLED_CAMPAIGN)])
    assert code == 2
    assert "--base and --no-base" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()
