"""Multi-stroke escape from a tight parallel slot, for poses where Hybrid A* stalls.

A car boxed in lengthwise (a parallel slot a few decimetres longer than the car, TPCAP
case 7) leaves it by shuffling: short strokes forward and back, each gaining millimetres
sideways. The search's 5 cm / 1 deg cells cannot see such strokes (a stroke's gain stays
in one cell), so this module computes them directly: from the boxed pose, a beam search
over strokes (each one or two circular arcs within the lock, in alternating directions,
driven until the footprint would come closer than the margin) keeps the ``beam`` poses
farthest out towards the slot's open side, until one of them can drive out (a stroke
that reaches ``exit_gap_m`` beyond the margin). The open side is the side along which
the car slides farther sideways at its own heading without touching anything.

The strokes are found in the pose's own frame (the exit towards +y), so the escape
depends only on the slot and the car, not on where the scene sits. Stroke ends are
sampled every ``step_m``; a sample must clear the margin plus the Lipschitz bound of a
half step (the footprint moves at most ``step (1 + r kappa_max)`` per step, r the body's
largest distance from the rear axle), so the continuous stroke keeps the margin.

Returned strokes run from the boxed pose outwards; :func:`reversed_strokes` gives them in
the order that drives into the slot (a goal escape is appended reversed to the plan).
Lengths m, angles rad unless named ``_deg``.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from parknss.config import StrictModel
from parknss.sim import geometry
from parknss.sim.planning.reeds_shepp import arc_poses
from parknss.sim.trajectory import Segment
from parknss.vehicle import VehicleGeometry, steer_for_curvature


class EscapeConfig(StrictModel):
    """Slot escape settings (planning.yaml ``escape``). Lengths in m."""

    enabled: bool = Field(True, description="escape a boxed-in goal (is_boxed) before searching")
    after_failed_search: bool = Field(
        False, description="also escape the goal when the search fails (unboxed goals)"
    )
    step_m: float = Field(0.005, gt=0.0, description="sample spacing along a stroke, m")
    max_stroke_m: float = Field(1.0, gt=0.0, description="longest shuffle stroke, m")
    max_strokes: int = Field(300, ge=1, description="give up after this many strokes")
    beam: int = Field(3, ge=1, description="stroke-end poses kept per stroke")
    lock_fractions: tuple[float, ...] = Field(
        (1.0,), description="stroke curvatures as fractions of the lock curvature"
    )
    switch_fractions: tuple[float, ...] = Field(
        (0.35, 0.5, 0.65), description="two-arc strokes switch curvature at these fractions "
        "of the first arc's free length"
    )
    exit_gap_m: float = Field(
        0.3, gt=0.0, description="escaped: a stroke reaches clearance margin + this, m"
    )
    drive_out_m: float = Field(4.0, gt=0.0, description="longest drive-out stroke, m")
    boxed_run_m: float = Field(
        0.3, ge=0.0, description="a pose whose straight runs forward plus back stay below "
        "this is boxed in: escaped before the search, m (0: only after a failed search)"
    )
    turn_every: int = Field(
        10, ge=1, description="every this many strokes, try turning out from the best pose"
    )
    turn_strokes: int = Field(
        16, ge=1, description="a turn-out: at most this many strokes, each turning the "
        "car's nose (or tail) farther towards the open side, then a drive-out"
    )
    stall_strokes: int = Field(20, ge=1, description="give up when the last this many "
                               "strokes together gained less than stall_m sideways")
    stall_m: float = Field(0.02, ge=0.0, description="see stall_strokes, m")
    stop_to_steer: bool = Field(
        True, description="a stroke stops where its curvature changes and the wheel turns "
        "standing (stroke_segments)"
    )
    dedupe_m: float = Field(0.002, gt=0.0, description="beam poses closer than this merge, m")
    dedupe_deg: float = Field(0.2, gt=0.0, description="...and in heading, deg")


@dataclass
class Stroke:
    """One stroke: ``direction`` +1/-1, ``poses`` (N, 3) from its start, ``kappa`` (N,)
    the curvature of the arc that reaches each pose (the first: of the arc leaving it;
    1/m), ``breaks`` the poses where one arc ends and the next begins."""

    direction: int
    poses: np.ndarray
    kappa: np.ndarray
    breaks: tuple[int, ...] = ()  # indices of the poses where the curvature changes

    @property
    def length(self) -> float:
        return float(np.hypot(*np.diff(self.poses[:, :2], axis=0).T).sum())


@dataclass
class EscapeResult:
    """``strokes`` from the boxed pose outwards (empty when not escaped), and why."""

    strokes: list[Stroke]
    reason: str
    side: int = 0  # +1: out to the pose's left, -1: right, 0: no open side
    progress_m: float = 0.0  # the farthest stroke end sideways towards the open side, m

    @property
    def found(self) -> bool:
        return bool(self.strokes) and self.reason == "ok"

    @property
    def end(self) -> np.ndarray:
        return self.strokes[-1].poses[-1]


def _to_local(pose, side: int, xy: np.ndarray) -> np.ndarray:
    """World points (..., 2) -> the pose's frame, mirrored so that ``side`` is +y."""
    x0, y0, th = (float(v) for v in pose[:3])
    c, s = math.cos(th), math.sin(th)
    dx, dy = xy[..., 0] - x0, xy[..., 1] - y0
    return np.stack([c * dx + s * dy, side * (-s * dx + c * dy)], axis=-1)


