"""The studies' arithmetic: power law, coefficient of variation, noise floor, windows."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parknss.errors import ConfigError, DataError
from parknss.experiments.ablations import padding_fraction, resolve_window
from parknss.experiments.config import (
    AblationAxis,
    ExperimentsConfig,
    load_experiments_config,
    merge_overrides,
)
from parknss.experiments.learning_curve import fit_power_law
from parknss.experiments.noise import NoiseFloor, coefficient_of_variation
from parknss.experiments.sweep import relative_effect


def test_power_law_recovers_exact_coefficients():
    n = np.array([4.0, 8.0, 12.0])
    e = 0.9 * n**-0.75
    fit = fit_power_law(n, e)
    assert fit.a == pytest.approx(0.9, rel=1e-10)
    assert fit.b == pytest.approx(0.75, rel=1e-10)
    assert float(fit(16)) == pytest.approx(0.9 * 16**-0.75, rel=1e-10)


def test_power_law_of_rising_errors_has_negative_exponent():
    fit = fit_power_law([4, 8, 12], [0.1, 0.2, 0.3])
    assert fit.b < 0


def test_power_law_needs_two_sizes():
    with pytest.raises(DataError):
        fit_power_law([12, 12], [0.1, 0.2])
    with pytest.raises(DataError):
        fit_power_law([4, 8], [0.1, -1.0])


def test_cv_of_constant_errors_is_zero_and_matches_numpy():
    assert coefficient_of_variation([0.2, 0.2, 0.2]) == 0.0
    x = [0.089, 0.070, 0.108, 0.095]
    ref = np.std(x, ddof=1) / np.mean(x)
    assert coefficient_of_variation(x) == pytest.approx(ref, rel=1e-12)
    assert math.isnan(coefficient_of_variation([0.1]))
    assert math.isnan(coefficient_of_variation([0.1, float("nan")]))


def test_noise_floor_verdicts():
    fl = NoiseFloor(vx=0.02, yaw=0.035, n_seeds=5, source="measured", z=2.0, max_threshold=0.1)
    assert fl.threshold("vx") == pytest.approx(0.04)
    assert fl.exceeds(0.27, "vx") is True
    assert fl.exceeds(-0.03, "vx") is False
    assert fl.exceeds(float("nan"), "vx") is None
    assert fl.confirms_null(0.01, "yaw") is True
    assert fl.confirms_null(0.5, "yaw") is False
    wide = NoiseFloor(vx=0.5, yaw=0.5, n_seeds=3, source="measured", z=2.0, max_threshold=0.1)
    assert wide.confirms_null(0.01, "vx") is None  # too wide to confirm "no effect"
    assert NoiseFloor.from_json(fl.to_json()) == fl


def test_relative_effect():
    assert relative_effect(0.127, 0.1) == pytest.approx(0.27)
    assert math.isnan(relative_effect(0.1, 0.0))


def test_window_rules():
    lengths = [100, 150, 200]
    assert resolve_window("shortest", lengths) == 100
    assert resolve_window("longest", lengths) == 200
    # at L = 200 every trial is one sequence: padding (100 + 50) / 600
    assert padding_fraction(lengths, 200) == pytest.approx(0.25)
    assert padding_fraction(lengths, 100) == 0.0
    L = resolve_window("padding:0.10", lengths)
    assert padding_fraction(lengths, L) >= 0.10 > padding_fraction(lengths, L - 1)


def test_merge_overrides_is_fieldwise():
    out = merge_overrides({"train": {"epochs": 3, "lr": 1e-3}}, None, {"train": {"lr": 2e-3}})
    assert out == {"train": {"epochs": 3, "lr": 2e-3}}


def test_config_rejects_bad_axes(tmp_path):
    with pytest.raises(ValueError, match="deployed"):
        AblationAxis(name="x", options=[{"label": "a"}, {"label": "b"}])
    with pytest.raises(ValueError, match="window"):
        AblationAxis(
            name="x",
            options=[{"label": "a", "deployed": True}, {"label": "b", "window": "padding:2"}],
        )
    bad = tmp_path / "bad.yaml"
    bad.write_text("floor_z: -1\n")
    with pytest.raises(ConfigError, match="floor_z"):
        load_experiments_config(bad)


def test_shipped_config_has_the_paper_budget_and_axes():
    cfg = load_experiments_config()
    assert isinstance(cfg, ExperimentsConfig)
    assert cfg.full.epochs == 3000 and cfg.full.convergence_epochs == 3200
    assert cfg.learning_curve_rs == [1, 2, 3]
    names = {a.name for a in cfg.axes}
    assert {
        "normalization",
        "loss",
        "lr schedule",
        "training window",
        "yaw readout",
        "integrator",
        "capacity",
    } <= names


def test_findings_verdicts_follow_the_floor():
    from parknss.experiments.ablations import AblationResult, AxisResult, OptionResult
    from parknss.experiments.findings import ablation_findings
    from parknss.experiments.sweep import FoldScore

    def opt(axis, label, vx, deployed=False, wall=10.0):
        s = FoldScore(vx, vx, 1.0, vx, 1.0, wall, 3, 12, epochs=10)
        return OptionResult(axis, label, deployed, [s])

    fl = NoiseFloor(vx=0.02, yaw=0.035, n_seeds=5, source="measured")
    res = AblationResult(
        [
            AxisResult(
                "yaw readout", [opt("y", "res", 0.1, True), opt("y", "direct", 0.127)], False
            ),
            AxisResult("loss", [opt("l", "MAE", 0.1, True), opt("l", "MSE", 0.101)], False),
            AxisResult(
                "integrator",
                [
                    opt("i", "Euler (fused)", 0.1, True, wall=10.0),
                    opt("i", "Euler (eager)", 0.1, wall=20.0),
                    opt("i", "RK4", 0.1005, wall=60.0),
                ],
                True,
                "fast",
            ),
        ],
        fl,
        3000,
        [0],
    )
    from parknss.experiments.config import VerdictConfig
    from parknss.experiments.judge import judge_from_floor

    # one fold, seed CV 2 %: a paired effect's interval is ±1.96·sqrt 2·2 % = ±5.5 %
    found = {f.claim.split(" (")[0]: f
             for f in ablation_findings(res, judge_from_floor(fl, VerdictConfig()))}
    readout = next(f for c, f in found.items() if c.startswith("The residual"))
    assert readout.verdict == "agrees"  # +27 % [+21.5, +32.5]
    loss = next(f for c, f in found.items() if c.startswith("MAE"))
    assert loss.verdict.startswith("cannot tell at this budget (MSE vx: effect +1.0 %")
    window = next(f for c, f in found.items() if c.startswith("The shortest"))
    assert window.verdict == "not measured"
    euler = next(f for c, f in found.items() if c.startswith("Euler"))
    assert euler.verdict.startswith("cannot tell")  # +0.5 % ± 5.5 % cannot show a 1 % tie
    narrow = NoiseFloor(vx=0.001, yaw=0.001, n_seeds=5, source="measured")
    euler = next(f for f in ablation_findings(res, judge_from_floor(narrow, VerdictConfig()))
                 if f.claim.startswith("Euler"))
    assert euler.agrees is True and "x3.00 vs eager Euler" in euler.measured
    assert "(fast recipe; the floor's fits: paper)" in euler.measured
    from parknss.experiments.study_tables import ablation_tables

    rows = ablation_tables(res)[0].rows  # a fast-recipe axis says so on each of its rows
    assert all(("fast recipe" in r[-1]) == (r[0] == "integrator") for r in rows)
    assert {a["name"]: a["recipe"] for a in res.to_json()["axes"]}["integrator"] == "fast"


def test_integrator_cost_is_cpu_time_when_every_fit_has_it():
    from parknss.experiments.ablations import AblationResult, AxisResult, OptionResult
    from parknss.experiments.findings import ablation_findings
    from parknss.experiments.study_tables import ablation_tables
    from parknss.experiments.sweep import FoldScore

    def opt(label, vxs, walls, cpus, deployed=False):
        scores = [FoldScore(v, v, 1.0, v, 1.0, w, 3, 12, epochs=10, cpu_s=c)
                  for v, w, c in zip(vxs, walls, cpus, strict=True)]
        return OptionResult("integrator", label, deployed, scores)

    nan = math.nan
    # the RK4 fits shared their core (wall 2x their CPU): the CPU ratio is the cost
    axis = AxisResult("integrator", [
        opt("Euler (fused)", [0.1, 0.2], [10.0, 10.0], [10.0, 10.0], deployed=True),
        opt("Euler (eager)", [0.1, 0.2], [20.0, 20.0], [20.0, 20.0]),
        opt("RK4", [0.101, 0.196], [140.0, 140.0], [70.0, 70.0]),
    ], True, "fast")
    fl = NoiseFloor(vx=0.02, yaw=0.035, n_seeds=5, source="measured")
    res = AblationResult([axis], fl, 3000, [0, 1])
    assert axis.cost_basis("RK4") == "CPU" and axis.cost_ratio("RK4", "Euler (eager)") == 3.5
    from parknss.experiments.config import VerdictConfig
    from parknss.experiments.judge import judge_from_floor

    judge = judge_from_floor(fl, VerdictConfig(resamples=200))
    euler = next(f for f in ablation_findings(res, judge) if f.claim.startswith("Euler"))
    assert "x7.00 vs fused Euler (CPU per step), x3.50 vs eager Euler (CPU" in euler.measured
    # paired per fold (+1.0 / -2.0 %): the mean -0.5 %, its interval wider than ±1 %
    assert "RK4 vx -0.5 %" in euler.measured and euler.agrees is None
    row = next(r for r in ablation_tables(res)[0].rows if r[1] == "RK4")
    assert row[9:11] == [7.0, "x7.00 (CPU)"]
    # one fold's fit without its CPU time: that option's cost falls back to wall
    axis.options[2].scores[1].cpu_s = nan
    assert axis.cost_basis("RK4") == "wall" and axis.cost_ratio("RK4") == 14.0
    assert axis.cost_basis("Euler (eager)") == "CPU"
