"""Shaping plans and time series for the browser: resampled paths, footprints along a
path, decimated and rounded series. Pure functions of arrays (m, rad, s)."""

from __future__ import annotations

import math

import numpy as np

from parknss.sim.geometry import footprint
from parknss.sim.trajectory import Trajectory
from parknss.vehicle import VehicleGeometry
from parknss.web.schemas import PathSegment, Series

DIGITS = 4  # decimals kept in the JSON (0.1 mm, 0.1 mrad)
LOOP_RATE_HZ = 100.0  # the closed loop's sample rate, Hz


def resample_poses(poses: np.ndarray, step_m: float) -> np.ndarray:
    """Poses of a path at about ``step_m`` spacing of arc length; both ends kept."""
    p = np.asarray(poses, dtype=float)
    if len(p) <= 2:
        return p
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p[:, :2], axis=0).T))])
    bins = np.floor(s / step_m + 1e-9)
    keep = np.concatenate([[True], bins[1:] != bins[:-1]])
    keep[-1] = True
    return p[keep]


def _pose(p) -> tuple[float, float, float]:
    return (round(float(p[0]), DIGITS), round(float(p[1]), DIGITS), round(float(p[2]), DIGITS))


def path_segments(traj: Trajectory | None, step_m: float) -> list[PathSegment]:
    """The gear segments of ``traj`` resampled at ``step_m`` (empty without a trajectory)."""
    if traj is None:
        return []
    return [
        PathSegment(
            direction=int(s.direction),
            poses=[_pose(p) for p in resample_poses(s.poses[:, :3], step_m)],
        )
        for s in traj.segments
    ]


def cusp_poses(traj: Trajectory | None) -> list[tuple[float, float, float]]:
    """The poses where the car stops to change gear."""
    if traj is None:
        return []
    return [_pose(s.poses[-1]) for s in traj.segments[:-1]]


def path_footprints(
    traj: Trajectory | None, geom: VehicleGeometry, step_m: float
) -> list[list[tuple[float, float]]]:
    """Car outlines (4 corners, m) every ``step_m`` of path length and at every segment end."""
    if traj is None:
        return []
    out = []
    for seg in traj.segments:
        for p in resample_poses(seg.poses[:, :3], step_m):
            out.append(
                [(round(float(x), DIGITS), round(float(y), DIGITS)) for x, y in footprint(p, geom)]
            )
    return out


def _clean(values: np.ndarray) -> list[float | None]:
    """Rounded floats; non-finite samples become None (JSON null)."""
    r = np.round(np.asarray(values, dtype=float), DIGITS)
    return [float(v) if math.isfinite(v) else None for v in r]


def decimation_stride(n: int, rate_hz: float, max_points: int) -> int:
    """Samples skipped per sample sent: the rate's stride, widened to fit ``max_points``."""
    stride = max(1, round(LOOP_RATE_HZ / rate_hz))
    return max(stride, math.ceil(n / max(max_points - 1, 1)))


def decimate_series(series: dict[str, np.ndarray], rate_hz: float, max_points: int) -> Series:
    """The run's 100 Hz series at every stride-th sample plus the last one."""
    n = len(series["t"])
    stride = decimation_stride(n, rate_hz, max_points)
    idx = np.arange(0, n, stride)
    if n and idx[-1] != n - 1:
        idx = np.append(idx, n - 1)
    cols = {
        name: _clean(series[name][idx])
        for name in Series.model_fields
        if name not in ("rate_hz", "stride")
    }
    return Series(rate_hz=LOOP_RATE_HZ / stride, stride=stride, **cols)


def finite(doc: dict) -> dict:
    """A flat dict of numbers, flags and text for JSON: floats rounded to 6 significant
    digits, non-finite floats None (JSON null), NumPy scalars as Python ones."""
    out = {}
    for k, v in doc.items():
        if isinstance(v, bool | np.bool_):
            out[k] = bool(v)
        elif isinstance(v, int | np.integer):
            out[k] = int(v)
        elif isinstance(v, float | np.floating):
            out[k] = float(f"{float(v):.6g}") if math.isfinite(v) else None
        else:
            out[k] = v
    return out
