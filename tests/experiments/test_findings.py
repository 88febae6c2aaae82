"""The co-tuning finding reads a chain build: agrees only when the signal-fitted brake
degrades the chain against the Phase B assembly and the co-tuned one beats it."""

from parknss.experiments.findings import cotuning_finding


def _rows(sig: float, tuned: float, ref: float, **doc) -> dict:
    return {"rows": {
        "signal_target": {"vx_full": sig},
        "cotuned_target": {"vx_full": tuned},
        "selected_assembly": {"vx_full": ref},
    }, **doc}


def test_reversal_agrees_when_cotuned_beats_both():
    f = cotuning_finding(_rows(0.069, 0.055, 0.059))
    assert f.agrees is True and f.verdict == "agrees"


def test_lowered_but_phase_b_better_differs_and_says_so():
    f = cotuning_finding(_rows(0.20, 0.065, 0.030))
    assert f.agrees is False and "Phase B assembly stays better" in f.measured


def test_no_verdict_to_reverse_when_the_target_is_phase_bs_own_winner():
    target = "brake/narx1s/cmd"
    f = cotuning_finding(_rows(0.11, 0.11, 0.11, selection={"brake": target},
                               cotune={"channel": "brake", "target": target, "best_step": 0}))
    # the paper's premise cannot arise: neither agrees nor differs
    assert f.agrees is None and f.verdict == "no verdict to reverse"
    assert "Phase B's own brake winner" in f.measured and "kept its starting" in f.measured
    # the shipped chain's case: the own winner co-tuned at step 30, 19 % lower
    f = cotuning_finding(_rows(0.0972, 0.0783, 0.0972, selection={"brake": target},
                               cotune={"channel": "brake", "target": target, "best_step": 30}))
    assert f.verdict == "no verdict to reverse" and "lowers the chain's vx full 19 %" in f.measured
    # co-tuning lowering a target that never degraded the chain (no selection recorded)
    # reverses nothing: differs
    assert cotuning_finding(_rows(0.059, 0.050, 0.059)).verdict == "differs"


def test_no_rows_is_not_measured():
    f = cotuning_finding(None)
    assert f.agrees is None and f.verdict == "not measured"


def _judge(cv_vx: float = 0.02, cv_yaw: float = 0.035):
    """A judge with no per-fold floor fits: the given CVs for every fold."""
    from parknss.experiments.config import VerdictConfig
    from parknss.experiments.judge import judge_from_floor
    from parknss.experiments.noise import NoiseFloor

    return judge_from_floor(NoiseFloor(cv_vx, cv_yaw, 5, "measured"),
                            VerdictConfig(resamples=500))


def _ablations(axes: dict[str, list[tuple[str, float, float]]], folds: int = 4):
    """An ablation result of ``folds`` folds per option: axis -> [(label, vx, yaw)], first
    deployed; the folds differ in level (x1, x1.2, ...) but not in the relative effect."""
    from parknss.experiments.ablations import AblationResult, AxisResult, OptionResult
    from parknss.experiments.noise import NoiseFloor
    from parknss.experiments.sweep import FoldScore

    def opt(axis, label, vx, yaw, deployed):
        scores = [FoldScore(vx * (1 + 0.2 * k), vx, yaw * (1 + 0.2 * k), vx, yaw, 10.0, 3, 12,
                            epochs=10) for k in range(folds)]
        return OptionResult(axis, label, deployed, scores)

    result = [AxisResult(name, [opt(name, *o, i == 0) for i, o in enumerate(opts)], False)
              for name, opts in axes.items()]
    return AblationResult(result, NoiseFloor(vx=0.02, yaw=0.035, n_seeds=5, source="measured"),
                          3000, list(range(folds)))


def _finding(res, start: str, judge=None):
    from parknss.experiments.findings import ablation_findings

    return next(f for f in ablation_findings(res, judge or _judge())
                if f.claim.startswith(start))


