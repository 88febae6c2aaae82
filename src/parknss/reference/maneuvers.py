"""Maneuver plans of the synthetic campaign: segments of a park-in or park-out, seeded.

A plan is what an automated parking system (APS) has decided before it moves: a list of
segments, each driven in one gear over a path length with a speed and a steering profile
over the travelled fraction. Park-in plans are multi-segment with a reversal between
consecutive segments; park-out plans are one segment. ``side`` +1 is left, -1 right.
Repetitions differ by seeded perturbations of lengths, speeds, steering and timing.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from parknss.data.trial import MANEUVER_CLASSES
from parknss.errors import ConfigError


@dataclass(frozen=True)
class SegmentPlan:
    """One gear's worth of motion.

    direction: +1 drive, -1 reverse. length_m: path length. speed_kmh: cruise speed.
    Steering (deg of steering-wheel angle) is ``steer_start_deg`` up to the travelled
    fraction ``turn_from``, then linear to ``steer_end_deg`` at ``turn_to``, then held;
    the start angle is set at standstill before moving off. hold_s: hold time at the
    stop that ends the segment.
    """

    direction: int
    length_m: float
    speed_kmh: float
    steer_start_deg: float
    steer_end_deg: float
    turn_from: float
    turn_to: float
    hold_s: float

    def steer_at(self, frac: float) -> float:
        """Planned steering-wheel angle (deg) at travelled fraction `frac` of the segment."""
        if frac <= self.turn_from:
            return self.steer_start_deg
        if frac >= self.turn_to:
            return self.steer_end_deg
        w = (frac - self.turn_from) / (self.turn_to - self.turn_from)
        return self.steer_start_deg + w * (self.steer_end_deg - self.steer_start_deg)


@dataclass(frozen=True)
class ManeuverPlan:
    """A whole trial: idle, segments, park, idle."""

    maneuver: str
    repetition: int
    segments: tuple[SegmentPlan, ...]
    idle_start_s: float
    idle_end_s: float

    @property
    def reversals(self) -> int:
        """Direction changes (reverse <-> drive) between consecutive segments."""
        return sum(a.direction != b.direction for a, b in pairwise(self.segments))


def _side(maneuver: str) -> int:
    return 1 if maneuver.endswith("_left") else -1


def _park_in(rng: np.random.Generator, side: int, lock: float) -> list[SegmentPlan]:
    """Parallel park-in: a long reverse S into the bay, then 8-9 short corrections.

    The first segment reverses with the wheel at one lock, countersteers to the other;
    the corrections alternate drive and reverse near the lock, each straightening toward
    its end (the last one to straight ahead). Every correction is one reversal.
    """
    u = rng.uniform
    n_corr = int(rng.choice([8, 9, 9, 10]))
    segs = [
        SegmentPlan(
            -1,
            u(3.0, 3.8),
            u(2.4, 3.0),
            side * u(0.93, 1.0) * lock,
            -side * u(0.93, 1.0) * lock,
            u(0.35, 0.45),
            u(0.7, 0.8),
            u(0.3, 0.6),
        )
    ]
    for i in range(n_corr):
        direction = 1 if i % 2 == 0 else -1
        last = i == n_corr - 1
        # forward corrections steer away from the kerb, backward ones toward it
        sign = -side if direction > 0 else side
        start = sign * u(0.93, 1.0) * lock
        end = 0.0 if last else sign * u(0.0, 0.3) * lock
        segs.append(
            SegmentPlan(
                direction,
                u(0.5, 0.85),
                u(1.6, 2.4),
                start,
                end,
                u(0.45, 0.6),
                u(0.85, 0.95),
                u(0.3, 0.6),
            )
        )
    return segs


def _park_out(rng: np.random.Generator, side: int, lock: float) -> list[SegmentPlan]:
    """Park-out: one forward segment leaving the bay at the lock, then straightening."""
    u = rng.uniform
    return [
        SegmentPlan(
            1,
            u(10.0, 13.5),
            u(2.3, 2.9),
            side * u(0.93, 1.0) * lock,
            -side * u(0.0, 0.15) * lock,
            u(0.3, 0.4),
            u(0.6, 0.75),
            u(0.5, 0.9),
        )
    ]


def make_plan(
    maneuver: str, repetition: int, rng: np.random.Generator, lock_deg: float
) -> ManeuverPlan:
    """The seeded plan of one trial of class `maneuver` (one of MANEUVER_CLASSES)."""
    if maneuver not in MANEUVER_CLASSES:
        raise ConfigError(
            f"unknown maneuver class {maneuver!r}; expected one of {MANEUVER_CLASSES}"
        )
    side = _side(maneuver)
    park_in = maneuver.startswith("park_in")
    segs = (_park_in if park_in else _park_out)(rng, side, lock_deg)
    idle = (1.0, 2.0) if park_in else (1.5, 3.0)
    return ManeuverPlan(
        maneuver,
        repetition,
        tuple(segs),
        idle_start_s=float(rng.uniform(*idle)),
        idle_end_s=float(rng.uniform(*idle)),
    )
