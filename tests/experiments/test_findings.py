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


def _ablations(axes: dict[str, list[tuple[str, float, float]]]):
    """An ablation result of one fold per option: axis -> [(label, vx, yaw)], first deployed."""
    from parknss.experiments.ablations import AblationResult, AxisResult, OptionResult
    from parknss.experiments.noise import NoiseFloor
    from parknss.experiments.sweep import FoldScore

    def opt(axis, label, vx, yaw, deployed):
        s = FoldScore(vx, vx, yaw, vx, yaw, 10.0, 3, 12, epochs=10)
        return OptionResult(axis, label, deployed, [s])

    result = [AxisResult(name, [opt(name, *o, i == 0) for i, o in enumerate(opts)], False)
              for name, opts in axes.items()]
    return AblationResult(result, NoiseFloor(vx=0.02, yaw=0.035, n_seeds=5, source="measured"),
                          3000, [0])


def _finding(res, start: str):
    from parknss.experiments.findings import ablation_findings

    return next(f for f in ablation_findings(res) if f.claim.startswith(start))


def test_normalization_needs_the_tie_and_the_z_score_penalty():
    # threshold 2 x 2 % = 4 %: plain +1 % ties, z-score +20 % is a penalty
    norm = [("clipped min-max", 0.2, 0.7), ("plain min-max", 0.202, 0.7), ("z-score", 0.24, 0.6)]
    assert _finding(_ablations({"normalization": norm}), "Clipped").verdict == "agrees"
    norm[1] = ("plain min-max", 0.23, 0.7)  # +15 %: no tie
    assert _finding(_ablations({"normalization": norm}), "Clipped").verdict == "differs"
    norm[1], norm[2] = ("plain min-max", 0.2, 0.7), ("z-score", 0.205, 0.6)  # penalty in noise
    assert _finding(_ablations({"normalization": norm}), "Clipped").verdict == "within noise"


def test_schedule_claims_a_vx_gain_and_a_yaw_tie():
    sched = [("cosine", 0.19, 0.70), ("constant", 0.21, 0.71)]  # vx +10.5 %, yaw +1.4 %
    assert _finding(_ablations({"lr schedule": sched}), "Cosine").verdict == "agrees"
    sched[1] = ("constant", 0.17, 0.71)  # constant better beyond the floor
    assert _finding(_ablations({"lr schedule": sched}), "Cosine").verdict == "differs"
    sched[1] = ("constant", 0.192, 0.71)  # the vx gain inside the floor
    assert _finding(_ablations({"lr schedule": sched}), "Cosine").verdict == "within noise"


def test_capacity_agrees_only_when_every_smaller_net_is_worse():
    cap = [("6x128", 0.1, 0.5), ("4x128", 0.12, 0.5), ("6x64", 0.13, 0.5)]
    assert _finding(_ablations({"capacity": cap}), "The deployed six").verdict == "agrees"
    cap[2] = ("6x64", 0.101, 0.5)
    assert _finding(_ablations({"capacity": cap}), "The deployed six").verdict == "within noise"
    assert _finding(_ablations({}), "The deployed six").verdict == "not measured"


def _curve(means: list[float]):
    from parknss.experiments.learning_curve import CurvePoint, LearningCurveResult, fit_power_law
    from parknss.experiments.sweep import FoldScore

    sizes = [4, 8, 12]
    points = [CurvePoint(r, n, [0], [FoldScore(m, m, 1.0, m, 1.0, 1.0, 3, n, 10)])
              for r, n, m in zip((3, 2, 1), sizes, means, strict=True)]
    return LearningCurveResult(points, {"vx": fit_power_law(sizes, means)}, 16, 3000)


def test_the_learning_curve_descends_only_beyond_the_floor():
    from parknss.experiments.findings import learning_curve_findings
    from parknss.experiments.noise import NoiseFloor

    fl = NoiseFloor(vx=0.02, yaw=0.035, n_seeds=5, source="measured")  # threshold 4 %
    (f,) = learning_curve_findings(_curve([0.30, 0.20, 0.15]), fl)
    assert f.verdict == "agrees" and "8->12 -25.0 %" in f.measured and "seed-noise" in f.measured
    (f,) = learning_curve_findings(_curve([0.30, 0.20, 0.198]), fl)  # last step -1 %: flat
    assert f.verdict == "within noise"
    (f,) = learning_curve_findings(_curve([0.30, 0.20, 0.25]), fl)  # rises at the boundary
    assert f.verdict == "differs"


def test_table2_findings_compare_the_fold_means():
    from parknss.experiments.cv import CVResult
    from parknss.experiments.findings import table2_findings

    def fold(vx, rev, within, beyond):
        return {"errors": {"vx_mse_moving_kmh2": vx, "vx_mse_reverse_kmh2": rev,
                           "vx_mse_within_kmh2": within, "vx_mse_beyond_kmh2": beyond,
                           "yaw_mse_within_degs2": 1.0, "yaw_mse_beyond_degs2": 0.5}}

    def res(*folds):
        return CVResult(folds={"nss": list(folds)})

    rev, hor = table2_findings(res(fold(0.1, 0.05, 0.1, 0.05), fold(0.116, 0.064, 0.1, 0.09)))
    assert rev.verdict == "agrees" and hor.verdict == "agrees"
    assert "vx 0.1 / 0.07" in hor.measured
    # the means decide: one fold worse beyond the horizon, the mean too (0.125 > 0.1)
    rev, hor = table2_findings(res(fold(0.116, 0.182, 0.1, 0.05), fold(0.116, 0.182, 0.1, 0.2)))
    assert rev.verdict == "differs" and "+56.9 %" in rev.measured and hor.verdict == "differs"


def test_seed_spread_is_of_the_order_of_the_fold_spread_within_the_factor():
    from parknss.experiments.cv import CVResult
    from parknss.experiments.findings import seed_spread_finding
    from parknss.experiments.noise import NoiseFloor, SeedNoiseResult
    from parknss.experiments.sweep import FoldScore

    def seeds(*vx):
        scores = [FoldScore(v, v, 1.0, v, 1.0, 1.0, 3, 12, 10) for v in vx]
        return SeedNoiseResult("cv", 1, list(range(len(vx))), scores,
                               NoiseFloor(0.02, 0.035, len(vx), "measured"), 3000)

    # the paper's own numbers: seed std 0.019 against fold std 0.038, a factor 2
    cv = CVResult(folds={"nss": [{"errors": {"vx_mse_moving_kmh2": v}}
                                 for v in (0.057, 0.095, 0.121, 0.160)]})
    f = seed_spread_finding(cv, seeds(0.07, 0.108), 3.0)  # std 0.019
    assert f.verdict == "agrees" and "0.089 ± 0.019" in f.measured
    assert seed_spread_finding(cv, seeds(0.089, 0.0895), 3.0).verdict == "differs"
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