def test_normalization_needs_the_tie_and_the_z_score_penalty():
    # 4 folds, seed CV 2 %: a paired effect's interval is about ±2.8 % (tie margin 5 %)
    norm = [("clipped min-max", 0.2, 0.7), ("plain min-max", 0.202, 0.7), ("z-score", 0.24, 0.6)]
    assert _finding(_ablations({"normalization": norm}), "Clipped").verdict == "agrees"
    norm[1] = ("plain min-max", 0.23, 0.7)  # +15 %: no tie
    assert _finding(_ablations({"normalization": norm}), "Clipped").verdict == "differs"
    norm[1], norm[2] = ("plain min-max", 0.2, 0.7), ("z-score", 0.205, 0.6)  # penalty in noise
    f = _finding(_ablations({"normalization": norm}), "Clipped")
    assert f.verdict.startswith("cannot tell at this budget (z-score vx: effect +2.5 %")


def test_schedule_claims_a_vx_gain_and_a_yaw_tie():
    sched = [("cosine", 0.19, 0.70), ("constant", 0.21, 0.70)]  # vx +10.5 %, yaw +0 %
    assert _finding(_ablations({"lr schedule": sched}), "Cosine").verdict == "agrees"
    sched[1] = ("constant", 0.17, 0.70)  # constant better beyond the floor
    assert _finding(_ablations({"lr schedule": sched}), "Cosine").verdict == "differs"
    sched[1] = ("constant", 0.192, 0.70)  # the vx gain inside the floor
    assert _finding(_ablations({"lr schedule": sched}), "Cosine").verdict.startswith(
        "cannot tell")
    # a noisier floor turns the +10.5 % into "cannot tell" too
    sched[1] = ("constant", 0.21, 0.70)
    assert _finding(_ablations({"lr schedule": sched}), "Cosine",
                    _judge(0.117, 0.143)).verdict.startswith("cannot tell")


def test_capacity_agrees_only_when_every_smaller_net_is_worse():
    cap = [("6x128", 0.1, 0.5), ("4x128", 0.12, 0.5), ("6x64", 0.13, 0.5)]
    assert _finding(_ablations({"capacity": cap}), "The deployed six").verdict == "agrees"
    cap[2] = ("6x64", 0.101, 0.5)
    assert _finding(_ablations({"capacity": cap}), "The deployed six").verdict.startswith(
        "cannot tell")
    assert _finding(_ablations({}), "The deployed six").verdict == "not measured"


def _curve(means: list[float], folds: int = 4):
    from parknss.experiments.learning_curve import CurvePoint, LearningCurveResult, fit_power_law
    from parknss.experiments.sweep import FoldScore

    sizes = [4, 8, 12]
    points = [CurvePoint(r, n, list(range(folds)),
                         [FoldScore(m * (1 + 0.01 * k), m, 1.0, m, 1.0, 1.0, 3, n, 10)
                          for k in range(folds)])
              for r, n, m in zip((3, 2, 1), sizes, means, strict=True)]
    return LearningCurveResult(points, {"vx": fit_power_law(sizes, means)}, 16, 3000)


def test_the_learning_curve_descends_only_beyond_the_noise():
    from parknss.experiments.findings import learning_curve_findings

    (f,) = learning_curve_findings(_curve([0.30, 0.20, 0.15]), _judge())
    assert f.verdict == "agrees" and "8->12 vx -25.0 %" in f.measured
    (f,) = learning_curve_findings(_curve([0.30, 0.20, 0.198]), _judge())  # last step -1 %
    assert f.verdict.startswith("cannot tell at this budget (8->12 vx")
    (f,) = learning_curve_findings(_curve([0.30, 0.20, 0.25]), _judge())  # rises
    assert f.verdict == "differs"


