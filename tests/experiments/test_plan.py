"""The study plan and its cost: the jobs are the studies' own, shared fits meet, the
cost model's arithmetic, and the store's share is not counted again."""

from __future__ import annotations

import pytest

from helpers.experiments import tiny_setup
from parknss.data.decimate import decimate, grid_length
from parknss.data.windows import make_windows
from parknss.errors import ConfigError
from parknss.experiments.config import load_experiments_config
from parknss.experiments.folds import make_fold
from parknss.experiments.plan import (
    FUSED,
    FitShape,
    Rates,
    estimate,
    fit_shape,
    plan_rows,
    study_jobs,
)
from parknss.experiments.store import ResultStore, fit_key
from parknss.experiments.sweep import Sweep, fold_spec
from parknss.nss.campaigns import load_campaign
from parknss.nss.recipes import HELD_INPUTS


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    data, cfg_path = tiny_setup(tmp_path_factory.mktemp("plan"))
    return str(data), load_experiments_config(cfg_path)


def _ids(jobs):
    return {fit_key(j.fn, j.kwargs) for j in jobs}


def test_the_plan_is_the_studies_own_jobs_and_shared_fits_meet(tiny):
    data, cfg = tiny
    sweep = Sweep(data=data, progress=False)
    b = cfg.budget(False)
    jobs = {n: study_jobs(n, cfg, False, sweep) for n in ("table2", "time_to_accuracy",
                                                          "convergence", "seed-noise",
                                                          "limiter", "learning-curve")}
    assert len(jobs["seed-noise"]) == len(b.seeds)
    assert len(jobs["limiter"]) == len(b.folds)
    assert len(jobs["learning-curve"]) == len(cfg.learning_curve_rs) * len(b.folds)
    assert len(jobs["time_to_accuracy"]) == (1 + len(b.tta_recipes)) * len(b.tta_folds)
    assert len(jobs["table2"]) == 12  # nss, direct yaw, linear x 4 folds
    # Fig. 4's fit is the fold-0 Table II NSS fit and the fold-0 TTA paper fit
    (conv,) = _ids(jobs["convergence"])
    assert conv in _ids(jobs["table2"]) and conv in _ids(jobs["time_to_accuracy"])
    rows = plan_rows(cfg, False, sweep, ("ablations",))
    assert list(rows) == [f"ablations: {a.name}" for a in cfg.axes]
    base = _ids(rows["ablations: loss"]) & _ids(rows["ablations: yaw readout"])
    assert len(base) == len(b.ablation_folds)  # the deployed baseline, in every axis's row
    assert _ids(study_jobs("ablations", cfg, False, sweep)) == set().union(
        *(_ids(j) for j in rows.values()))
    with pytest.raises(ValueError, match="no plan"):
        study_jobs("table9", cfg, False, sweep)


def test_fit_shapes_follow_recipe_engine_window_and_training_set(tiny):
    data, cfg = tiny
    sweep = Sweep(data=data, progress=False)
    camp = load_campaign(data)
    base = cfg.budget(False).study_overrides()
    paper = fit_shape(fold_spec(sweep, "cv", 0, base), camp)
    assert (paper.recipe, paper.engine, paper.epochs, paper.updates) == ("paper", FUSED, 2, 0)
    fast = fit_shape(fold_spec(sweep, "cv", 0, {**base, "train": {"recipe": "fast"}}), camp)
    assert (fast.recipe, fast.epochs, fast.updates) == ("fast", 2, 6)  # finish, updates
    rk4 = fit_shape(fold_spec(sweep, "cv", 0, {**base, "model": {"integrator": "rk4"}}), camp)
    assert rk4.engine == ("rk4", "eager")
    fold = make_fold(camp, "cv", 0)
    train = [camp[i] for i in fold.train]
    ov = {**base, "train": {"recipe": "coarse"}, "coarse": {"factor": 4, "epochs": 7,
                                                             "finish_epochs": 3}}
    coarse = fit_shape(fold_spec(sweep, "cv", 0, ov), camp)
    assert (coarse.recipe, coarse.epochs, coarse.updates) == ("coarse", 3, 7)
    assert coarse.phases == (("coarse", 7), ("full", 3)) and coarse.samples == paper.samples
    L = min(t.n for t in train)  # what the coarse phase tiles: the decimated trials
    dec = [decimate(t, 4, HELD_INPUTS) for t in train]
    assert coarse.coarse_samples == make_windows(dec, grid_length(L, 4)).inputs.shape[0] * (
        grid_length(L, 4))
    longest = max(t.n for t in train)
    for window, L in (("shortest", min(t.n for t in train)), (longest, longest)):
        ov = {**base, "data": {"window": window}}
        shape = fit_shape(fold_spec(sweep, "cv", 0, ov), camp)
        assert shape.samples == make_windows(train, L).inputs.shape[0] * L  # what training tiles
    fewer = fit_shape(fold_spec(sweep, "leave", 0, base, r=3), camp)
    assert fewer.samples < paper.samples  # 4 training trials instead of 12
    lin = fit_shape(study_jobs("table2", cfg, False, sweep)[-1], camp)
    assert lin.model == "linear"


