"""Reeds-Shepp curves: the shortest paths of a car that drives forwards and backwards.

A path is a word of at most five segments, each a left turn (L), right turn (R) or
straight (S), driven forwards (+) or backwards (-), at the minimum turning radius. Reeds
and Shepp (1990) showed that an optimal path is one of 48 words from nine families
(CSC, C|C|C, C|CC, CC|C, CCu|CuC, C|CuCu|C, C|C[π/2]SC, CSC[π/2]|C, C|C[π/2]SC[π/2]|C).
This module solves the nine base formulas of the paper (eq. 8.1-8.11, in units of the
turning radius, start at the origin heading +x) and maps each to the other words by the
paper's symmetries: timeflip (drive the word backwards in time: (x, y, φ) -> (-x, y, -φ),
all segment signs flipped), reflect (mirror in the x axis: (x, y, φ) -> (x, -y, -φ), L <-> R)
and backwards (traverse the word in reverse order: (x, y, φ) ->
(x cos φ + y sin φ, x sin φ - y cos φ, φ)).

The solvers are plain ``math`` on scalars: one call costs a few tens of microseconds, which
is what Hybrid A* needs for its heuristic (:func:`shortest_length`) and analytic expansion
(:func:`all_paths`). Sampling is vectorised with NumPy.

Poses are (x m, y m, heading rad, counter-clockwise from +x), rear-axle centre.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from parknss.errors import PlanningError
from parknss.vehicle import arc_step

PI = math.pi
HALF_PI = 0.5 * math.pi
TWO_PI = 2.0 * math.pi
_TOL = 1e-10  # sign tolerance of segment parameters (unit radius)

_SWAP = {"L": "R", "R": "L", "S": "S"}
_CURV = {"L": 1.0, "R": -1.0, "S": 0.0}


def _mod2pi(a: float) -> float:
    """Angle wrapped to (-π, π]."""
    v = math.fmod(a, TWO_PI)
    if v <= -PI:
        v += TWO_PI
    elif v > PI:
        v -= TWO_PI
    return v


def _polar(x: float, y: float) -> tuple[float, float]:
    return math.hypot(x, y), math.atan2(y, x)


def _tau_omega(u: float, v: float, xi: float, eta: float, phi: float) -> tuple[float, float]:
    """Helper angles of the CCCC families (Reeds & Shepp 1990, eq. 8.7/8.8)."""
    delta = _mod2pi(u - v)
    a = math.sin(u) - math.sin(delta)
    b = math.cos(u) - math.cos(delta) - 1.0
    t1 = math.atan2(eta * a - xi * b, xi * a + eta * b)
    t2 = 2.0 * (math.cos(delta) - math.cos(v) - math.cos(u)) + 3.0
    tau = _mod2pi(t1 + PI) if t2 < 0 else _mod2pi(t1)
    omega = _mod2pi(tau - u + v - phi)
    return tau, omega


# ---------------------------------------------------------------------------------------
# Base formulas. Each takes the goal (x, y, φ) in the unit-radius start frame and returns
# the signed segment parameters (angle for C, distance for S) of one base word, or None.


def _lsl(x: float, y: float, phi: float):
    """L+S+L+ (eq. 8.1)."""
    u, t = _polar(x - math.sin(phi), y - 1.0 + math.cos(phi))
    if t >= -_TOL:
        v = _mod2pi(phi - t)
        if v >= -_TOL:
            return (t, u, v)
    return None


def _lsr(x: float, y: float, phi: float):
    """L+S+R+ (eq. 8.2)."""
    u1, t1 = _polar(x + math.sin(phi), y - 1.0 - math.cos(phi))
    u1 *= u1
    if u1 >= 4.0:
        u = math.sqrt(u1 - 4.0)
        t = _mod2pi(t1 + math.atan2(2.0, u))
        v = _mod2pi(t - phi)
        if t >= -_TOL and v >= -_TOL:
            return (t, u, v)
    return None


def _lrl(x: float, y: float, phi: float):
    """L+R-L± (eq. 8.3 C|C|C for v >= 0, eq. 8.4 C|CC for v <= 0)."""
    u1, theta = _polar(x - math.sin(phi), y - 1.0 + math.cos(phi))
    if u1 <= 4.0:
        u = -2.0 * math.asin(0.25 * u1)
        t = _mod2pi(theta + 0.5 * u + PI)
        v = _mod2pi(phi - t + u)
        if t >= -_TOL and u <= _TOL:
            return (t, u, v)
    return None


def _lrlr_u(x: float, y: float, phi: float):
    """L+R+L-R- (eq. 8.7, CCu|CuC)."""
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho = 0.25 * (2.0 + math.hypot(xi, eta))
    if rho <= 1.0:
        u = math.acos(rho)
        t, v = _tau_omega(u, -u, xi, eta, phi)
        if t >= -_TOL and v <= _TOL:
            return (t, u, -u, v)
    return None


def _lrlr_m(x: float, y: float, phi: float):
    """L+R-L-R+ (eq. 8.8, C|CuCu|C)."""
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho = (20.0 - xi * xi - eta * eta) / 16.0
    if 0.0 <= rho <= 1.0:
        u = -math.acos(rho)
        if u >= -HALF_PI:
            t, v = _tau_omega(u, u, xi, eta, phi)
            if t >= -_TOL and v >= -_TOL:
                return (t, u, u, v)
    return None


def _lrsl(x: float, y: float, phi: float):
    """L+R-S-L- (eq. 8.9, C|C[π/2]SC, same-side final turn)."""
    rho, theta = _polar(x - math.sin(phi), y - 1.0 + math.cos(phi))
    if rho >= 2.0:
        r = math.sqrt(rho * rho - 4.0)
        u = 2.0 - r
        t = _mod2pi(theta + math.atan2(r, -2.0))
        v = _mod2pi(phi - HALF_PI - t)
        if t >= -_TOL and u <= _TOL and v <= _TOL:
            return (t, -HALF_PI, u, v)
    return None


def _lrsr(x: float, y: float, phi: float):
    """L+R-S-R- (eq. 8.10, C|C[π/2]SC, opposite final turn)."""
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho, theta = _polar(-eta, xi)
    if rho >= 2.0:
        t = theta
        u = 2.0 - rho
        v = _mod2pi(t + HALF_PI - phi)
        if t >= -_TOL and u <= _TOL and v <= _TOL:
            return (t, -HALF_PI, u, v)
    return None


def _lrslr(x: float, y: float, phi: float):
    """L+R-S-L-R+ (eq. 8.11, C|C[π/2]SC[π/2]|C)."""
    xi, eta = x + math.sin(phi), y - 1.0 - math.cos(phi)
    rho, _theta = _polar(xi, eta)
    if rho >= 2.0:
        u = 4.0 - math.sqrt(rho * rho - 4.0)
        if u <= _TOL:
            t = _mod2pi(math.atan2((4.0 - u) * xi - 2.0 * eta, -2.0 * xi + (u - 4.0) * eta))
            v = _mod2pi(t - phi)
            if t >= -_TOL and v >= -_TOL:
                return (t, -HALF_PI, u, -HALF_PI, v)
    return None


# (solver, letters, solved in the backwards frame?)
_BASES = (
    (_lsl, "LSL", False),
    (_lsr, "LSR", False),
    (_lrl, "LRL", False),
    (_lrl, "LRL", True),
    (_lrlr_u, "LRLR", False),
    (_lrlr_m, "LRLR", False),
    (_lrsl, "LRSL", False),
    (_lrsr, "LRSR", False),
    (_lrsl, "LRSL", True),
    (_lrsr, "LRSR", True),
    (_lrslr, "LRSLR", False),
)

# (x sign, y sign, φ sign, flip segment signs, swap L/R): as solved, timeflip, reflect, both
_SYMMETRIES = (
    (1.0, 1.0, 1.0, False, False),
    (-1.0, 1.0, -1.0, True, False),
    (1.0, -1.0, -1.0, False, True),
    (-1.0, -1.0, 1.0, True, True),
)


def _word_letters(letters: str, swap: bool, backwards: bool) -> str:
    word = "".join(_SWAP[c] for c in letters) if swap else letters
    return word[::-1] if backwards else word


# Flat table: (solver, backwards, x sign, y sign, φ sign, flip, final letters)
_TABLE = tuple(
    (solve, backwards, sx, sy, sp, flip, _word_letters(letters, swap, backwards))
    for solve, letters, backwards in _BASES
    for sx, sy, sp, flip, swap in _SYMMETRIES
)


def _words(x: float, y: float, phi: float) -> Iterator[tuple[str, tuple[float, ...]]]:
    """Every valid candidate (letters, signed unit-radius parameters) for goal (x, y, φ)."""
    cphi, sphi = math.cos(phi), math.sin(phi)
    frames = ((x, y), (x * cphi + y * sphi, x * sphi - y * cphi))
    for solve, backwards, sx, sy, sp, flip, word in _TABLE:
        fx, fy = frames[backwards]
        p = solve(sx * fx, sy * fy, sp * phi)
        if p is None:
            continue
        if flip:
            p = tuple(-q for q in p)
        if backwards:
            p = p[::-1]
        yield word, p


def _min_length(x: float, y: float, phi: float) -> float:
    """Shortest total |parameter| over all words (unit radius); the hot loop of A*."""
    cphi, sphi = math.cos(phi), math.sin(phi)
    frames = ((x, y), (x * cphi + y * sphi, x * sphi - y * cphi))
    best = math.inf
    for solve, backwards, sx, sy, sp, _flip, _word in _TABLE:
        fx, fy = frames[backwards]
        p = solve(sx * fx, sy * fy, sp * phi)
        if p is not None:
            n = 0.0
            for q in p:
                n += q if q >= 0.0 else -q
            if n < best:
                best = n
    return best


def _relative(start, goal, radius: float) -> tuple[float, float, float]:
    """Goal in the start frame, scaled to unit turning radius."""
    if not radius > 0.0 or not math.isfinite(radius):
        raise PlanningError(f"Reeds-Shepp turning radius must be positive, got {radius!r}")
    x0, y0, th0 = (float(v) for v in start)
    x1, y1, th1 = (float(v) for v in goal)
    dx, dy = x1 - x0, y1 - y0
    c, s = math.cos(th0), math.sin(th0)
    return (c * dx + s * dy) / radius, (-s * dx + c * dy) / radius, th1 - th0


def shortest_length(start, goal, turning_radius: float) -> float:
    """Length in m of the shortest Reeds-Shepp path between two poses (no path object)."""
    x, y, phi = _relative(start, goal, turning_radius)
    return _min_length(x, y, phi) * turning_radius


def csc_length(start, goal, turning_radius: float) -> float:
    """Shortest length in m over the CSC family only: an upper bound of the shortest path,
    a fifth of the work of :func:`shortest_length`."""
    x, y, phi = _relative(start, goal, turning_radius)
    best = math.inf
    for solve, _backwards, sx, sy, sp, _flip, _word in _TABLE[:8]:
        p = solve(sx * x, sy * y, sp * phi)
        if p is not None:
            n = abs(p[0]) + abs(p[1]) + abs(p[2])
            if n < best:
                best = n
    return best * turning_radius


# ---------------------------------------------------------------------------------------
# Paths


def arc_poses(pose, kappa: float, s: np.ndarray) -> np.ndarray:
    """Poses after driving signed arc lengths ``s`` (m, (N,)) at curvature ``kappa`` (1/m).

    Returns (N, 3) [x, y, heading]; the heading is continuous (not wrapped). Exact for
    straights and circular arcs (the chord formula, stable for kappa -> 0).
    """
    x0, y0, th0 = (float(v) for v in pose)
    s = np.asarray(s, dtype=float)
    return np.stack(arc_step(x0, y0, th0, s, kappa * s), axis=1)


@dataclass(frozen=True)
class RSSegment:
    """One segment: kind 'L', 'R' or 'S'; signed length in m (negative = reverse)."""

    kind: str
    length: float

    @property
    def direction(self) -> int:
        return 1 if self.length >= 0.0 else -1

    def curvature(self, radius: float) -> float:
        """Signed curvature in 1/m (left positive)."""
        return _CURV[self.kind] / radius


@dataclass(frozen=True)
class RSPath:
    """A Reeds-Shepp path from ``start`` to ``goal`` at turning radius ``radius`` (m)."""

    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    radius: float
    word: str
    params: tuple[float, ...]  # signed, in units of the radius

    @property
    def segments(self) -> list[RSSegment]:
        """Segments with non-zero length, in driving order."""
        return [
            RSSegment(k, p * self.radius)
            for k, p in zip(self.word, self.params, strict=True)
            if abs(p) > _TOL
        ]

    @property
    def length(self) -> float:
        """Total driven length, m."""
        return self.radius * sum(abs(p) for p in self.params)

    @property
    def cusps(self) -> int:
        """Number of direction changes."""
        dirs = [s.direction for s in self.segments]
        return sum(1 for a, b in itertools.pairwise(dirs) if a != b)

    @property
    def signature(self) -> str:
        """The word with directions, e.g. 'L+R-L-' (zero-length segments included)."""
        pairs = zip(self.word, self.params, strict=True)
        return "".join(f"{k}{'+' if p >= 0 else '-'}" for k, p in pairs)

    def end_pose(self) -> np.ndarray:
        """(3,) pose reached by integrating the segments (equals the goal up to rounding)."""
        pose = np.asarray(self.start, dtype=float)
        for seg in self.segments:
            pose = arc_poses(pose, seg.curvature(self.radius), np.array([seg.length]))[0]
        return pose

    def sample(self, step: float, max_dheading: float | None = None) -> np.ndarray:
        """Poses every ``step`` m (and at most ``max_dheading`` rad of turn) along the path.

        Returns (N, 4) [x, y, heading, direction]; direction is +1 forward, -1 reverse.
        Each segment is split into equal sub-steps no longer than the limits, so every
        segment end is a sample. A cusp pose appears twice, once ending the incoming
        segment (old direction) and once starting the next (new direction). Headings are
        continuous from the start heading; the last row is the goal (heading up to 2π).
        """
        return sample_paths([self], step, max_dheading)[0]

    def pieces(self, step: float, max_dheading: float | None = None):
        """The sampled path split at cusps: list of ((N, 3) poses, direction)."""
        samp = self.sample(step, max_dheading)
        cut = np.flatnonzero(np.diff(samp[:, 3]) != 0) + 1
        return [(p[:, :3], int(p[0, 3])) for p in np.split(samp, cut) if len(p) >= 2]


def sample_paths(
    paths: list[RSPath], step: float, max_dheading: float | None = None
) -> list[np.ndarray]:
    """:meth:`RSPath.sample` for many paths in one vectorised pass (list of (N_i, 4))."""
    if not step > 0.0:
        raise PlanningError(f"Reeds-Shepp sample step must be positive, got {step!r}")
    starts, kap, ds, dirs, counts, skip, owner = [], [], [], [], [], [], []
    for pi, path in enumerate(paths):
        x, y, th = (float(v) for v in path.start)
        prev_dir = 0
        r = path.radius
        segs = [
            (_CURV[w] / r, q * r)
            for w, q in zip(path.word, path.params, strict=True)
            if abs(q) > _TOL
        ]
        if not segs:  # zero-length path: one sample at the goal
            starts.append((x, y, th))
            kap.append(0.0)
            ds.append(0.0)
            dirs.append(1)
            counts.append(1)
            skip.append(False)
            owner.append(pi)
            continue
        for k, length in segs:
            lim = step
            if max_dheading is not None and k != 0.0:
                lim = min(step, max_dheading / abs(k))
            n = max(1, math.ceil(abs(length) / lim - 1e-9))
            d = 1 if length >= 0.0 else -1
            starts.append((x, y, th))
            kap.append(k)
            ds.append(length / n)
            dirs.append(d)
            counts.append(n + 1)
            skip.append(prev_dir == d)  # continuation: joint already sampled
            owner.append(pi)
            prev_dir = d
            x, y, th = arc_step(x, y, th, length, k * length)
    counts_a = np.array(counts)
    seg_id = np.repeat(np.arange(len(counts)), counts_a)
    j = np.arange(int(counts_a.sum())) - np.repeat(np.cumsum(counts_a) - counts_a, counts_a)
    keep = ~(np.array(skip)[seg_id] & (j == 0))
    seg_id, j = seg_id[keep], j[keep]
    st = np.array(starts)[seg_id]
    sv = j * np.array(ds)[seg_id]
    x, y, th = arc_step(st[:, 0], st[:, 1], st[:, 2], sv, np.array(kap)[seg_id] * sv)
    out = np.column_stack([x, y, th, np.array(dirs, dtype=float)[seg_id]])
    path_of = np.array(owner)[seg_id]
    cuts = np.flatnonzero(np.diff(path_of)) + 1
    result = np.split(out, cuts)
    for path, arr in zip(paths, result, strict=True):
        gx, gy, gth = (float(v) for v in path.goal)
        last = arr[-1, 2]
        arr[-1, :3] = (gx, gy, gth + TWO_PI * round((last - gth) / TWO_PI))
    return result


def all_paths(start, goal, turning_radius: float) -> list[RSPath]:
    """Every valid Reeds-Shepp candidate between two poses, shortest first."""
    x, y, phi = _relative(start, goal, turning_radius)
    st = tuple(float(v) for v in start)
    gl = tuple(float(v) for v in goal)
    paths = [RSPath(st, gl, float(turning_radius), w, p) for w, p in _words(x, y, phi)]
    paths.sort(key=lambda p: round(p.length, 9))  # stable: equal lengths in word order
    return paths


def shortest_path(start, goal, turning_radius: float) -> RSPath:
    """The shortest Reeds-Shepp path between two poses (x m, y m, heading rad)."""
    paths = all_paths(start, goal, turning_radius)
    if not paths:  # cannot happen for finite poses (LSL or a symmetry always solves)
        raise PlanningError(f"no Reeds-Shepp word solves {start} -> {goal}")
    return paths[0]
