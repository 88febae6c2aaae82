"""The fidelity computation (parknss.sim.fidelity) on runs of chain and truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helpers.scenes import arc_scene
from parknss.sim.closed_loop import ClosedLoopConfig
from parknss.sim.fidelity import (
    FidelityConfig,
    cell_seed,
    compare_outcomes,
    fidelity_text,
    held,
    load_fidelity_config,
    summarize_fidelity,
)
from parknss.sim.session import run_cell


@pytest.fixture(scope="module")
def runs():
    """The hand-made arc scene driven under the chain and under the truth."""
    scene, traj = arc_scene()
    _, (chain, truth) = run_cell(
        scene, ["chain", "reference"], ClosedLoopConfig(plant_seed=7), trajectory=traj
    )
    assert chain.completed and truth.completed
    return chain, truth


def delayed(o, delay_s: float):
    """``o`` with ``delay_s`` of standstill (its first sample held) before the run."""
    dt = float(o.series["t"][1] - o.series["t"][0])
    k = round(delay_s / dt)
    series = {c: np.concatenate([np.full(k, v[0]), v]) for c, v in o.series.items()}
    series["t"] = np.arange(len(series["x"])) * dt
    return dataclasses.replace(o, series=series, duration_s=float(series["t"][-1]))


def stretched(o, factor: float):
    """``o`` run ``factor`` times slower: every channel sampled (previous sample) at
    t / factor, so that the gear stays a gear."""
    t = o.series["t"]
    tn = np.arange(round(t[-1] * factor / 0.01) + 1) * 0.01
    idx = np.minimum(np.floor(tn / factor / 0.01 + 1e-9).astype(int), len(t) - 1)
    series = {c: v[idx] for c, v in o.series.items()}
    series["t"] = tn
    return dataclasses.replace(o, series=series, duration_s=float(tn[-1]))


@pytest.mark.parametrize("which", [0, 1])
def test_identical_runs_agree_perfectly(runs, which):
    o = runs[which]
    c = compare_outcomes(o, o, "same")
    assert c.outcome_agree and not c.collision_where_truth_parks
    assert c.duration_ratio == 1.0
    assert c.iso_vx == pytest.approx(1.0, abs=1e-12)
    assert c.iso_yaw_rate == pytest.approx(1.0, abs=1e-12)
    assert c.goal_diff_cm == 0 and c.heading_diff_deg == 0 and c.clearance_diff_cm == 0
    for v in (c.rmse_vx_ms, c.rmse_yaw_rate_dps, c.rmse_ax_ms2, c.rmse_steer_deg):
        assert v == 0
    assert c.gear_sequence_agree and c.gear_timing_mean_s == 0
    s = summarize_fidelity([c, c, None])
    assert (s.cells, s.executed, s.both_completed) == (3, 2, 2)
    assert s.duration_dev_median == 0 and s.duration_dev_p90 == 0
    assert s.phase_ratio_median == {"forward": 1.0, "reverse": 1.0, "stand": 1.0}
    assert c.truth_forward_s > 0 and c.truth_reverse_s > 0 and c.truth_stand_s > 0
    total = c.truth_forward_s + c.truth_reverse_s + c.truth_stand_s
    assert total == pytest.approx(len(o.series["t"]) * 0.01)
    assert all(t.passed for t in s.targets), fidelity_text(s)


def test_a_delayed_trace_gives_the_expected_ratio_and_gear_timing(runs):
    truth = runs[1]
    late = delayed(truth, 2.0)
    c = compare_outcomes(late, truth, "late")
    assert c.duration_ratio == pytest.approx((truth.duration_s + 2.0) / truth.duration_s)
    assert c.gear_sequence_agree and c.gear_timing_mean_s == pytest.approx(2.0)
    assert c.goal_diff_cm == 0 and c.outcome_agree
    assert c.iso_vx < 1.0 and c.rmse_vx_ms > 0  # the late run is scored for being late
    # the delay is standing time: forward and reverse times are the truth's
    assert c.chain_stand_s == pytest.approx(c.truth_stand_s + 2.0)
    assert (c.chain_forward_s, c.chain_reverse_s) == (c.truth_forward_s, c.truth_reverse_s)
    s = summarize_fidelity([c])
    assert s.duration_dev_median == pytest.approx(2.0 / truth.duration_s)


def test_a_stretched_trace_gives_its_stretch_as_the_ratio(runs):
    truth = runs[1]
    slow = stretched(truth, 1.25)
    c = compare_outcomes(slow, truth, "slow")
    assert c.duration_ratio == pytest.approx(1.25, abs=1e-3)
    assert c.gear_sequence_agree
    assert c.gear_timing_mean_s > 0
    s = summarize_fidelity([c, compare_outcomes(truth, truth)])
    assert s.duration_dev_median == pytest.approx(0.125, abs=1e-3)
    failed = [t.label for t in s.targets if not t.passed]
    assert any("90th" in f for f in failed)  # a 25 % stretch breaks the 15 % line


def test_chain_against_truth_is_scored_from_both_runs(runs):
    chain, truth = runs
    c = compare_outcomes(chain, truth, "arc")
    assert c.duration_ratio == pytest.approx(chain.duration_s / truth.duration_s)
    assert c.goal_diff_cm == pytest.approx(chain.goal_error_cm - truth.goal_error_cm)
    assert 0.0 <= c.iso_vx <= 1.0 and 0.0 <= c.iso_yaw_rate <= 1.0
    assert c.chain_gear_changes >= 2 and c.truth_gear_changes >= 2


def test_a_collision_where_the_truth_parks_is_flagged(runs):
    chain, truth = runs
    crashed = dataclasses.replace(chain, reason="collision", completed=False)
    c = compare_outcomes(crashed, truth)
    assert not c.outcome_agree and c.collision_where_truth_parks
    s = summarize_fidelity([c])
    assert s.both_completed == 0 and s.duration_dev_median is None
    assert not s.targets[0].passed and not s.targets[1].passed


def test_held_extends_with_the_last_sample():
    assert held({"v": np.array([1.0, 2.0])}, "v", 4).tolist() == [1.0, 2.0, 2.0, 2.0]


def test_cell_seeds_are_fresh_and_deterministic():
    a, b = cell_seed(44000, "3"), cell_seed(44000, "4")
    assert a == cell_seed(44000, "3") and a != b and a != cell_seed(1, "3")


def test_config_file_matches_the_defaults():
    assert load_fidelity_config() == FidelityConfig()