def test_cost_arithmetic():
    rk4, mid = ("rk4", "eager"), ("midpoint", "eager")
    rates = Rates({FUSED: 2.0, rk4: 10.0, mid: 4.0}, {FUSED: 0.5, mid: 3.0}, ref_samples=1000)
    assert rates.cost(FitShape("nss", "paper", FUSED, 100, 0, 1000)) == pytest.approx(200.0)
    assert rates.cost(FitShape("nss", "paper", FUSED, 100, 0, 500)) == pytest.approx(100.0)
    # fast: updates at the engine's update rate, finish epochs as paper ones
    assert rates.cost(FitShape("nss", "fast", FUSED, 10, 40, 1000)) == pytest.approx(40.0)
    assert rates.cost(FitShape("nss", "fast", mid, 10, 40, 1000)) == pytest.approx(
        40 * 3.0 + 10 * 4.0)
    # an update rate not timed: the fused one times the class's epoch ratio
    assert rates.cost(FitShape("nss", "fast", rk4, 10, 40, 1000)) == pytest.approx(
        40 * 0.5 * 5 + 100.0)
    assert rates.cost(FitShape("nss", "paper", ("euler", "eager"), 1, 0, 1000)) == 2.0
    assert rates.cost(FitShape("linear")) == 0.0
    # the first s steps: a paper fit's epochs; a fast fit's updates, then finish epochs
    paper = FitShape("nss", "paper", FUSED, 100, 0, 1000)
    assert rates.cost(paper, 30) == pytest.approx(60.0)
    assert rates.cost(paper, 0) == 0.0 and rates.cost(paper, 500) == rates.cost(paper)
    fast = FitShape("nss", "fast", mid, 10, 40, 1000)
    assert rates.cost(fast, 20) == pytest.approx(20 * 3.0)
    assert rates.cost(fast, 45) == pytest.approx(40 * 3.0 + 5 * 4.0)
    assert rates.cost(fast, 10_000) == pytest.approx(rates.cost(fast))
    # coarse: its epochs at the epoch rate scaled by their samples, then finish epochs
    coarse = FitShape("nss", "coarse", FUSED, 10, 40, 1000, 125)
    assert rates.cost(coarse) == pytest.approx(40 * 2.0 * 0.125 + 10 * 2.0)
    assert rates.cost(coarse, 20) == pytest.approx(20 * 2.0 * 0.125)
    assert rates.cost(coarse, 45) == pytest.approx(40 * 0.25 + 5 * 2.0)


def test_estimate_counts_the_store_once_and_charges_only_the_rest(tiny, tmp_path):
    data, cfg = tiny
    sweep = Sweep(data=data, progress=False)
    store = ResultStore(tmp_path / "results", log=lambda msg: None)
    studies = ("table2", "time_to_accuracy", "convergence")

    def run():
        return estimate(cfg, False, sweep, store, lambda m: None, sec_per_epoch=1.0,
                        sec_per_update=0.1, studies=studies)

    before = run()
    (conv,) = study_jobs("convergence", cfg, False, sweep)
    store.put(conv, {"stub": True}, wall_s=1.0, cpu_s=1.0)
    after = run()
    by = {s.study: s for s in after.studies}
    assert [by[n].stored for n in studies] == [1, 1, 1]  # one fit, three studies
    assert after.total.stored == 1 and after.total.fits == before.total.fits
    shape = fit_shape(conv, load_campaign(data))
    assert before.total.cpu_h - after.total.cpu_h == pytest.approx(
        after.rates.cost(shape) / 3600.0)
    assert by["convergence"].cpu_h == 0.0
    assert after.total.recipes == {"paper": 8, "fast": 2, "coarse": 4, "linear": 4}


