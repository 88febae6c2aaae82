"""The canonical frame of a plan: the goal pose at the origin with heading 0, the start
on the left (y >= 0; a scene with the start on the right is mirrored).

Hybrid A* bins poses into cells anchored at the frame's origin and heading 0, so a plan
made in world coordinates depends on where the scene sits. Planned in this frame, a
rigid motion of the whole scene (translation, rotation, mirror) gives the same plan moved
with it, up to floating point. The map (the world's axis-aligned bounds) becomes a
rotated rectangle in this frame: the planner tests it in world coordinates
(:meth:`CanonicalFrame.to_world_xy`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from parknss.sim.trajectory import Trajectory


@dataclass(frozen=True)
class CanonicalFrame:
    """World -> canonical: rotate by -heading about (x, y), then y -> ``sign`` * y."""

    x: float
    y: float
    heading: float
    sign: float  # +1, or -1 for a mirrored frame

    @classmethod
    def of(cls, start, goal) -> CanonicalFrame:
        """The frame of the goal pose, mirrored when the start lies right of the goal."""
        gx, gy, gth = (float(v) for v in goal[:3])
        c, s = math.cos(gth), math.sin(gth)
        dx, dy = float(start[0]) - gx, float(start[1]) - gy
        ly = -s * dx + c * dy
        if ly == 0.0:  # on the goal's axis: the start heading decides
            ly = math.sin(float(start[2]) - gth)
        return cls(gx, gy, gth, -1.0 if ly < 0.0 else 1.0)

    def to_canon_xy(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) world points -> canonical, m."""
        p = np.asarray(xy, dtype=float)
        c, s = math.cos(self.heading), math.sin(self.heading)
        dx, dy = p[..., 0] - self.x, p[..., 1] - self.y
        return np.stack([c * dx + s * dy, self.sign * (-s * dx + c * dy)], axis=-1)

    def to_world_xy(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Canonical coordinates (any shape) -> world (x, y), m."""
        c, s = math.cos(self.heading), math.sin(self.heading)
        y = self.sign * y
        return self.x + c * x - s * y, self.y + s * x + c * y

    def to_canon_pose(self, pose) -> tuple[float, float, float]:
        xy = self.to_canon_xy(np.asarray(pose[:2], dtype=float))
        th = self.sign * (float(pose[2]) - self.heading)
        return (float(xy[0]), float(xy[1]), th)

    def to_canon_polygon(self, poly: np.ndarray) -> np.ndarray:
        """A CCW polygon (M, 2) in the canonical frame, still CCW (mirrored: reversed)."""
        q = self.to_canon_xy(poly)
        return q[::-1].copy() if self.sign < 0 else q

    def to_world_poses(self, poses: np.ndarray) -> np.ndarray:
        """(N, 3+) canonical poses -> world (extra columns kept)."""
        out = np.array(poses, dtype=float)
        out[:, 0], out[:, 1] = self.to_world_xy(poses[:, 0], poses[:, 1])
        out[:, 2] = self.heading + self.sign * poses[:, 2]
        return out

    def to_world_trajectory(self, traj: Trajectory) -> Trajectory:
        """A trajectory planned in this frame, in world coordinates (mirrored steering
        changes sign)."""
        segs = [
            replace(
                seg,
                poses=self.to_world_poses(seg.poses),
                steer=None if seg.steer is None else self.sign * np.asarray(seg.steer),
            )
            for seg in traj.segments
        ]
        return Trajectory(segs, source=traj.source, info=dict(traj.info))


@dataclass
class CanonicalScene:
    """A scene in its canonical frame: what the search sees.

    ``bounds``: the bounding box of the world map in this frame (the map itself is
    ``world_bounds`` in world coordinates); ``obstacles``: CCW convex parts, m.
    """

    frame: CanonicalFrame
    world_bounds: tuple[float, float, float, float]
    bounds: tuple[float, float, float, float]
    obstacles: list[np.ndarray]
    start: tuple[float, float, float]
    goal: tuple[float, float, float]

    @classmethod
    def of(cls, scene, canonical: bool = True) -> CanonicalScene:
        """``scene`` in its canonical frame; ``canonical=False``: the world frame itself
        (the identity transform, bit for bit)."""
        if canonical:
            frame = CanonicalFrame.of(scene.start, scene.goal)
        else:
            frame = CanonicalFrame(0.0, 0.0, 0.0, 1.0)
        xmin, ymin, xmax, ymax = (float(v) for v in scene.bounds)
        box = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
        corners = frame.to_canon_xy(box)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        return cls(
            frame,
            (xmin, ymin, xmax, ymax),
            (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
            [frame.to_canon_polygon(o) for o in scene.obstacle_arrays()],
            frame.to_canon_pose(scene.start),
            frame.to_canon_pose(scene.goal),
        )

    def obstacle_arrays(self) -> list[np.ndarray]:
        return self.obstacles

    def inside_map(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Boolean (same shape): canonical points inside the world map."""
        wx, wy = self.frame.to_world_xy(x, y)
        xmin, ymin, xmax, ymax = self.world_bounds
        return (wx >= xmin) & (wx <= xmax) & (wy >= ymin) & (wy <= ymax)

    def map_edge_distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Signed distance (m) of canonical points to the world map's edge (< 0 outside)."""
        wx, wy = self.frame.to_world_xy(x, y)
        xmin, ymin, xmax, ymax = self.world_bounds
        return np.minimum(np.minimum(wx - xmin, xmax - wx), np.minimum(wy - ymin, ymax - wy))