def _to_world(pose, side: int, poses: np.ndarray) -> np.ndarray:
    """Local poses (N, 3) -> world."""
    x0, y0, th = (float(v) for v in pose[:3])
    c, s = math.cos(th), math.sin(th)
    y = side * poses[:, 1]
    return np.stack(
        [x0 + c * poses[:, 0] - s * y, y0 + s * poses[:, 0] + c * y, th + side * poses[:, 2]],
        axis=1,
    )


CHUNK = 64
"""Stroke samples checked per batch (a speed setting only: the result is the same)."""


class _Slot:
    """The obstacles and map in one pose's (mirrored) frame, with the stroke sampler."""

    def __init__(self, pose, side, obstacles, geom, margin, cfg, inside):
        self.pose, self.side, self.geom, self.cfg = pose, side, geom, cfg
        # mirrored (side -1), a CCW polygon comes out clockwise: reversed back to CCW
        self.obs = [_to_local(pose, side, o)[::side].copy() for o in obstacles]
        self.inside = inside
        self.kmax = 1.0 / geom.min_turning_radius()
        reach = math.hypot(max(geom.length - geom.rear_overhang, geom.rear_overhang),
                           geom.width / 2)
        self.need = margin + 0.5 * cfg.step_m * (1.0 + reach * self.kmax)
        self.margin = margin

    def clearance(self, poses: np.ndarray) -> np.ndarray:
        c = geometry.clearance(poses, self.geom, self.obs, cutoff=1.0)
        if self.inside is not None:
            c = np.where(self.inside(_to_world(self.pose, self.side, poses)), c, -1.0)
        return c

    def run(self, p, d: int, kappa: float, length: float):
        """Free poses (N, 3) of driving ``d`` at ``kappa`` from ``p`` up to ``length``
        (without ``p``), cut before the first sample below the margin, and their
        clearances."""
        n = max(1, int(length / self.cfg.step_m))
        s = d * self.cfg.step_m * np.arange(1, n + 1)
        poses = arc_poses(p, kappa, s)
        c = np.empty(n)
        for i in range(0, n, CHUNK):  # sampled in chunks: most strokes stop within one
            c[i : i + CHUNK] = self.clearance(poses[i : i + CHUNK])
            bad = np.flatnonzero(c[i : i + CHUNK] < self.need)
            if len(bad):
                k = i + int(bad[0])
                return poses[:k], c[:k]
        return poses, c


def open_side(pose, obstacles: Sequence[np.ndarray], geom: VehicleGeometry, margin: float,
              width: float | None = None) -> tuple[int, float]:
    """(side, m): the side (+1 left, -1 right) along which the car slides sideways at its
    heading farther (up to ``width``, default the car's width plus 1 m) keeping the
    margin, and how far; (0, 0.0) if neither side moves at all."""
    width = width if width is not None else geom.width + 1.0
    x0, y0, th = (float(v) for v in pose[:3])
    t = np.arange(0.01, width + 1e-9, 0.01)
    best = (0, 0.0)
    for side in (1, -1):
        poses = np.stack([x0 - side * t * math.sin(th), y0 + side * t * math.cos(th),
                          np.full_like(t, th)], axis=1)
        c = geometry.clearance(poses, geom, obstacles, cutoff=1.0)
        bad = np.flatnonzero(c < margin)
        free = float(t[bad[0] - 1]) if len(bad) and bad[0] > 0 else (
            0.0 if len(bad) else float(t[-1]))
        if free > best[1]:
            best = (side, free)
    return best


def straight_runs(pose, obstacles, geom: VehicleGeometry, margin: float, limit: float = 2.0,
                  step: float = 0.01) -> tuple[float, float]:
    """(forward, back) free straight run from ``pose`` keeping ``margin``, each capped at
    ``limit`` (m)."""
    out = []
    for d in (1, -1):
        s = d * np.arange(step, limit + 1e-9, step)
        c = geometry.clearance(arc_poses(pose, 0.0, s), geom, obstacles, cutoff=1.0)
        bad = np.flatnonzero(c < margin)
        out.append(limit if not len(bad) else float(bad[0]) * step)
    return out[0], out[1]


