"""Reeds-Shepp curves against the independent `rsplan` implementation and geometry."""

import itertools
import math

import numpy as np
import pytest
from rsplan import planner as rsplan_planner

from parknss.errors import PlanningError
from parknss.sim.planning import reeds_shepp as rs

R = 4.6


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def _random_pairs(n, seed, span=12.0):
    rng = np.random.default_rng(seed)
    a = np.column_stack([rng.uniform(-span, span, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    b = np.column_stack([rng.uniform(-span, span, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    return a, b


def test_shortest_length_equals_minimum_over_rsplan_candidates():
    # rsplan's path() prefers fewer segments; _solve_path returns every candidate word
    starts, goals = _random_pairs(2500, seed=1)
    worst = 0.0
    for s, g in zip(starts, goals, strict=True):
        s, g = tuple(s), tuple(g)
        ref = min(p.total_length for p in rsplan_planner._solve_path(s, g, R, 0.1))
        ours = rs.shortest_path(s, g, R).length
        assert abs(ours - rs.shortest_length(s, g, R)) < 1e-9
        worst = max(worst, abs(ours - ref))
    assert worst < 1e-6


def test_every_candidate_integrates_and_samples_to_the_goal():
    starts, goals = _random_pairs(150, seed=2)
    for s, g in zip(starts, goals, strict=True):
        for path in rs.all_paths(s, g, R):
            end = path.end_pose()
            assert math.hypot(end[0] - g[0], end[1] - g[1]) < 1e-8
            assert abs(_wrap(end[2] - g[2])) < 1e-8
            samp = path.sample(0.1)
            assert samp.shape[1] == 4
            np.testing.assert_allclose(samp[0, :3], s, atol=1e-12)
            assert samp[-1, 0] == g[0] and samp[-1, 1] == g[1]
            assert abs(_wrap(samp[-1, 2] - g[2])) < 1e-12
            # the sample just before the goal is within one step of it
            assert math.hypot(*(samp[-1, :2] - samp[-2, :2])) <= 0.1 + 1e-9
            assert set(np.unique(samp[:, 3])) <= {-1.0, 1.0}


def test_sampling_respects_step_and_heading_limits():
    path = rs.shortest_path((0.0, 0.0, 0.0), (-3.0, 4.0, 2.5), R)
    samp = path.sample(0.05, math.radians(0.5))
    ds = np.hypot(*np.diff(samp[:, :2], axis=0).T)
    dth = np.abs(np.diff(samp[:, 2]))
    assert ds.max() <= 0.05 + 1e-9
    assert dth.max() <= math.radians(0.5) + 1e-9
    # total sampled arc length equals the path length (arcs: chord ~ arc at this step)
    assert abs(ds.sum() - path.length) < 1e-3


def test_the_48_words_of_reeds_and_shepp():
    base = [
        "L+S+L+", "L+S+R+", "L+R-L+", "L+R-L-", "L+R+L-", "L+R+L-R-", "L+R-L-R+",
        "L+R-S-L-", "L+R-S-R-", "L+S+R+L-", "L+S+L+R-", "L+R-S-L-R+",
    ]  # fmt: skip

    def reflect(w):
        return w.translate(str.maketrans("LR", "RL"))

    def timeflip(w):
        return w.translate(str.maketrans("+-", "-+"))

    expected = {
        f(w) for w in base for f in (str, reflect, timeflip, lambda x: reflect(timeflip(x)))
    }
    assert len(expected) == 48
    rng = np.random.default_rng(3)
    seen = set()
    for _ in range(6000):
        g = (rng.uniform(-15, 15), rng.uniform(-15, 15), rng.uniform(-math.pi, math.pi))
        seen.update(p.signature for p in rs.all_paths((0.0, 0.0, 0.0), g, 1.0))
    assert seen == expected


def test_straight_ahead_and_segment_bookkeeping():
    path = rs.shortest_path(
        (1.0, 2.0, 0.3), (1.0 + 5 * math.cos(0.3), 2.0 + 5 * math.sin(0.3), 0.3), R
    )
    assert abs(path.length - 5.0) < 1e-9
    assert path.cusps == 0
    assert [s.kind for s in path.segments] == ["S"]
    # behind: straight reverse
    back = rs.shortest_path((0.0, 0.0, 0.0), (-2.0, 0.0, 0.0), R)
    assert abs(back.length - 2.0) < 1e-9 and back.segments[0].direction == -1
    # segment lengths add up and cusps count direction changes
    p = rs.shortest_path((0.0, 0.0, 0.0), (0.5, 1.0, math.pi / 2), R)
    assert abs(sum(abs(s.length) for s in p.segments) - p.length) < 1e-12
    dirs = [s.direction for s in p.segments]
    assert p.cusps == sum(a != b for a, b in itertools.pairwise(dirs))
    # radius scaling: lengths scale with the radius for scaled poses
    q1 = rs.shortest_length((0, 0, 0), (2.0, 1.0, 1.0), 1.0)
    q2 = rs.shortest_length((0, 0, 0), (2.0 * R, 1.0 * R, 1.0), R)
    assert abs(q2 - R * q1) < 1e-9


def test_zero_length_and_bad_radius():
    p = rs.shortest_path((1.0, 1.0, 0.5), (1.0, 1.0, 0.5), R)
    assert p.length < 1e-12 and len(p.sample(0.1)) == 1
    with pytest.raises(PlanningError):
        rs.shortest_path((0, 0, 0), (1, 0, 0), 0.0)
    with pytest.raises(PlanningError):
        rs.shortest_path((0, 0, 0), (1, 0, 0), R).sample(0.0)