def test_a_parked_state_is_credited_with_the_epochs_it_has_done(tiny, tmp_path):
    import json

    from parknss.experiments import parked
    from parknss.nss.train_state import FORMAT, META

    data, cfg = tiny
    sweep = Sweep(data=data, progress=False)
    store = ResultStore(tmp_path / "results", log=lambda msg: None)
    studies = ("convergence",)

    def run():
        return estimate(cfg, False, sweep, store, lambda m: None, sec_per_epoch=1.0,
                        sec_per_update=0.1, studies=studies)

    before = run()
    (conv,) = study_jobs("convergence", cfg, False, sweep)
    shape = fit_shape(conv, load_campaign(data))
    assert shape.recipe == "paper" and shape.epochs >= 2 and before.total.parked == 0

    def park(step):
        folder = parked.parked_dir(store.root, store.entry_key(conv)[0])
        folder.mkdir(parents=True, exist_ok=True)
        (folder / META).write_text(json.dumps({"format": FORMAT, "epoch": step}))

    park(shape.epochs - 1)
    after = run()
    assert before.rates.cost(shape, shape.epochs - 1) > 0.0
    assert after.total.parked == 1 and after.total.stored == 0
    assert after.total.cpu_h == pytest.approx(before.total.cpu_h / shape.epochs)
    park(10 * shape.epochs)  # a state past the fit's epochs leaves nothing, not less
    assert run().total.cpu_h == 0.0
    store.put(conv, {"stub": True}, wall_s=1.0, cpu_s=1.0)  # stored: not counted as parked
    stored = run()
    assert (stored.total.parked, stored.total.stored) == (0, 1)


def test_a_parked_fast_fit_is_credited_with_its_updates_then_its_finish_epochs(tiny, tmp_path):
    import json

    from parknss.experiments import parked
    from parknss.nss.train_state import FORMAT, META

    data, cfg = tiny
    sweep = Sweep(data=data, progress=False)
    store = ResultStore(tmp_path / "results", log=lambda msg: None)
    camp = load_campaign(data)
    fast = next(j for j in study_jobs("time_to_accuracy", cfg, False, sweep)
                if fit_shape(j, camp).recipe == "fast")
    shape = fit_shape(fast, camp)

    def run():
        return estimate(cfg, False, sweep, store, lambda m: None, sec_per_epoch=1.0,
                        sec_per_update=0.1, studies=("time_to_accuracy",))

    before = run()
    folder = parked.parked_dir(store.root, store.entry_key(fast)[0])
    folder.mkdir(parents=True)
    rates = before.rates
    epoch = rates.cost(shape, shape.updates + 1) - rates.cost(shape, shape.updates)
    assert epoch == pytest.approx(rates.epoch_rate(shape.engine) * shape.samples
                                  / rates.ref_samples)
    for step, done in ((3, 3 * 0.1), (shape.updates, shape.updates * 0.1),
                       (shape.updates + 1, shape.updates * 0.1 + epoch)):
        (folder / META).write_text(json.dumps({"format": FORMAT, "epoch": step}))
        after = run()
        assert after.total.parked == 1
        assert (before.total.cpu_h - after.total.cpu_h) * 3600 == pytest.approx(done)


def test_rates_are_timed_per_engine_class_the_plan_needs(tiny):
    from parknss.experiments.plan import time_rates

    data, cfg = tiny
    said: list[str] = []
    mid = ("midpoint", "eager")
    rates = time_rates(data, cfg.budget(False).overrides, {("rk4", "eager"), mid},
                       load_campaign(data), said.append, fast_engines={mid})
    assert set(rates.epoch) == {FUSED, ("rk4", "eager"), mid} and rates.timed
    assert set(rates.update) == {FUSED, mid}  # update rates of the fast fits' engines
    assert all(v > 0 for v in [*rates.epoch.values(), *rates.update.values()])
    assert any("rk4" in m for m in said) and any("updates" in m and "midpoint" in m
                                                  for m in said)
    given = time_rates(data, {}, set(), load_campaign(data), said.append, 1.5, 0.2)
    assert given.epoch == {FUSED: 1.5} and given.update == {FUSED: 0.2} and not given.timed
    said.clear()  # a fused rate given: RK4 is still timed, and costs its ratio to fused
    scaled = time_rates(data, {}, {("rk4", "eager")}, load_campaign(data), said.append, 1.5,
                        0.2)
    assert scaled.epoch[FUSED] == 1.5 and any("rk4" in m for m in said)
    assert scaled.epoch[("rk4", "eager")] > 1.5  # four eager stages cost more than one fused
    with pytest.raises(ConfigError, match="non-positive"):
        time_rates(data, {}, set(), load_campaign(data), said.append, 0.0, 0.2)


