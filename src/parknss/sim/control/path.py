"""One gear segment as a tracking reference: dense poses, arc length, motion heading and
curvature, speed caps, and the projection of the car's pose onto it.

Motion frame: the heading of travel φ = heading (+π in reverse) and the motion curvature
k = dφ/ds (1/m, s the travelled distance), so reverse driving is forward driving of the
motion frame and the steering-wheel angle that follows k is steer(direction·k).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from parknss.sim.geometry import densify
from parknss.sim.trajectory import Segment
from parknss.vehicle import VehicleGeometry, steer_for_curvature


@dataclass
class Projection:
    """Where the car is relative to the reference.

    s: travelled distance of the foot point, m (< 0 before the start, > length past the
    end, along the end tangents); e_y: lateral offset left of the travel direction, m;
    e_phi: heading error of travel, rad; index: nearest reference point.
    """

    s: float
    e_y: float
    e_phi: float
    index: int


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _window_min(v: np.ndarray, n: int) -> np.ndarray:
    """v_out[i] = min(v[i : i + n]) (forward window, edge-padded)."""
    if n <= 1:
        return v.copy()
    padded = np.concatenate([v, np.full(n - 1, v[-1])])
    return np.lib.stride_tricks.sliding_window_view(padded, n).min(axis=1)


class PathReference:
    """A dense reference of one segment (see module docstring).

    Args:
        seg: the planned segment.
        geom: vehicle geometry (constant-ratio steering of the planner's model).
        step_m: reference point spacing, m.
        steer_rate_dps: steering-wheel rate the speed cap assumes, deg/s.
        smooth_m: width of the moving average of the reference steering angle, m.
        lookahead_m: the cap at s is the minimum over [s, s + lookahead], m.
    """

    def __init__(
        self,
        seg: Segment,
        geom: VehicleGeometry,
        step_m: float = 0.02,
        steer_rate_dps: float = 400.0,
        smooth_m: float = 0.3,
        lookahead_m: float = 0.4,
    ) -> None:
        self.direction = int(seg.direction)
        extra = [seg.speed] if seg.speed is not None else []
        raw = np.column_stack([seg.poses] + [np.asarray(e, float) for e in extra])
        keep = np.concatenate([[True], np.hypot(*np.diff(raw[:, :2], axis=0).T) > 1e-9])
        keep |= np.concatenate([[True], np.abs(np.diff(raw[:, 2])) > 1e-9])
        dense = densify(raw[keep], step_m, math.radians(1.0))
        self.xy = dense[:, :2]
        self.heading = np.unwrap(dense[:, 2])
        self.phi = self.heading + (math.pi if self.direction < 0 else 0.0)
        ds = np.hypot(*np.diff(self.xy, axis=0).T)
        self.s = np.concatenate([[0.0], np.cumsum(ds)])
        self.length = float(self.s[-1])
        k = np.diff(self.phi) / np.maximum(ds, 1e-9)
        self.kappa = np.concatenate([k, k[-1:]]) if len(k) else np.zeros(1)
        self.planned_speed = dense[:, 3] if extra else None
        self.steer_ref = steer_for_curvature(self.direction * self.kappa, geom)
        self.v_steer = self._steer_cap(step_m, steer_rate_dps, smooth_m, lookahead_m)

    def _steer_cap(self, step: float, rate: float, smooth: float, look: float) -> np.ndarray:
        """Speed cap (m/s) so the smoothed reference steering needs <= ``rate`` deg/s."""
        n = max(1, round(smooth / step))
        kernel = np.ones(n) / n
        pad = np.concatenate(
            [np.full(n, self.steer_ref[0]), self.steer_ref, np.full(n, self.steer_ref[-1])]
        )
        smooth_ref = np.convolve(pad, kernel, mode="same")[n:-n]
        if len(self.s) < 2:
            return np.full(len(self.s), np.inf)
        slope = np.abs(np.gradient(smooth_ref, self.s))
        cap = rate / np.maximum(slope, 1e-9)
        return _window_min(cap, max(1, round(look / step)))

    # ------------------------------------------------------------------ queries
    def at(self, s: float, values: np.ndarray) -> float:
        """``values`` (per reference point) interpolated at distance s (clamped)."""
        return float(np.interp(s, self.s, values))

    def project(self, x: float, y: float, heading: float, hint: int, window_m: float) -> Projection:
        """Project a rear-axle pose onto the reference near point ``hint``."""
        n = len(self.s)
        if n == 1:
            return Projection(0.0, 0.0, _wrap(heading - self.heading[0]), 0)
        lo = int(np.searchsorted(self.s, self.s[hint] - window_m))
        hi = int(np.searchsorted(self.s, self.s[hint] + window_m, side="right"))
        lo, hi = max(lo - 1, 0), min(hi + 1, n)
        d2 = (self.xy[lo:hi, 0] - x) ** 2 + (self.xy[lo:hi, 1] - y) ** 2
        i = lo + int(np.argmin(d2))
        best = None
        for j in (i - 1, i):
            if j < 0 or j >= n - 1:
                continue
            p0, p1 = self.xy[j], self.xy[j + 1]
            seg = p1 - p0
            L2 = float(seg @ seg)
            t = float(((x - p0[0]) * seg[0] + (y - p0[1]) * seg[1]) / max(L2, 1e-18))
            # interior pieces clamp to [0, 1]; the first and last extend along their tangent
            t = max(t, 0.0) if j > 0 else t
            t = min(t, 1.0) if j < n - 2 else t
            foot = p0 + t * seg
            dist = (x - foot[0]) ** 2 + (y - foot[1]) ** 2
            if best is None or dist < best[0]:
                best = (dist, j, t, foot)
        _, j, t, foot = best
        s = self.s[j] + t * (self.s[j + 1] - self.s[j])
        phi_r = self.phi[j] + min(max(t, 0.0), 1.0) * (self.phi[j + 1] - self.phi[j])
        nx, ny = -math.sin(phi_r), math.cos(phi_r)
        e_y = (x - foot[0]) * nx + (y - foot[1]) * ny
        phi = heading + (math.pi if self.direction < 0 else 0.0)
        return Projection(float(s), float(e_y), _wrap(phi - phi_r), i)