def is_boxed(pose, obstacles, geom: VehicleGeometry, margin: float, cfg: EscapeConfig) -> bool:
    """True when the straight runs forward plus back stay below ``cfg.boxed_run_m``; a
    pose already inside the margin is not boxed in (the search refuses it)."""
    if cfg.boxed_run_m <= 0.0 or not obstacles:
        return False
    if geometry.clearance([pose], geom, obstacles)[0] < margin:
        return False
    f, b = straight_runs(pose, obstacles, geom, margin, limit=cfg.boxed_run_m)
    return f + b < cfg.boxed_run_m


def escape(
    pose,
    obstacles: Sequence[np.ndarray],
    geom: VehicleGeometry,
    margin: float,
    cfg: EscapeConfig | None = None,
    inside: Callable[[np.ndarray], np.ndarray] | None = None,
    deadline: float | None = None,
) -> EscapeResult:
    """Strokes that take the car from ``pose`` out of its slot (module docstring).

    Args:
        obstacles: convex polygons (M, 2), m, in the pose's coordinates.
        geom: the planner's vehicle (its lock bounds the strokes).
        margin: clearance kept at every pose, m.
        inside: optional (N, 3) world poses -> (N,) bool, the footprint on the map.
        deadline: optional ``time.perf_counter()`` value after which it gives up.
    """
    cfg = cfg or EscapeConfig()
    side, _ = open_side(pose, obstacles, geom, margin)
    if side == 0:
        return EscapeResult([], "no open side")
    slot = _Slot(np.asarray(pose, dtype=float)[:3], side, obstacles, geom, margin, cfg, inside)
    if slot.clearance(np.zeros((1, 3)))[0] < margin:
        return EscapeResult([], "pose in collision", side)
    fwd, back = straight_runs(pose, obstacles, geom, margin, limit=geom.length)
    xc = 0.5 * (fwd - back)
    beam: list[tuple[np.ndarray, int, list[Stroke]]] = [(np.zeros(3), 0, [])]
    best, history = 0.0, [0.0]
    for k in range(cfg.max_strokes):
        if deadline is not None and time.perf_counter() > deadline:
            return EscapeResult([], f"time budget exhausted after {k} strokes", side, best)
        cand: list[tuple[np.ndarray, int, list[Stroke]]] = []
        for p, last, hist in beam:
            for d in ((1, -1) if last == 0 else (-last,)):
                out = _drive_out(slot, p, d)
                if out is not None:
                    return EscapeResult(_world(slot, [*hist, out]), "ok", side, best)
                cand.extend((s.poses[-1], d, [*hist, s]) for s in _strokes(slot, p, d))
        if not cand:
            return EscapeResult([], "stuck: no stroke moves", side, best)
        beam = _select(cand, cfg, xc)
        best = max(best, float(beam[0][0][1]))
        if (k + 1) % cfg.turn_every == 0:
            p, last, hist = beam[0]
            turn = _turn_out(slot, p, last)
            if turn is not None:
                return EscapeResult(_world(slot, hist + turn), "ok", side, best)
        history.append(best)
        if k >= cfg.stall_strokes and best - history[-1 - cfg.stall_strokes] < cfg.stall_m:
            return EscapeResult([], f"stalled after {k + 1} strokes", side, best)
    return EscapeResult([], f"not out after {cfg.max_strokes} strokes", side, best)


def _select(cand, cfg: EscapeConfig, xc: float):
    """The ``beam`` candidates farthest out, distinct poses only: by the sideways progress
    y - tan(heading) (x - xc), xc the middle of the slot's straight run (the progress a
    stroke cannot fake by tilting the car about the slot's middle)."""
    cand.sort(key=lambda c: (-(c[0][1] - math.tan(c[0][2]) * (c[0][0] - xc)), abs(c[0][2])))
    seen, keep = set(), []
    qd = math.radians(cfg.dedupe_deg)
    for c in cand:
        key = (round(c[0][0] / cfg.dedupe_m), round(c[0][1] / cfg.dedupe_m),
               round(c[0][2] / qd), c[1])
        if key in seen:
            continue
        seen.add(key)
        keep.append(c)
        if len(keep) >= cfg.beam:
            break
    return keep


def _stroke(p, d, parts) -> Stroke:
    """A stroke from ``p``: ``parts`` a list of (poses, kappa) pieces (poses without p)."""
    poses = np.concatenate([p[None, :]] + [q for q, _ in parts], axis=0)
    kappa = np.concatenate([[parts[0][1]]] + [np.full(len(q), k) for q, k in parts])
    ends = np.cumsum([len(q) for q, _ in parts])[:-1]
    return Stroke(d, poses, kappa, tuple(int(e) for e in ends))


