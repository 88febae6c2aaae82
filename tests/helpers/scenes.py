"""Hand-made scenes and trajectories for the tracker and closed-loop tests."""

from __future__ import annotations

import numpy as np

from parknss.sim.plants import integrate_poses
from parknss.sim.scenarios import Obstacle, Scene
from parknss.sim.trajectory import Segment, Trajectory


def straight_segment(direction: int, length: float = 5.0) -> Segment:
    """A straight segment along +x from the origin, driven in ``direction`` (+1 / -1)."""
    xs = np.linspace(0.0, direction * length, 26)
    return Segment(np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)]), direction)


def arc_scene() -> tuple[Scene, Trajectory]:
    """Drive 4 m straight, then reverse 5 m on a left-lock-side arc of radius 6 m."""
    s1 = straight_segment(1, 4.0)
    n = 101
    steps = np.full(n - 1, -0.05)
    arc = integrate_poses((4.0, 0.0, 0.0), steps, steps / 6.0, dt=1.0)
    traj = Trajectory([s1, Segment(arc, -1)], source="test")
    box = np.array([[5.0, 1.6], [7.0, 1.6], [7.0, 2.1], [5.0, 2.1]])  # 0.61 m left of the plan
    scene = Scene(
        (-10.0, -10.0, 20.0, 10.0), (Obstacle("car", box),), (0.0, 0.0, 0.0), tuple(arc[-1])
    )
    return scene, traj


def shuffle_scene(strokes: int = 20, length: float = 0.15, radius: float = 5.0):
    """Turn on the spot by ``strokes`` short arcs (m, m), forward on the left lock side and
    reverse on the right: the slot shuffle's kind of plan, each stroke a few decimetres."""
    pose, segments = (0.0, 0.0, 0.0), []
    for i in range(strokes):
        d = 1 if i % 2 == 0 else -1
        steps = np.full(15, d * length / 15)
        poses = integrate_poses(pose, steps, steps * d / radius, dt=1.0)
        segments.append(Segment(poses, d))
        pose = tuple(poses[-1])
    scene = Scene((-10.0, -10.0, 10.0, 10.0), (), (0.0, 0.0, 0.0), pose)
    return scene, Trajectory(segments, source="test")