def test_a_rate_the_noise_swamped_is_timed_again_at_each_fits_minimum(tiny, monkeypatch):
    """A deterministic fake fit (1 s + 0.25 s an epoch on a fake CPU clock) whose first
    1-epoch fit the noise slows past the 6-epoch one: the class is timed again and each
    fit's minimum gives the true rate; noise on every try still refuses."""
    import types

    import parknss.experiments.folds as folds
    import parknss.experiments.plan as plan

    data, _ = tiny
    clock = [0.0]
    noise = iter([0.0, 1.5, 0.0, 0.0, 0.0])  # warm-up, 1 (slowed), 6, 1, 6

    def fake_fold_job(kind, fold, data=None, overrides=None):
        clock[0] += 1.0 + 0.25 * overrides["train"]["epochs"] + next(noise, 0.0)

    monkeypatch.setattr(folds, "fold_job", fake_fold_job)
    monkeypatch.setattr(plan, "time", types.SimpleNamespace(process_time=lambda: clock[0]))
    said: list[str] = []
    rates = plan.time_rates(data, {}, set(), load_campaign(data), said.append, None, 0.2)
    assert rates.epoch[FUSED] == pytest.approx(0.25) and any("again" in m for m in said)
    noise = iter([0.0, *[2.0, 0.0] * (1 + plan.TIMING_RETRIES)])  # every 1-epoch fit slowed
    with pytest.raises(ConfigError, match="non-positive"):
        plan.time_rates(data, {}, set(), load_campaign(data), said.append, None, 0.2)


def test_estimate_counts_a_limiter_fit_and_the_fold_fits_it_answers_once(tiny, tmp_path):
    data, cfg = tiny
    sweep = Sweep(data=data, progress=False)
    store = ResultStore(tmp_path / "results", log=lambda msg: None)
    studies = ("limiter", "seed-noise", "learning-curve")
    est = estimate(cfg, False, sweep, store, lambda m: None, sec_per_epoch=1.0,
                   sec_per_update=0.1, studies=studies)
    b = cfg.budget(False)
    by = {s.study: s for s in est.studies}
    # seed 0 of the seed-noise fold and the learning curve's r = 1 folds are limiter fits
    assert est.total.fits == len(b.folds) + (len(b.seeds) - 1) + (
        len(cfg.learning_curve_rs) - 1) * len(b.folds)
    assert sum(by[n].fits for n in studies) - est.total.fits == 1 + len(b.folds)
    for job in study_jobs("limiter", cfg, False, sweep):
        store.put(job, {"stub": True}, wall_s=1.0, cpu_s=1.0)
    after = estimate(cfg, False, sweep, store, lambda m: None, sec_per_epoch=1.0,
                     sec_per_update=0.1, studies=studies)
    by = {s.study: s for s in after.studies}
    assert (by["limiter"].stored, by["seed-noise"].stored) == (len(b.folds), 1)
    assert by["learning-curve"].stored == len(b.folds)
    # a fold job asked first: answered through the alias, and a limiter entry without its
    # fold part is not taken for one
    fold = next(j for j in study_jobs("learning-curve", cfg, False, sweep)
                if j.kwargs["split"] == "cv")
    assert store.get(fold) == (False, None)  # the stubs have no "fold" part


def test_the_shipped_schedule_axis_runs_at_a_reduced_lr_its_cosine_row_a_loss_fit(tiny):
    """The paper isolates the schedule shape at a reduced LR: the shipped axis's cosine
    option is then the loss sweep's MAE fit at that LR, one fit for both rows."""
    data, _ = tiny
    cfg = load_experiments_config()
    sched = next(a for a in cfg.axes if a.name == "lr schedule")
    lrs = {o.overrides["train"]["lr"] for o in sched.options}
    assert len(lrs) == 1 and lrs.pop() < 0.002  # below the deployed LR, the same for both
    rows = plan_rows(cfg, False, Sweep(data=data, progress=False), ("ablations",))
    schedule, loss = _ids(rows["ablations: lr schedule"]), _ids(rows["ablations: loss"])
    assert len(schedule & loss) == len(cfg.budget(False).ablation_folds)  # the cosine row


def test_the_floor_row_is_the_other_folds_seeds_and_seed_0_is_the_limiter_fit(tiny):
    data, cfg = tiny
    sweep = Sweep(data=data, progress=False)
    b = cfg.budget(False)
    floor = study_jobs("floor", cfg, False, sweep)
    others = [k for k in b.folds if k != cfg.seed_noise_split.index]
    assert len(floor) == len(others) * len(b.floor_seeds)
    assert not _ids(floor) & _ids(study_jobs("seed-noise", cfg, False, sweep))
    # seed 0 of a fold's floor is that fold's deployed-configuration fit (the limiter's)
    limiter = {j.kwargs["index"]: j for j in study_jobs("limiter", cfg, False, sweep)}
    seed0 = [j for j in floor if "seed" not in j.kwargs["overrides"].get("train", {})]
    assert len(seed0) == len(others)
    for j in seed0:  # the same arguments: the stored limiter fit answers it (ALIASES)
        assert j.kwargs == limiter[j.kwargs["index"]].kwargs