def _strokes(slot: _Slot, p, d: int, two_arcs: bool = True) -> list[Stroke]:
    """Candidate strokes from ``p`` in direction ``d``: one arc at each lock fraction
    (left, right, straight) driven to the margin, and two arcs (lock, opposite lock)
    switching at ``switch_fractions`` of the first arc's free run."""
    cfg, out = slot.cfg, []
    kappas = [0.0] + [s * f * slot.kmax for f in cfg.lock_fractions for s in (1, -1)]
    for k1 in kappas:
        q1, _ = slot.run(p, d, k1, cfg.max_stroke_m)
        if not len(q1):
            continue
        out.append(_stroke(p, d, [(q1, k1)]))
        if k1 == 0.0 or not two_arcs:
            continue
        for f in cfg.switch_fractions:
            n = round(f * len(q1))
            if n < 1 or n >= len(q1):
                continue
            q2, _ = slot.run(q1[n - 1], d, -k1, cfg.max_stroke_m)
            if len(q2):
                out.append(_stroke(p, d, [(q1[:n], k1), (q2, -k1)]))
    return out


def _drive_out(slot: _Slot, p, d: int) -> Stroke | None:
    """A stroke from ``p`` in direction ``d`` (left lock, straight, right lock) that
    reaches clearance margin + ``exit_gap_m`` within ``drive_out_m``: cut there."""
    cfg = slot.cfg
    target = slot.margin + cfg.exit_gap_m
    for k in (slot.kmax, 0.0, -slot.kmax):
        q, c = slot.run(p, d, k, cfg.drive_out_m)
        hit = np.flatnonzero(c >= target)
        if len(hit):
            return _stroke(p, d, [(q[: hit[0] + 1], k)])
    return None


def _turn_out(slot: _Slot, p, last: int) -> list[Stroke] | None:
    """Strokes from ``p`` (the last one driven in direction ``last``) that turn the nose
    (sign +1) or the tail (-1) towards the open side, greedily the most heading each,
    until a drive-out succeeds (within ``turn_strokes``); None if none does."""
    for sign in (1, -1):
        q, d, out = p, -last, []
        for _ in range(slot.cfg.turn_strokes):
            cands = _strokes(slot, q, d, two_arcs=False)
            if not cands:
                break
            s = max(cands, key=lambda c: (sign * c.poses[-1][2], c.poses[-1][1]))
            if sign * s.poses[-1][2] <= sign * q[2] + 1e-9:
                break
            out.append(s)
            q, d = s.poses[-1], -d
            drive = _drive_out(slot, q, d)
            if drive is not None:
                return [*out, drive]
    return None


def _world(slot: _Slot, strokes: list[Stroke]) -> list[Stroke]:
    """Local strokes -> world poses and curvatures (mirrored: curvature changes sign)."""
    return [
        Stroke(s.direction, _to_world(slot.pose, slot.side, s.poses), slot.side * s.kappa,
               s.breaks)
        for s in strokes
    ]


def reversed_strokes(strokes: list[Stroke]) -> list[Stroke]:
    """The same path driven the other way: last stroke first, each backwards in the other
    gear (the curvature at each pose, hence the steering, unchanged)."""
    out = []
    for s in reversed(strokes):
        n = len(s.poses)
        kappa = np.empty(n)  # the arc reaching each pose, driven backwards
        kappa[1:] = s.kappa[::-1][:-1]
        kappa[0] = kappa[1]
        out.append(Stroke(-s.direction, s.poses[::-1].copy(), kappa,
                          tuple(sorted(n - 1 - b for b in s.breaks))))
    return out


def stroke_segments(strokes: list[Stroke], geom: VehicleGeometry,
                    stop_to_steer: bool = True) -> list[Segment]:
    """Strokes as trajectory segments (steering-wheel angle from the curvature).
    ``stop_to_steer``: a stroke is cut where its curvature changes, into segments of the
    same gear: the car stops there and turns the wheel standing (lock to opposite lock
    takes about a metre of driving at the steering rate, a stroke is centimetres)."""
    out = []
    for s in strokes:
        cuts = [0, *s.breaks, len(s.poses) - 1] if stop_to_steer else [0, len(s.poses) - 1]
        for a, b in itertools.pairwise(cuts):
            kappa = s.kappa[a + 1 : b + 1]
            kappa = np.concatenate([kappa[:1], kappa])
            out.append(Segment(s.poses[a : b + 1], s.direction,
                               steer=np.asarray(steer_for_curvature(kappa, geom), dtype=float)))
    return out
