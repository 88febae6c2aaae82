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

from parknss.sim.scenarios import Obstacle, Scene, map_planes
from parknss.sim.trajectory import Trajectory

AXIS_ALIGNED_RTOL = 1e-9
"""A moved map outline whose corners lie this close (relative to its size) to its
bounding box is that box."""


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

    def to_canon_scene(self, scene: Scene) -> Scene:
        """``scene`` moved into this frame, a :class:`Scene` like any other: obstacles,
        start, goal and the map (its outline, or its box's corners; an outline that comes
        out axis-aligned, as a goal-aligned TPCAP map does, becomes the box ``bounds``)."""
        if scene.map_outline is not None:
            corners = np.asarray(scene.map_outline, dtype=float)
        else:
            xmin, ymin, xmax, ymax = (float(v) for v in scene.bounds)
            corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
        q = self.to_canon_polygon(corners)
        lo, hi = q.min(axis=0), q.max(axis=0)
        bounds = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        span = float(np.max(hi - lo))
        on_box = np.minimum(np.abs(q - lo), np.abs(q - hi)).max(axis=1)
        aligned = len(q) == 4 and bool(np.all(on_box <= AXIS_ALIGNED_RTOL * span))
        obstacles = tuple(
            Obstacle(
                o.kind,
                self.to_canon_polygon(o.vertices),
                tuple(self.to_canon_polygon(p) for p in o.parts),
            )
            for o in scene.obstacles
        )
        out = replace(
            scene,
            bounds=bounds,
            obstacles=obstacles,
            start=self.to_canon_pose(scene.start),
            goal=self.to_canon_pose(scene.goal),
            map_outline=None if aligned else tuple((float(a), float(b)) for a, b in q),
        )
        return out

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
    planes: tuple[np.ndarray, np.ndarray] | None = None  # the map outline's, canonical

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
        if getattr(scene, "map_outline", None) is not None:
            box = np.asarray(scene.map_outline, dtype=float)
        corners = frame.to_canon_polygon(box)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        planes = None
        if getattr(scene, "map_outline", None) is not None:
            planes = map_planes(None, corners)
        return cls(
            frame,
            (xmin, ymin, xmax, ymax),
            (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
            [frame.to_canon_polygon(o) for o in scene.obstacle_arrays()],
            frame.to_canon_pose(scene.start),
            frame.to_canon_pose(scene.goal),
            planes,
        )

    def obstacle_arrays(self) -> list[np.ndarray]:
        return self.obstacles

    def inside_map(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Boolean (same shape): canonical points inside the world map."""
        if self.planes is not None:
            return self.map_edge_distance(x, y) >= 0.0
        wx, wy = self.frame.to_world_xy(x, y)
        xmin, ymin, xmax, ymax = self.world_bounds
        return (wx >= xmin) & (wx <= xmax) & (wy >= ymin) & (wy <= ymax)

    def map_edge_distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Signed distance (m) of canonical points to the world map's edge (< 0 outside)."""
        if self.planes is not None:
            A, b = self.planes
            x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
            out = b[0] - A[0, 0] * x - A[0, 1] * y
            for k in range(1, len(b)):
                out = np.minimum(out, b[k] - A[k, 0] * x - A[k, 1] * y)
            return out
        wx, wy = self.frame.to_world_xy(x, y)
        xmin, ymin, xmax, ymax = self.world_bounds
        return np.minimum(np.minimum(wx - xmin, xmax - wx), np.minimum(wy - ymin, ymax - wy))


def snap_scene(scene: Scene, snap: float) -> Scene:
    """``scene`` with every coordinate (m) and heading (rad) rounded to a multiple of
    ``snap``: the same scene moved elsewhere, whose canonical transform differs in the
    last bits (~1e-13 m), becomes bit-identical (unless a number lies within those bits
    of a rounding boundary, about 1e-7 of the time at 1e-6)."""

    def r(v):
        return np.round(np.asarray(v, dtype=float) / snap) * snap

    def t(v):
        return tuple(float(x) for x in r(v))

    return replace(
        scene,
        bounds=t(scene.bounds),
        obstacles=tuple(
            Obstacle(o.kind, r(o.vertices), tuple(r(p) for p in o.parts))
            for o in scene.obstacles
        ),
        start=t(scene.start),
        goal=t(scene.goal),
        map_outline=None
        if scene.map_outline is None
        else tuple(t(p) for p in scene.map_outline),
    )


def snap_trajectory(traj: Trajectory, snap: float) -> Trajectory:
    """``traj`` with its poses' x, y (m), heading (rad) and steering-wheel angle (deg)
    rounded to multiples of ``snap`` (see :func:`snap_scene`)."""
    segs = []
    for seg in traj.segments:
        poses = np.array(seg.poses, dtype=float)
        poses[:, :3] = np.round(poses[:, :3] / snap) * snap
        steer = None if seg.steer is None else np.round(np.asarray(seg.steer) / snap) * snap
        segs.append(replace(seg, poses=poses, steer=steer))
    return Trajectory(segs, source=traj.source, info=dict(traj.info))


def move_scene(scene: Scene, angle: float, shift, mirror: bool = False) -> Scene:
    """``scene`` moved rigidly: mirrored in y (first, when ``mirror``), rotated by
    ``angle`` rad about the origin, then shifted by ``shift`` (x, y m). The map moves
    with it: its outline (or its box's corners) becomes the moved scene's outline."""
    m = -1.0 if mirror else 1.0
    c, s = math.cos(angle), math.sin(angle)

    def xy(p):
        p = np.asarray(p, dtype=float)
        x, y = p[..., 0], m * p[..., 1]
        return np.stack([c * x - s * y + shift[0], s * x + c * y + shift[1]], axis=-1)

    def pose(p):
        q = xy(p[:2])
        return (float(q[0]), float(q[1]), angle + m * float(p[2]))

    def poly(v):
        q = xy(v)
        return q[::-1].copy() if mirror else q

    if scene.map_outline is not None:
        corners = np.asarray(scene.map_outline, dtype=float)
    else:
        xmin, ymin, xmax, ymax = (float(v) for v in scene.bounds)
        corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
    outline = poly(corners)
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    return replace(
        scene,
        bounds=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
        obstacles=tuple(
            Obstacle(o.kind, poly(o.vertices), tuple(poly(p) for p in o.parts))
            for o in scene.obstacles
        ),
        start=pose(scene.start),
        goal=pose(scene.goal),
        map_outline=tuple((float(a), float(b)) for a, b in outline),
    )