def test_table2_findings_pair_each_folds_ratio():
    from parknss.experiments.cv import CVResult
    from parknss.experiments.findings import table2_findings

    def fold(vx, rev, within, beyond):
        return {"errors": {"vx_mse_moving_kmh2": vx, "vx_mse_reverse_kmh2": rev,
                           "yaw_mse_moving_degs2": 1.0,
                           "vx_mse_within_kmh2": within, "vx_mse_beyond_kmh2": beyond,
                           "yaw_mse_within_degs2": 1.0, "yaw_mse_beyond_degs2": 0.5}}

    def res(*folds):
        return CVResult(folds={"nss": list(folds)})

    good = [fold(0.1, 0.05, 0.1, 0.05), fold(0.116, 0.064, 0.1, 0.06),
            fold(0.12, 0.07, 0.11, 0.07), fold(0.09, 0.05, 0.1, 0.055)]
    rev, hor = table2_findings(res(*good), _judge())
    assert rev.verdict == "agrees" and hor.verdict == "agrees"
    assert "beyond vs within vx" in hor.measured
    bad = [fold(0.116, 0.182, 0.1, 0.2), fold(0.1, 0.16, 0.1, 0.18),
           fold(0.12, 0.2, 0.1, 0.22), fold(0.11, 0.17, 0.1, 0.19)]
    rev, hor = table2_findings(res(*bad), _judge())
    assert rev.verdict == "differs" and hor.verdict == "differs"
    # one fold that reverses the sign: the raw means would decide, the interval does not
    mixed = [fold(0.1, 0.05, 0.1, 0.05), fold(0.1, 0.16, 0.1, 0.2)]
    rev, _ = table2_findings(res(*mixed), _judge())
    assert rev.verdict.startswith("cannot tell at this budget")


def test_seed_spread_is_of_the_order_of_the_fold_spread_within_the_factor():
    from parknss.experiments.cv import CVResult
    from parknss.experiments.findings import seed_spread_finding
    from parknss.experiments.noise import NoiseFloor, SeedNoiseResult
    from parknss.experiments.sweep import FoldScore

    def seeds(*vx):
        scores = [FoldScore(v, v, 1.0, v, 1.0, 1.0, 3, 12, 10) for v in vx]
        return SeedNoiseResult("cv", 1, list(range(len(vx))), scores,
                               NoiseFloor(0.02, 0.035, len(vx), "measured"), 3000)

    folds = (0.057, 0.095, 0.121, 0.160)
    cv = CVResult(folds={"nss": [{"errors": {"vx_mse_moving_kmh2": v}} for v in folds]})
    # the same spread on 4 seeds as on the 4 folds: ratio 1, but 4 + 4 values cannot pin
    # it within x3 (the bootstrap interval of an sd ratio is wide); within x20 they can
    same = [v + 0.01 for v in folds]
    f = seed_spread_finding(cv, seeds(*same), 3.0)
    assert "ratio 1.00 [" in f.measured and f.verdict.startswith("cannot tell at this budget")
    assert seed_spread_finding(cv, seeds(*same), 20.0).verdict == "agrees"
    tight = seeds(0.089, 0.0895, 0.0890, 0.0892, 0.0891)  # sd 0.0002 against 0.043
    assert seed_spread_finding(cv, tight, 3.0).verdict == "differs"
    assert seed_spread_finding(cv, None, 3.0).verdict == "not measured"


def test_an_unmeasured_axis_says_how_many_fits_it_lacks():
    from parknss.experiments.ablations import UnmeasuredAxis

    res = _ablations({})
    res.unmeasured = [UnmeasuredAxis(n, 3, 16) for n in ("normalization", "lr schedule",
                                                            "integrator", "capacity")]
    for start in ("Clipped", "Cosine", "Euler", "The deployed six"):
        f = _finding(res, start)
        assert f.verdict == "not measured" and f.measured == (
            "not measured: 3 of 16 fits are not stored")
    assert "not in the ablation config" in _finding(res, "MAE").measured
