"""Checks of a posted scene JSON before it is built: every coordinate finite and within
the server's physical range, every heading within its range, the meta fields of the
right types. A number like 1e308 passes "finite" but overflows the geometry (areas,
grid sizes); a name that is a number fails the answer after the whole plan was computed.
Both are refused here, at once, with HTTP 422 and the path of the offending value.
"""

from __future__ import annotations

import math
from numbers import Real

from pydantic import TypeAdapter, ValidationError

from parknss.sim.scenarios import SceneMeta
from parknss.web.errors import BadSceneError

_META = TypeAdapter(SceneMeta)


def _number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool)


def _check(value, limit: float, where: str, unit: str) -> None:
    if not _number(value):
        return  # not a number: Scene.from_json says what it should be
    if isinstance(value, float) and not math.isfinite(value):
        raise BadSceneError(f"{where}: must be a finite number, got {value}")
    if abs(value) > limit:
        small = isinstance(value, float) or abs(value) < 10**300
        shown = f"{float(value):.3g}" if small else "a huge number"
        raise BadSceneError(
            f"{where}: {shown} {unit} is outside the server's range of ±{limit:g} {unit}"
        )


def check_pose(pose, where: str, max_coordinate_m: float, max_heading_rad: float) -> None:
    """BadSceneError when a pose's x, y are beyond ±``max_coordinate_m`` m or its heading
    beyond ±``max_heading_rad`` rad (or any of them is not finite)."""
    if not isinstance(pose, list | tuple):
        return
    for i, v in enumerate(pose[:3]):
        limit, unit = (max_heading_rad, "rad") if i == 2 else (max_coordinate_m, "m")
        _check(v, limit, f"{where}[{i}]", unit)


def check_scene_json(doc, max_coordinate_m: float, max_heading_rad: float) -> None:
    """BadSceneError for the first out-of-range number (bounds, map outline, vertices,
    start, goal) or mistyped meta field of a posted scene; what is not a number is left to
    :meth:`parknss.sim.scenarios.Scene.from_json`."""
    if not isinstance(doc, dict):
        return
    bounds = doc.get("bounds")
    if isinstance(bounds, list | tuple):
        for i, v in enumerate(bounds[:4]):
            _check(v, max_coordinate_m, f"scene.bounds[{i}]", "m")
    outline = doc.get("map_outline")
    if isinstance(outline, list):
        for j, point in enumerate(outline):
            if isinstance(point, list | tuple):
                for k, v in enumerate(point[:2]):
                    _check(v, max_coordinate_m, f"scene.map_outline[{j}][{k}]", "m")
    for key in ("start", "goal"):
        check_pose(doc.get(key), f"scene.{key}", max_coordinate_m, max_heading_rad)
    obstacles = doc.get("obstacles")
    if isinstance(obstacles, list):
        for i, ob in enumerate(obstacles):
            vertices = ob.get("vertices") if isinstance(ob, dict) else None
            if not isinstance(vertices, list):
                continue
            for j, vertex in enumerate(vertices):
                if isinstance(vertex, list | tuple):
                    for k, v in enumerate(vertex[:2]):
                        where = f"scene.obstacles[{i}].vertices[{j}][{k}]"
                        _check(v, max_coordinate_m, where, "m")
    meta = doc.get("meta")
    if isinstance(meta, dict):
        try:
            _META.validate_python(meta)
        except ValidationError as exc:
            err = exc.errors(include_url=False)[0]
            loc = ".".join(str(p) for p in err["loc"])
            raise BadSceneError(f"scene.meta.{loc}: {err['msg']}") from None
