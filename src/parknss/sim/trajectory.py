"""The planned motion handed from the planners to the tracker.

A Trajectory is a sequence of gear segments; within a segment the direction of travel is
constant (+1 drive, -1 reverse) and consecutive segments meet at a cusp where the car
stops. Poses are rear-axle centre (x m, y m, heading rad, counter-clockwise from +x).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Segment:
    """One gear segment.

    Attributes:
        poses: (N, 3) rear-axle poses [x, y, heading], N >= 2, ending at the cusp or goal.
        direction: +1 (drive, forward) or -1 (reverse).
        speed: (N,) planned speed magnitude in m/s (>= 0; 0 at the segment's end), or None
            if the planner gave no profile (the tracker then uses its own).
        steer: (N,) planned steering-wheel angle in deg, or None.
        t: (N,) planned time stamps in s from the segment start, or None.
    """

    poses: np.ndarray
    direction: int
    speed: np.ndarray | None = None
    steer: np.ndarray | None = None
    t: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.poses = np.asarray(self.poses, dtype=float)
        if self.poses.ndim != 2 or self.poses.shape[1] != 3 or len(self.poses) < 2:
            raise ValueError(f"segment poses must be (N>=2, 3), got {self.poses.shape}")
        if self.direction not in (1, -1):
            raise ValueError(f"segment direction must be +1 or -1, got {self.direction}")

    @property
    def arc_length(self) -> np.ndarray:
        """(N,) cumulative arc length from the segment start, m."""
        d = np.hypot(np.diff(self.poses[:, 0]), np.diff(self.poses[:, 1]))
        return np.concatenate([[0.0], np.cumsum(d)])

    @property
    def length(self) -> float:
        return float(self.arc_length[-1])


@dataclass
class Trajectory:
    """A parking plan: gear segments in driving order, plus how it was made."""

    segments: list[Segment]
    source: str = "hybrid_astar"  # or "refined", or "coarse_fallback"
    info: dict = field(default_factory=dict)

    @property
    def length(self) -> float:
        return float(sum(s.length for s in self.segments))

    @property
    def cusps(self) -> int:
        """Number of direction changes (stops between segments)."""
        return max(len(self.segments) - 1, 0)

    def poses(self) -> np.ndarray:
        """(M, 3) all poses in order (the shared cusp pose appears once per segment)."""
        return np.concatenate([s.poses for s in self.segments], axis=0)

    def directions(self) -> np.ndarray:
        """(M,) direction of travel of each pose of :meth:`poses`."""
        return np.concatenate([np.full(len(s.poses), s.direction) for s in self.segments])

    def digest(self) -> str:
        """Short SHA-256 of everything the tracker reads (per segment: direction, poses,
        speed, steering, time stamps, as float64 bytes): equal digests, the same drive."""
        h = hashlib.sha256()
        for s in self.segments:
            h.update(str(int(s.direction)).encode())
            for a in (s.poses, s.speed, s.steer, s.t):
                h.update(b"-" if a is None else np.ascontiguousarray(a, dtype=float).tobytes())
        return h.hexdigest()[:16]
