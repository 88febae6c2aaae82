"""The predictive steering tracker: speed and steering-wheel requests along each gear segment.

Steering: the spatial preview MPC of :mod:`parknss.sim.control.mpc` on the path-error
dynamics with a first-order steering lag (λ = T_s·|v| + σ), previewing the reference
curvature ``horizon·ds`` metres ahead, so the wheel starts turning before a curvature
change by the distance the lag will cost, and the error feedback absorbs what the plant
does differently (rack nonlinearity, slip, lag).

Speed: indexed by *distance to go*, never by the clock (open-loop replay of a planned
speed profile diverges, §V-G): v = min(v_max, the segment's planned speed at the current
distance (if any; floored), the steering-rate cap (the smoothed reference steering must
not need more than ``steer_rate_dps``; floored at ``v_floor_ms``) -- these caps made
reachable by braking at ``decel_ms2`` before them --, √(2·a_dec·(d_togo −
tol)), ramp-up from the last request at ``accel_ms2`` and at most ``lead_ms`` above the
measured speed, so the request does not run away from a car still held at a launch; the
ramp pauses while the car is faster than the request by more than ``ramp_hold_ms``, so
a plant that overshoots is
braked back by the speed feedback instead of being pushed on by the ramp's feed-forward).
The stop is requested when the distance to go falls below the gear's stop offset +
v·``stop_latency_s``. The offset starts at ``stop_tolerance_m`` and is fed back stroke by
stroke: at each standstill that ends a segment, the distance still to go (positive:
short, negative: past the end) moves the next stop of the same gear by
``stop_adapt_gain`` of it, within ±``stop_adapt_max_m``. A plant that stops short by the
same centimetre every time (the kinematic plant stops where it is asked to) would
otherwise lose that centimetre on every stroke: a 150-stroke slot shuffle (TPCAP case 7)
ended 34.5 cm sideways from its goal with a fixed 1 cm offset, 0.7 cm with 1 mm.

Phases per segment: ALIGN (stand, request the segment's gear, turn the wheel to the
MPC's steering at standstill until within ``steer_settle_deg``), DRIVE, STOP (request 0:
the interface brakes and holds until standstill), then the next segment's ALIGN; after
the last segment PARK (request park) and DONE once park is engaged at standstill.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from parknss.config import StrictModel
from parknss.plant import PlantOutput
from parknss.signals import DT
from parknss.sim.control.interface import Request
from parknss.sim.control.mpc import MpcConfig, PreviewMpc
from parknss.sim.control.path import PathReference, Projection
from parknss.sim.trajectory import Trajectory
from parknss.vehicle import VehicleGeometry, curvature, steer_for_curvature

ALIGN, DRIVE, STOP, PARK, DONE = "align", "drive", "stop", "park", "done"


class TrackerConfig(StrictModel):
    """Speed profile, stopping and steering of the tracker (m, s, deg)."""

    v_max_ms: float = Field(0.75, gt=0, description="speed ceiling, m/s")
    accel_ms2: float = Field(0.4, gt=0, description="speed-request ramp-up, m/s²")
    lead_ms: float = Field(0.15, gt=0, description="request at most this above vx, m/s")
    ramp_hold_ms: float = Field(
        0.05, ge=0, description="the ramp pauses while vx exceeds the request by more, m/s"
    )
    decel_ms2: float = Field(0.35, gt=0, description="approach deceleration, m/s²")
    v_floor_ms: float = Field(0.2, gt=0, description="lowest steering/planned speed cap, m/s")
    use_planned_speed: bool = Field(True, description="cap by the planned speed at s")
    steer_rate_dps: float = Field(400.0, gt=0, description="steering rate the cap assumes")
    steer_smooth_m: float = Field(0.3, gt=0, description="reference steering smoothing, m")
    steer_lookahead_m: float = Field(0.4, ge=0, description="slow down this far ahead, m")
    stop_tolerance_m: float = Field(0.01, ge=0, description="stop this close to the end, m")
    stop_latency_s: float = Field(0.0, ge=0, description="plus speed x this latency, s")
    stop_adapt_gain: float = Field(
        0.5, ge=0, le=1, description="stroke-level stop feedback: each segment's stop error "
        "(distance still to go at standstill, m) moves the next stop of its gear by this "
        "fraction of it (0: the fixed stop_tolerance_m)"
    )
    stop_adapt_max_m: float = Field(
        0.05, ge=0, description="the fed-back stop offset stays within ±this, m"
    )
    steer_settle_deg: float = Field(5.0, gt=0, description="launch once steer within, deg")
    ref_step_m: float = Field(0.02, gt=0, description="reference point spacing, m")
    search_window_m: float = Field(1.0, gt=0, description="projection search ±window, m")
    mpc: MpcConfig = MpcConfig()

    omit_at_default = frozenset({"stop_adapt_gain", "stop_adapt_max_m"})


class Tracker:
    """Drives a :class:`~parknss.sim.trajectory.Trajectory` segment by segment."""

    def __init__(
        self,
        traj: Trajectory,
        cfg: TrackerConfig | None = None,
        geom: VehicleGeometry | None = None,
        dt: float = DT,
        mpc: PreviewMpc | None = None,
    ) -> None:
        self.cfg = cfg or TrackerConfig()
        self.geom = geom or VehicleGeometry()
        self.dt = float(dt)
        c = self.cfg
        self.refs = [
            PathReference(
                seg,
                self.geom,
                c.ref_step_m,
                c.steer_rate_dps,
                c.steer_smooth_m,
                c.steer_lookahead_m,
            )
            for seg in traj.segments
        ]
        self.caps = [self._cap_profile(r) for r in self.refs]
        self.mpc = mpc if mpc is not None else PreviewMpc(c.mpc)
        self.k_max = float(curvature(self.geom.steer_lock_deg, self.geom))
        self._done_length = np.concatenate([[0.0], np.cumsum([r.length for r in self.refs])])
        self.index = 0
        self.phase = ALIGN if self.refs else PARK
        self.v_ref = 0.0
        self.hint = 0
        self.steer = 0.0
        self.last: Projection | None = None
        # the stop offset per gear (+1 drive, -1 reverse), m: fed back at each standstill
        self.stop_offset = {1: c.stop_tolerance_m, -1: c.stop_tolerance_m}

    # ------------------------------------------------------------------ state
    @property
    def done(self) -> bool:
        return self.phase == DONE

    @property
    def progress(self) -> float:
        """Path distance completed so far, m (segments done + position on the current)."""
        if self.index >= len(self.refs):
            return float(self._done_length[-1])
        s = self.last.s if self.last is not None else 0.0
        ref = self.refs[self.index]
        return float(self._done_length[self.index] + min(max(s, 0.0), ref.length))

    @property
    def distance_to_go(self) -> float:
        """Distance to the end of the current segment, m."""
        if self.index >= len(self.refs) or self.last is None:
            return 0.0
        return self.refs[self.index].length - self.last.s

    # ------------------------------------------------------------------ step
    def step(self, pose, y: PlantOutput, standstill: bool) -> Request:
        """Next request from the rear-axle pose (x, y, heading), bus output and standstill."""
        if self.phase in (PARK, DONE):
            if self.phase == PARK and y.gear == 0 and standstill:
                self.phase = DONE
            return Request(0, 0.0, self.steer)
        ref = self.refs[self.index]
        c = self.cfg
        proj = ref.project(pose[0], pose[1], pose[2], self.hint, c.search_window_m)
        self.last, self.hint = proj, proj.index
        self.steer = self._steering(ref, proj, y)
        d = ref.direction
        if self.phase == ALIGN:
            settled = abs(y.steer - self.steer) <= c.steer_settle_deg
            if y.gear == d and standstill and settled:
                self.phase, self.v_ref = DRIVE, 0.0
            else:
                return Request(d, 0.0, self.steer)
        if self.phase == DRIVE:
            togo = ref.length - proj.s
            v_est = max(abs(y.vx), self.v_ref)
            if togo > self.stop_offset[d] + v_est * c.stop_latency_s:
                v = self._speed(ref, proj.s, togo, abs(y.vx))
                accel = (v - self.v_ref) / self.dt
                self.v_ref = v
                return Request(d, v, self.steer, accel)
            self.phase = STOP
        self.v_ref = 0.0
        if standstill:
            self._feed_back_stop(d, ref.length - proj.s)
            self.index += 1
            self.hint = 0
            if self.index < len(self.refs):
                self.phase = ALIGN
                self.last = None
                return Request(self.refs[self.index].direction, 0.0, self.steer)
            self.phase = PARK
            return Request(0, 0.0, self.steer)
        return Request(d, 0.0, self.steer)

    def _feed_back_stop(self, gear: int, short_m: float) -> None:
        """Move the gear's next stop by the fed-back fraction of this stop's error (m to go
        at standstill; negative past the end), within ±stop_adapt_max_m."""
        c = self.cfg
        lim = c.stop_adapt_max_m
        offset = self.stop_offset[gear] - c.stop_adapt_gain * short_m
        self.stop_offset[gear] = min(max(offset, -lim), lim)

    def _cap_profile(self, ref: PathReference) -> np.ndarray:
        """Speed cap per reference point, m/s: v_max, the steering-rate cap and the planned
        speed (both floored at v_floor), made reachable at the approach deceleration."""
        c = self.cfg
        cap = np.minimum(np.maximum(ref.v_steer, c.v_floor_ms), c.v_max_ms)
        if c.use_planned_speed and ref.planned_speed is not None:
            cap = np.minimum(cap, np.maximum(ref.planned_speed, c.v_floor_ms))
        ds = np.diff(ref.s)
        for i in range(len(cap) - 2, -1, -1):  # backward pass: brake in time for each cap
            cap[i] = min(cap[i], math.sqrt(cap[i + 1] ** 2 + 2.0 * c.decel_ms2 * ds[i]))
        return cap

    def _speed(self, ref: PathReference, s: float, togo: float, speed: float) -> float:
        """Distance-indexed speed request, m/s (see module docstring)."""
        c = self.cfg
        cap = ref.at(s, self.caps[self.index])
        stop_at = self.stop_offset[ref.direction]
        approach = math.sqrt(2.0 * c.decel_ms2 * max(togo - stop_at, 0.0))
        # the ramp rises only while the car is not already faster than the request: a
        # request still ramping up behind a car that overshot would feed its ramp forward
        # against the speed feedback (the interface adds kff x the request's acceleration)
        rise = c.accel_ms2 * self.dt if speed <= self.v_ref + c.ramp_hold_ms else 0.0
        ramp = min(self.v_ref + rise, speed + c.lead_ms)
        return max(min(cap, approach, ramp), 0.0)

    def _steering(self, ref: PathReference, proj: Projection, y: PlantOutput) -> float:
        """Steering-wheel request (deg) from the preview MPC."""
        d = ref.direction
        k_act = d * float(curvature(y.steer, self.geom))
        state = np.array([proj.e_y, proj.e_phi, k_act])
        k_ref = np.interp(proj.s + self.mpc.preview, ref.s, ref.kappa)
        u = self.mpc.command(state, k_ref, y.vx)
        kappa = min(max(d * u, -self.k_max), self.k_max)
        return float(steer_for_curvature(kappa, self.geom))
