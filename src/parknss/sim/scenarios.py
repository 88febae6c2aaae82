"""Parking scenes as data, and the deterministic scenario grids of the paper (§V-G).

A :class:`Scene` is a rectangular map, convex obstacle polygons (neighbour cars, curbs, a
lane barrier), and start and goal rear-axle poses (x m, y m, heading rad). Scenes are
plain JSON so users can write their own (:meth:`Scene.load`).

The grids (all dimensions in ``configs/scenarios.yaml``, :class:`ScenariosConfig`):

* **36-cell grid**: bay type (parallel, perpendicular, angled) x approach (left, right) x
  difficulty tier (0 loose, 1 middle, 2 tight) x lane barrier (absent, present).
  Cell index = 12·bay + 6·approach + 2·tier + barrier, with bay 0 parallel,
  1 perpendicular, 2 angled; approach 0 left, 1 right; barrier 0 absent, 1 present.
* **12-cell tuning core**: the middle tier of every bay x approach x barrier (cells with
  tier 1): every geometry and side is represented at typical difficulty while both
  extreme tiers stay out of tuning.
* **252-cell robustness grid**: 7 perturbations x the 36 cells, index = 36·variant + cell,
  variants 0 skew +5° (every neighbour car rotated about its centre), 1 skew -5°,
  2 start jitter a (+0.25 m along and +0.25 m left of the start heading, +3°),
  3 start jitter b (-0.25 m, -0.25 m, -3°), 4 slot 7.5 cm tighter, 5 slot 7.5 cm looser,
  6 combined (skew +5°, jitter a and tighter at once).

Frame: the lane runs along x, the bays lie at y < 0 behind the bay entrance line y = 0,
the lane occupies 0 <= y <= lane width (the barrier, when present, lies just beyond it).
"Left" approach: the car starts at x < 0 driving +x (bays on its right); "right": it
starts at x > 0 driving -x (bays on its left). Parallel and perpendicular right-approach
scenes are the mirror images (x -> -x) of the left ones; angled bays keep their slant, so
from the right the car approaches against the slant (the harder back-in).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from pydantic import Field

from parknss.config import StrictModel, load_config, read_json
from parknss.errors import ConfigError, PlanningError
from parknss.sim.geometry import convex_polygon, rectangle
from parknss.sim.obstacles import (
    ObstacleInputConfig,
    SceneImportConfig,
    check_counts,
    drawn_obstacle,
)
from parknss.vehicle import VehicleGeometry

BAYS = ("parallel", "perpendicular", "angled")
APPROACHES = ("left", "right")
TIERS = (0, 1, 2)
N_CELLS = 36
PERTURBATIONS = ("skew_pos", "skew_neg", "jitter_a", "jitter_b", "tighter", "looser", "combined")
N_ROBUST = N_CELLS * len(PERTURBATIONS)
GRIDS = ("36", "12", "252")
"""The scenario grids by name: the 36-cell grid, its 12-cell tuning core, the 252-cell
robustness grid."""
SCENE_FORMAT = "parknss.scene"
SCENE_VERSION = 1


# ---------------------------------------------------------------------------------------
# Configuration


class ParallelBayConfig(StrictModel):
    """Parallel slots between two rows of curbside cars."""

    slot_length_cars: tuple[float, float, float] = Field(
        (1.5, 1.35, 1.2), description="free gap between neighbour bumpers / car length, tier 0..2"
    )
    strip_depth_m: float = Field(2.5, gt=0, description="curb to lane edge, m")
    curb_offset_m: float = Field(0.35, ge=0, description="car side to curb, m")
    lane_width_m: float = Field(3.5, gt=0, description="driving lane width, m")
    row_gap_m: float = Field(1.0, ge=0, description="gap between further parked cars, m")
    start_past_slot_m: float = Field(
        1.0, description="start rear axle ahead of the slot's far end (beside the neighbour), m"
    )
    start_side_gap_m: float = Field(0.8, ge=0, description="start: car side to parked row, m")


class BayRowConfig(StrictModel):
    """A row of perpendicular or angled bays with cars in the neighbouring bays."""

    angle_deg: float = Field(90.0, gt=0, le=90, description="bay axis to lane axis, deg")
    bay_width_extra_m: tuple[float, float, float] = Field(
        (1.0, 0.7, 0.4), description="bay width minus car width, m, tier 0..2"
    )
    setback_m: float = Field(0.3, ge=0, description="parked front bumper behind entrance, m")
    rear_gap_m: float = Field(0.3, ge=0, description="parked rear corner to back curb, m")
    lane_width_m: float = Field(6.0, gt=0, description="aisle width, m")
    neighbour_shift_m: float = Field(
        0.0, description="neighbour cars shifted from their bay centre toward the slot, m"
    )


class RobustnessConfig(StrictModel):
    """Magnitudes of the held-out perturbations."""

    skew_deg: float = 5.0
    jitter_m: float = 0.25
    jitter_deg: float = 3.0
    slot_delta_m: float = 0.075


class ScenariosConfig(StrictModel):
    """Every dimension of the scenario grids (m and deg)."""

    parallel: ParallelBayConfig = ParallelBayConfig()
    perpendicular: BayRowConfig = BayRowConfig()
    angled: BayRowConfig = BayRowConfig(angle_deg=60.0, lane_width_m=4.5)
    neighbours_per_side: int = Field(2, ge=0, description="parked cars on each side of slot")
    neighbour_length_m: float = Field(4.95, gt=0)
    neighbour_width_m: float = Field(1.98, gt=0)
    start_distance_m: float = Field(
        9.0, description="perpendicular/angled start: rear axle before the slot centre, m"
    )
    map_half_length_m: float = Field(16.0, gt=0, description="map from -this to +this in x")
    open_lane_extra_m: float = Field(8.0, gt=0, description="map beyond the lane, no barrier")
    curb_thickness_m: float = Field(0.2, gt=0)
    barrier_thickness_m: float = Field(0.2, gt=0)
    core_tier: int = Field(1, ge=0, le=2, description="tier of the 12-cell tuning core")
    robustness: RobustnessConfig = RobustnessConfig()
    obstacles: ObstacleInputConfig = ObstacleInputConfig()
    imports: SceneImportConfig = SceneImportConfig()


def load_scenarios_config(path: str | Path | None = None) -> ScenariosConfig:
    """Read ``path`` (default: the shipped configs/scenarios.yaml)."""
    return load_config(ScenariosConfig, path, default="scenarios.yaml")


# ---------------------------------------------------------------------------------------
# Scene


@dataclass(frozen=True)
class Obstacle:
    """An obstacle: kind ('car', 'curb', 'wall', ... any label), its outline as drawn
    ((M, 2) CCW, m; convex or not) and its convex parts (:mod:`parknss.sim.obstacles`;
    empty: the outline is convex and its own part)."""

    kind: str
    vertices: np.ndarray
    parts: tuple[np.ndarray, ...] = ()

    def convex_parts(self) -> tuple[np.ndarray, ...]:
        """The convex (K, 2) CCW polygons whose union is the outline, m."""
        return self.parts or (self.vertices,)


@dataclass(frozen=True)
class SceneMeta:
    """Where a scene comes from. Grid scenes fill every field; user scenes may not."""

    name: str = "custom"
    bay: str = "custom"
    approach: str | None = None
    tier: int | None = None
    barrier: bool | None = None
    cell: int | None = None
    robust_index: int | None = None
    perturbation: str = "nominal"
    slot_size_m: float | None = None
    source: str | None = None
    origin_m: tuple[float, float] | None = None
    """Where the scene's local frame lies in the source's coordinates (x, y m): imported
    benchmark scenes are shifted so their numbers stay small (TPCAP lies near 4e9 m)."""


VIEW_ZOOM_ABOVE_M = 100.0
"""Maps larger than this (m, either side) are shown zoomed to the problem (start, goal,
the plan) in figures and the web view."""
VIEW_ZOOM_PAD_M = 10.0
"""...with this border around them, m."""


@dataclass(frozen=True)
class Scene:
    """A parking problem: bounds (xmin, ymin, xmax, ymax) m, obstacles, start/goal poses."""

    bounds: tuple[float, float, float, float]
    obstacles: tuple[Obstacle, ...]
    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    meta: SceneMeta = field(default_factory=SceneMeta)
    notes: tuple[str, ...] = field(default=(), compare=False)
    """What loading normalised (removed vertices, lines made walls): reported, not saved."""
    map_outline: tuple[tuple[float, float], ...] | None = None
    """The map as a convex CCW polygon (x, y m) when it is not the box ``bounds`` (which is
    then its bounding box): e.g. a TPCAP map aligned with the goal, so that it moves with
    the scene. The planner, the refinement and the dense check keep the car inside it."""

    def map_planes(self) -> tuple[np.ndarray, np.ndarray]:
        """(A (M, 2), b (M,)): a point p is on the map where A @ p <= b (the outline's
        edges, else the box's four sides)."""
        return map_planes(self.bounds, self.map_outline)

    def obstacle_arrays(self) -> list[np.ndarray]:
        """The convex parts of every obstacle as a list of (M, 2) CCW arrays, m: what the
        search, the dense check, the refinement and the collision check use (their union
        is each obstacle as drawn, so clearances are exact distances to it)."""
        return [p for o in self.obstacles for p in o.convex_parts()]

    def to_json(self) -> dict:
        """A JSON-serialisable dict (the file format of :meth:`load`)."""
        return {
            "format": SCENE_FORMAT,
            "version": SCENE_VERSION,
            "bounds": [float(v) for v in self.bounds],
            "obstacles": [
                {"kind": o.kind, "vertices": np.round(o.vertices, 9).tolist()}
                for o in self.obstacles
            ],
            "start": [float(v) for v in self.start],
            "goal": [float(v) for v in self.goal],
            "meta": dict(self.meta.__dict__),
        } | (
            {} if self.map_outline is None
            else {"map_outline": [list(map(float, p)) for p in self.map_outline]}
        )

    @classmethod
    def from_json(
        cls, data, source: str = "scene", cfg: ObstacleInputConfig | None = None
    ) -> Scene:
        """Build a scene from :meth:`to_json` output; PlanningError naming ``source``.
        Obstacles may be any simple polygon or a ``"shape": "polyline"`` wall
        (:mod:`parknss.sim.obstacles`, limits of ``cfg``)."""
        return _scene_from_json(data, source, cfg)

    @classmethod
    def load(cls, path: str | Path, cfg: ObstacleInputConfig | None = None) -> Scene:
        """Read a scene JSON file; PlanningError with the file name if it is malformed."""
        p = Path(path)
        if not p.is_file():
            raise PlanningError(f"{p}: scene file not found")
        data = read_json(p, PlanningError)  # depth-limited, unreadable: one line
        return _scene_from_json(data, str(p), cfg)

    def save(self, path: str | Path) -> Path:
        """Write the scene as JSON."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(self.to_json(), indent=1))
        return p


def _numbers(value, n: int, what: str, source: str) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n:
        raise PlanningError(f"{source}: {what} must be a list of {n} numbers")
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise PlanningError(f"{source}: {what} must be a list of {n} numbers") from exc
    if any(isinstance(v, bool) for v in value) or not all(math.isfinite(v) for v in out):
        raise PlanningError(f"{source}: {what} must be finite numbers")
    return out


def obstacle_from_drawing(
    kind: str, vertices, name: str, shape: str = "polygon", cfg: ObstacleInputConfig | None = None
) -> tuple[Obstacle, str | None]:
    """(obstacle, note or None) of one drawn obstacle
    (:func:`~parknss.sim.obstacles.drawn_obstacle`); the note says what was normalised."""
    out = drawn_obstacle(vertices, name, shape, cfg)
    parts = out.parts if len(out.parts) > 1 else ()
    what = []
    if out.removed:
        what.append(f"{out.removed} duplicate/collinear vertices removed")
    if out.wall:
        what.append("drawn as a line: a wall")
    if len(out.parts) > 1:
        what.append(f"split into {len(out.parts)} convex parts")
    return Obstacle(kind, out.vertices, parts), (f"{name}: {', '.join(what)}" if what else None)


def _scene_from_json(data, source: str, cfg: ObstacleInputConfig | None = None) -> Scene:
    cfg = cfg or ObstacleInputConfig()
    if not isinstance(data, dict):
        raise PlanningError(f"{source}: expected a JSON object at top level")
    if data.get("format", SCENE_FORMAT) != SCENE_FORMAT:
        raise PlanningError(f"{source}: format is {data.get('format')!r}, not {SCENE_FORMAT!r}")
    if data.get("version", SCENE_VERSION) != SCENE_VERSION:
        raise PlanningError(f"{source}: unsupported scene version {data.get('version')!r}")
    for key in ("bounds", "obstacles", "start", "goal"):
        if key not in data:
            raise PlanningError(f"{source}: missing key {key!r}")
    bounds = _numbers(data["bounds"], 4, "bounds [xmin, ymin, xmax, ymax]", source)
    if not (bounds[0] < bounds[2] and bounds[1] < bounds[3]):
        raise PlanningError(f"{source}: bounds need xmin < xmax and ymin < ymax")
    if not isinstance(data["obstacles"], list):
        raise PlanningError(f"{source}: obstacles must be a list")
    raw = data["obstacles"]
    n_vertices = sum(
        len(ob["vertices"])
        for ob in raw
        if isinstance(ob, dict) and isinstance(ob.get("vertices"), list)
    )
    check_counts(len(raw), n_vertices, source, cfg)  # before any work on them
    obstacles, notes = [], []
    for i, ob in enumerate(raw):
        if not isinstance(ob, dict) or "vertices" not in ob:
            raise PlanningError(f"{source}: obstacle {i} must be an object with 'vertices'")
        kind = ob.get("kind", "obstacle")
        if not isinstance(kind, str) or not kind:
            raise PlanningError(f"{source}: obstacle {i} kind must be a non-empty string")
        name = f"{source}: obstacle {i} ({kind})"
        if ob.get("holes") or ob.get("interiors"):
            raise PlanningError(f"{name}: polygons with holes are not supported")
        shape = ob.get("shape", "polygon")
        obstacle, note = obstacle_from_drawing(kind, ob["vertices"], name, shape, cfg)
        obstacles.append(obstacle)
        if note:
            notes.append(note)
    start = _numbers(data["start"], 3, "start [x, y, heading]", source)
    goal = _numbers(data["goal"], 3, "goal [x, y, heading]", source)
    meta_in = data.get("meta", {}) or {}
    if not isinstance(meta_in, dict):
        raise PlanningError(f"{source}: meta must be an object")
    unknown = set(meta_in) - set(SceneMeta.__dataclass_fields__)
    if unknown:
        raise PlanningError(f"{source}: unknown meta field(s) {sorted(unknown)}")
    try:
        meta = SceneMeta(**meta_in)
    except TypeError as exc:
        raise PlanningError(f"{source}: bad meta ({exc})") from exc
    outline = None
    if data.get("map_outline") is not None:
        outline = _outline(data["map_outline"], source)
        lo, hi = np.min(outline, axis=0), np.max(outline, axis=0)
        bounds = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    return Scene(bounds, tuple(obstacles), start, goal, meta, tuple(notes), outline)


def _outline(raw, source: str) -> tuple[tuple[float, float], ...]:
    """A map outline from JSON: a convex counter-clockwise polygon of finite points."""
    try:
        pts = np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as exc:
        raise PlanningError(f"{source}: map_outline must be a list of [x, y] points") from exc
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
        raise PlanningError(f"{source}: map_outline must be 3 or more finite [x, y] points")
    d = np.roll(pts, -1, axis=0) - pts
    cross = d[:, 0] * np.roll(d[:, 1], -1) - d[:, 1] * np.roll(d[:, 0], -1)
    if np.any(cross <= 0.0):
        raise PlanningError(f"{source}: map_outline must be convex and counter-clockwise")
    return tuple((float(x), float(y)) for x, y in pts)


def map_planes(bounds, outline=None) -> tuple[np.ndarray, np.ndarray]:
    """Half-planes (A (M, 2), b (M,)) of a map: A @ p <= b on it. ``outline``: a convex
    CCW polygon (its edges' outward normals, unit length); None: the box ``bounds``."""
    if outline is None:
        xmin, ymin, xmax, ymax = (float(v) for v in bounds)
        A = np.array([[-1.0, 0.0], [0.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
        return A, np.array([-xmin, -ymin, xmax, ymax])
    p = np.asarray(outline, dtype=float)
    d = np.roll(p, -1, axis=0) - p
    n = np.column_stack([d[:, 1], -d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
    return n, np.einsum("ij,ij->i", n, p)


# ---------------------------------------------------------------------------------------
# Grid addressing


@dataclass(frozen=True)
class Cell:
    """One cell of the 36-cell grid."""

    index: int
    bay: str
    approach: str
    tier: int
    barrier: bool

    @property
    def name(self) -> str:
        return f"{self.bay}-{self.approach}-t{self.tier}-{'barrier' if self.barrier else 'open'}"


def cell(index: int) -> Cell:
    """The cell at grid index 0..35 (index = 12·bay + 6·approach + 2·tier + barrier)."""
    if not isinstance(index, int | np.integer) or not 0 <= index < N_CELLS:
        raise PlanningError(f"grid cell index must be 0..{N_CELLS - 1}, got {index!r}")
    i = int(index)
    return Cell(i, BAYS[i // 12], APPROACHES[(i // 6) % 2], (i // 2) % 3, bool(i % 2))


def cell_index(bay: str, approach: str, tier: int, barrier: bool) -> int:
    """Inverse of :func:`cell`."""
    if bay not in BAYS or approach not in APPROACHES or tier not in TIERS:
        raise PlanningError(f"no grid cell for bay={bay!r} approach={approach!r} tier={tier!r}")
    return 12 * BAYS.index(bay) + 6 * APPROACHES.index(approach) + 2 * tier + int(barrier)


def core_cells(cfg: ScenariosConfig | None = None) -> list[int]:
    """The 12 tuning-core cell indices: tier ``core_tier`` of every bay x approach x barrier."""
    tier = (cfg or ScenariosConfig()).core_tier
    return [i for i in range(N_CELLS) if cell(i).tier == tier]


def robust_address(index: int) -> tuple[int, str]:
    """(cell index, perturbation name) of robustness-grid index 0..251."""
    if not isinstance(index, int | np.integer) or not 0 <= index < N_ROBUST:
        raise PlanningError(f"robustness index must be 0..{N_ROBUST - 1}, got {index!r}")
    return int(index) % N_CELLS, PERTURBATIONS[int(index) // N_CELLS]


# ---------------------------------------------------------------------------------------
# Scene construction


def slot_size(bay: str, tier: int, cfg: ScenariosConfig, geom: VehicleGeometry) -> float:
    """Nominal slot size of a tier, m: gap length (parallel) or bay width (others)."""
    if bay == "parallel":
        return cfg.parallel.slot_length_cars[tier] * geom.length
    row = cfg.perpendicular if bay == "perpendicular" else cfg.angled
    return geom.width + row.bay_width_extra_m[tier]


def _car_rect(cfg: ScenariosConfig, cx: float, cy: float, angle: float) -> np.ndarray:
    return rectangle(cx, cy, cfg.neighbour_length_m, cfg.neighbour_width_m, angle)


def _parallel(cfg, geom, slot, barrier):
    """Obstacles, goal and lane width of a parallel slot (left approach)."""
    pc = cfg.parallel
    half_x = cfg.map_half_length_m
    y_curb = -pc.strip_depth_m
    cy = y_curb + pc.curb_offset_m + 0.5 * cfg.neighbour_width_m
    cars = []
    for side in (-1.0, 1.0):
        x_near = 0.5 * slot
        for k in range(cfg.neighbours_per_side):
            cx = x_near + 0.5 * cfg.neighbour_length_m + k * (cfg.neighbour_length_m + pc.row_gap_m)
            cars.append(_car_rect(cfg, side * cx, cy, 0.0))
    curb = np.array(
        [
            [-half_x, y_curb - cfg.curb_thickness_m],
            [half_x, y_curb - cfg.curb_thickness_m],
            [half_x, y_curb],
            [-half_x, y_curb],
        ]
    )
    goal_y = y_curb + pc.curb_offset_m + 0.5 * geom.width
    goal = (-(0.5 * geom.length - geom.rear_overhang), goal_y, 0.0)
    return cars, curb, goal, pc.lane_width_m, y_curb - cfg.curb_thickness_m


def _bay_row(cfg, geom, row: BayRowConfig, slot, nominal):
    """Obstacles, goal and lane width of a perpendicular/angled row (left approach)."""
    half_x = cfg.map_half_length_m
    a = math.radians(row.angle_deg)
    u = np.array([math.cos(a), math.sin(a)])  # bay axis, pointing out of the bay
    pitch_slot = slot / math.sin(a)
    pitch = nominal / math.sin(a)
    front_set = row.setback_m
    # centre of a car parked with its front bumper setback behind entrance point (x, 0)
    centre_off = -(front_set + 0.5 * cfg.neighbour_length_m) * u
    cars = []
    for side in (-1.0, 1.0):
        for k in range(cfg.neighbours_per_side):
            x = side * (0.5 * pitch_slot + 0.5 * pitch + k * pitch - row.neighbour_shift_m)
            c = np.array([x, 0.0]) + centre_off
            cars.append(_car_rect(cfg, c[0], c[1], a))
    lowest = -(front_set + cfg.neighbour_length_m) * math.sin(
        a
    ) - 0.5 * cfg.neighbour_width_m * math.cos(a)
    y_curb = lowest - row.rear_gap_m
    curb = np.array(
        [
            [-half_x, y_curb - cfg.curb_thickness_m],
            [half_x, y_curb - cfg.curb_thickness_m],
            [half_x, y_curb],
            [-half_x, y_curb],
        ]
    )
    rear_axle = -(front_set + geom.length - geom.rear_overhang) * u
    goal = (float(rear_axle[0]), float(rear_axle[1]), a)
    return cars, curb, goal, row.lane_width_m, y_curb - cfg.curb_thickness_m


def _rotate_about_centroid(poly: np.ndarray, angle: float) -> np.ndarray:
    c = poly.mean(axis=0)
    cs, sn = math.cos(angle), math.sin(angle)
    return (poly - c) @ np.array([[cs, sn], [-sn, cs]]) + c


def _mirror_x(scene: Scene) -> Scene:
    """Mirror a scene in the y axis (x -> -x, heading -> π - heading)."""

    def pose(p):
        return (-p[0], p[1], math.atan2(math.sin(math.pi - p[2]), math.cos(math.pi - p[2])))

    obs = tuple(
        Obstacle(o.kind, convex_polygon(o.vertices * [-1.0, 1.0], o.kind)) for o in scene.obstacles
    )
    xmin, ymin, xmax, ymax = scene.bounds
    return replace(
        scene,
        bounds=(-xmax, ymin, -xmin, ymax),
        obstacles=obs,
        start=pose(scene.start),
        goal=pose(scene.goal),
    )


def build_scene(
    bay: str,
    approach: str,
    tier: int,
    barrier: bool,
    *,
    cfg: ScenariosConfig | None = None,
    geom: VehicleGeometry | None = None,
    perturbation: str = "nominal",
    slot_override_m: float | None = None,
) -> Scene:
    """Build one grid scene; ``slot_override_m`` replaces the tier's slot size (m)."""
    cfg = cfg or ScenariosConfig()
    geom = geom or VehicleGeometry()
    if bay not in BAYS or approach not in APPROACHES or tier not in TIERS:
        raise PlanningError(f"no scene for bay={bay!r} approach={approach!r} tier={tier!r}")
    if perturbation != "nominal" and perturbation not in PERTURBATIONS:
        raise PlanningError(f"unknown perturbation {perturbation!r}; one of {PERTURBATIONS}")
    rb = cfg.robustness
    parts = {"combined": ("skew_pos", "jitter_a", "tighter")}.get(perturbation, (perturbation,))
    nominal = slot_size(bay, tier, cfg, geom)
    slot = nominal if slot_override_m is None else float(slot_override_m)
    slot += rb.slot_delta_m * (("looser" in parts) - ("tighter" in parts))
    if bay == "parallel":
        cars, curb, goal, lane, ymin = _parallel(cfg, geom, slot, barrier)
    else:
        row = cfg.perpendicular if bay == "perpendicular" else cfg.angled
        cars, curb, goal, lane, ymin = _bay_row(cfg, geom, row, slot, nominal)
    skew = math.radians(rb.skew_deg) * (("skew_pos" in parts) - ("skew_neg" in parts))
    if skew:
        cars = [_rotate_about_centroid(c, skew) for c in cars]
    half_x = cfg.map_half_length_m
    obstacles = [Obstacle("car", convex_polygon(c, "car")) for c in cars]
    obstacles.append(Obstacle("curb", convex_polygon(curb, "curb")))
    if barrier:
        bar = np.array(
            [
                [-half_x, lane],
                [half_x, lane],
                [half_x, lane + cfg.barrier_thickness_m],
                [-half_x, lane + cfg.barrier_thickness_m],
            ]
        )
        obstacles.append(Obstacle("barrier", convex_polygon(bar, "barrier")))
        ymax = lane + cfg.barrier_thickness_m
    else:
        ymax = lane + cfg.open_lane_extra_m
    if bay == "parallel":  # stopped beside the front neighbour, as a driver would
        pc = cfg.parallel
        row_top = -pc.strip_depth_m + pc.curb_offset_m + cfg.neighbour_width_m
        start = (
            0.5 * slot + pc.start_past_slot_m,
            row_top + pc.start_side_gap_m + 0.5 * geom.width,
            0.0,
        )
    else:
        start = (-cfg.start_distance_m, 0.5 * lane, 0.0)
    scene = Scene((-half_x, ymin, half_x, ymax), tuple(obstacles), start, goal)
    if approach == "right":
        if bay == "angled":  # bays keep their slant; only the start is mirrored
            scene = replace(scene, start=(cfg.start_distance_m, 0.5 * lane, math.pi))
        else:
            scene = _mirror_x(scene)
    jit = ("jitter_a" in parts) - ("jitter_b" in parts)
    if jit:
        x, y, th = scene.start
        dl, dt = jit * rb.jitter_m, jit * rb.jitter_m
        scene = replace(
            scene,
            start=(
                x + dl * math.cos(th) - dt * math.sin(th),
                y + dl * math.sin(th) + dt * math.cos(th),
                th + jit * math.radians(rb.jitter_deg),
            ),
        )
    idx = cell_index(bay, approach, tier, barrier)
    c = cell(idx)
    meta = SceneMeta(
        name=c.name if perturbation == "nominal" else f"{c.name}-{perturbation}",
        bay=bay,
        approach=approach,
        tier=tier,
        barrier=barrier,
        cell=idx,
        robust_index=None
        if perturbation == "nominal"
        else PERTURBATIONS.index(perturbation) * N_CELLS + idx,
        perturbation=perturbation,
        slot_size_m=round(slot, 6),
    )
    return replace(scene, meta=meta)


def grid_scene(
    index: int, cfg: ScenariosConfig | None = None, geom: VehicleGeometry | None = None
) -> Scene:
    """Scene of 36-cell grid index 0..35."""
    c = cell(index)
    return build_scene(c.bay, c.approach, c.tier, c.barrier, cfg=cfg, geom=geom)


def robust_scene(
    index: int, cfg: ScenariosConfig | None = None, geom: VehicleGeometry | None = None
) -> Scene:
    """Scene of robustness-grid index 0..251 (index = 36·variant + cell)."""
    ci, pert = robust_address(index)
    c = cell(ci)
    return build_scene(c.bay, c.approach, c.tier, c.barrier, cfg=cfg, geom=geom, perturbation=pert)


def grid(cfg: ScenariosConfig | None = None, geom: VehicleGeometry | None = None) -> list[Scene]:
    """All 36 grid scenes in index order."""
    return [grid_scene(i, cfg, geom) for i in range(N_CELLS)]


def grid_cells(grid: str, cfg: ScenariosConfig | None = None, spec: str | None = None) -> list[int]:
    """Cell indices of grid "36", "12" (the tuning core, indices of the 36-cell grid) or
    "252", or the subset ``spec`` of them ("0-5,9"); one-line ConfigError otherwise."""
    if grid not in GRIDS:
        raise ConfigError(f"--grid {grid!r}: one of {', '.join(GRIDS)}")
    if grid == "12":
        allowed = core_cells(cfg if cfg is not None else load_scenarios_config())
    else:
        allowed = list(range(N_ROBUST if grid == "252" else N_CELLS))
    if not spec:
        return allowed
    out: list[int] = []
    for part in spec.split(","):
        lo, _, hi = part.strip().partition("-")
        try:
            rng = range(int(lo), int(hi or lo) + 1)
        except ValueError as exc:
            raise ConfigError(f"--cells {spec!r}: expected numbers like 0-5,9") from exc
        for i in rng:
            if i not in allowed:
                raise ConfigError(f"--cells: {i} is not a cell of grid {grid}")
            out.append(i)
    return out


def cell_scene(
    grid: str, index: int, cfg: ScenariosConfig | None = None, geom: VehicleGeometry | None = None
) -> Scene:
    """Scene ``index`` of grid "252" (robustness) or of the 36-cell grid ("36", "12")."""
    if grid == "252":
        return robust_scene(index, cfg, geom)
    return grid_scene(index, cfg, geom)


def resolve_scene(
    spec: str, cfg: ScenariosConfig | None = None, geom: VehicleGeometry | None = None
) -> Scene:
    """A Scene from a file (scene JSON, TPCAP case CSV, CommonRoad XML), a grid cell index
    0-35, or ``robust:N`` (0-251); grid scenes are built for the car ``geom``."""
    cfg = cfg if cfg is not None else load_scenarios_config()
    text = spec.strip()
    if text.isdigit():
        return grid_scene(int(text), cfg, geom)
    if text.lower().startswith("robust:") and text[7:].isdigit():
        return robust_scene(int(text[7:]), cfg, geom)
    path = Path(text)
    suffix = path.suffix.lower()
    if suffix in (".csv", ".xml"):
        raise PlanningError(
            f"--scene {spec!r}: benchmark files are read by parknss.sim.scene_formats"
        )
    if suffix == ".json" or path.exists():
        return Scene.load(path, cfg.obstacles)
    raise PlanningError(
        f"--scene {spec!r}: not a scene file (.json, TPCAP .csv, CommonRoad .xml), "
        "a cell 0-35 or robust:N"
    )


def run_cells(
    fn: str,
    grid: str,
    cells: list[int],
    kwargs: dict,
    *,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    cache_dir: str | Path | None = None,
    progress: bool = True,
    desc: str = "cells",
    store=None,
    tally=None,
) -> list:
    """Each cell of a grid as one job of the one executor (:func:`parknss.executor.run_jobs`,
    local pool or Ray): ``fn`` ("module:function") is called as ``fn(grid=, index=,
    **kwargs)`` with grid "252" or "36" (the core's cells are 36-grid cells) and JSON
    ``kwargs``; the results in the order of ``cells``. ``store``/``tally``: the result
    store each finished cell is kept in as it finishes, and where the results came from
    (:func:`parknss.executor.run_jobs`)."""
    from parknss.executor import Job, run_jobs

    kind = "252" if grid == "252" else "36"
    jobs = [Job(fn, {"grid": kind, "index": i, **kwargs}, name=f"cell {i}") for i in cells]
    return run_jobs(
        jobs,
        executor=executor,
        workers=workers,
        cache_dir=cache_dir,
        address=address,
        progress=progress,
        desc=desc,
        store=store,
        tally=tally,
    )
