"""Hybrid A* (Dolgov et al. 2010) for parking, bidirectional, with Reeds-Shepp connections.

The search runs on continuous poses (x, y, heading) binned into cells; each cell keeps
its cheapest pose. Cells are ``xy_resolution_m`` x ``heading_resolution_deg`` in the
open and the finer ``fine_*`` resolution where the car is within
``fine_below_clearance_m`` of an obstacle, so a tight slot gets enough distinct states
for a multi-move manoeuvre without flooding the open lane. Successors are arcs of the
kinematic bicycle at ``n_steer`` curvatures between the right and left lock (minimum
turning radius from the steering lock and rack ratio,
:func:`parknss.vehicle.min_turning_radius`, about 4.6 m), forwards and in reverse. An arc
that would hit an obstacle is cut back to its last safe pose (to the dense spacing), so
the car can use all of a tight slot.

Costs: length, times ``reverse_cost`` in reverse, plus ``gear_switch_cost`` per cusp,
``steer_cost`` per metre at full lock and ``steer_change_cost`` per full lock of steering
change. The heuristic is the maximum of a holonomic distance with obstacles (Dijkstra on
a grid, for the rear axle, which must stay W/2 + margin from every obstacle) and the
Reeds-Shepp length without obstacles (computed lazily, when a node is first popped).

Two trees grow at once, one from the start and one from the goal (driving the manoeuvre
backwards in time); a node of either tree is connected to the other tree's root, and
every ``connect_every`` expansions to its ``connect_neighbours`` nearest nodes in the
other tree, by Reeds-Shepp candidates (shortest first) that pass the collision check.
Leaving a tight slot backwards is the same geometric problem as entering it, and the
goal tree solves it while the start tree covers the lane; a single tree (``search``:
``from_start`` / ``from_goal``) is available for comparison.

Collisions in the search use :class:`~parknss.sim.planning.collision_field.FieldChecker`
(a distance field with exact vertex tests, near-exact, certified between samples); a
plan is accepted only after the exact dense check of :mod:`parknss.sim.geometry` (<= 2 cm
/ 0.5° between poses, exact polygon distances) clears the safety margin. Degenerate
requests return ``found=False`` with a reason, never an exception.

Budgets: the search stops after ``max_expansions`` node expansions of both trees (a
count, so a scene plans the same on any machine and under any load: the grids' studies
are reproducible); ``time_budget_s`` is a wall-clock guard over setup and search for a
scene whose expansions are pathologically slow. A plan stopped by the guard ("time
budget exhausted") depends on the machine; one stopped by the count ("expansion budget
exhausted") does not.
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from parknss.config import StrictModel, load_config
from parknss.sim import geometry
from parknss.sim.geometry import DenseCheckConfig
from parknss.sim.planning import reeds_shepp as rs
from parknss.sim.planning.collision_field import FieldChecker
from parknss.sim.planning.escape import EscapeConfig
from parknss.sim.planning.frame import CanonicalScene
from parknss.sim.planning.holonomic import HolonomicGrid, HolonomicHeuristic
from parknss.sim.planning.refine_config import RefineConfig
from parknss.sim.planning.region import (
    GridMemoryError,
    check_grid_memory,
    near_cropped_edge,
    search_region,
)
from parknss.sim.trajectory import Segment, Trajectory
from parknss.vehicle import VehicleGeometry, min_turning_radius, steer_for_curvature

REASONS = (
    "ok",
    "goal off the map",
    "start off the map",
    "goal in collision",
    "start in collision",
    "goal unreachable",
    "expansion budget exhausted",
    "time budget exhausted",
    "search space exhausted",
)


class PlanningConfig(StrictModel):
    """Hybrid A* settings (configs/planning.yaml). Lengths in m, angles in deg."""

    safety_margin_m: float = Field(0.10, ge=0.0, description="min exact clearance, m")
    xy_resolution_m: float = Field(0.3, gt=0.0)
    heading_resolution_deg: float = Field(7.5, gt=0.0)
    fine_xy_resolution_m: float = Field(0.05, gt=0.0)
    fine_heading_resolution_deg: float = Field(1.0, gt=0.0)
    fine_below_clearance_m: float = Field(0.3, ge=0.0, description="fine cells below this")
    n_steer: int = Field(3, ge=2, description="curvatures from right to left lock")
    primitive_length_m: float = Field(1.2, gt=0.0, description="arc length of a successor")
    min_primitive_m: float = Field(0.1, gt=0.0, description="shortest cut-back successor")
    sample_step_m: float = Field(0.1, gt=0.0, description="pose spacing of the search check")
    reverse_cost: float = Field(1.2, ge=1.0, description="cost factor per metre in reverse")
    gear_switch_cost: float = Field(1.0, ge=0.0, description="cost per cusp, m")
    steer_cost: float = Field(0.1, ge=0.0, description="cost per metre at full lock")
    steer_change_cost: float = Field(0.2, ge=0.0, description="cost per lock-to-centre change")
    heuristic_weight: float = Field(2.0, ge=1.0)
    retry_weights: tuple[Annotated[float, Field(ge=1.0)], ...] = Field(
        (3.0,),
        description="a search that exhausts max_expansions runs again with each of these "
        "heuristic weights in turn (each with max_expansions more), within time_budget_s",
    )
    holonomic_resolution_m: float = Field(0.25, gt=0.0)
    field_resolution_m: float = Field(0.05, gt=0.0, description="distance-field grid, m")
    field_tolerance_m: float = Field(0.01, ge=0.0, description="interpolation allowance, m")
    search: Literal["bidirectional", "from_start", "from_goal"] = "bidirectional"
    analytic_every: int = Field(4, ge=1, description="connect to the other root every n")
    analytic_always_within_m: float = Field(5.0, ge=0.0, description="...and always this close")
    connect_every: int = Field(3, ge=1, description="connect to nearest other-tree nodes every n")
    connect_neighbours: int = Field(2, ge=0, description="nearest other-tree nodes tried")
    connect_max_m: float = Field(15.0, gt=0.0, description="skip longer connections, m")
    connect_min_free_m: float = Field(
        0.5, ge=0.0, description="connect only from nodes that can drive this far, m"
    )
    rs_candidates: int = Field(6, ge=1, description="Reeds-Shepp words checked per connection")
    start_lead_ins_m: tuple[float, ...] = Field(
        (4.0, 8.0, 12.0), description="straight lead-ins from the start tried before RS, m"
    )
    max_expansions: int = Field(
        1200, ge=1, description="search budget: node expansions of both trees together"
    )
    time_budget_s: float = Field(
        60.0, gt=0.0, description="wall-clock guard over setup and search, s"
    )
    canonical_frame: bool = Field(
        True, description="search in the goal's frame (frame.py): plans move with the scene"
    )
    canonical_snap: float = Field(
        1e-6, ge=0.0,
        description="the refinement's canonical input (scene, coarse path) rounded to this, "
        "m and rad: a moved scene refines the same (0: no rounding)",
    )
    cell_offset: float = Field(
        0.5, ge=0.0, lt=1.0,
        description="cell and heading-bin anchor: the frame's origin sits this fraction "
        "into a cell (0.5: at the centre of its cell and bin)",
    )
    tie_quantum: float = Field(
        1e-6, ge=0.0,
        description="costs, lengths and distances the search orders by are rounded to this "
        "(m) and equal ones taken in insertion order: a moved scene breaks ties the same "
        "(0: raw floats)",
    )
    region_margin_m: float = Field(
        20.0, gt=0.0, description="search region: start/goal box grown by this (doubles), m"
    )
    max_grid_memory_mb: float = Field(
        800.0, gt=0.0, description="refuse a search region whose grids need more, MiB"
    )
    dense: DenseCheckConfig = DenseCheckConfig()
    refine: RefineConfig = RefineConfig()
    escape: EscapeConfig = EscapeConfig()


def load_planning_config(path: str | Path | None = None) -> PlanningConfig:
    """Read ``path`` (default: the shipped configs/planning.yaml)."""
    return load_config(PlanningConfig, path, default="planning.yaml")


@dataclass
class PlanStats:
    """Counters and timings of one plan (s)."""

    expansions: int = 0
    attempts: int = 0  # searches run: 1 + the retries with a greedier weight
    nodes: int = 0
    connections_tried: int = 0
    rs_checked: int = 0
    rejected_by_exact_check: int = 0
    setup_time_s: float = 0.0
    search_time_s: float = 0.0
    verify_time_s: float = 0.0
    time_s: float = 0.0


@dataclass
class PlanResult:
    """Outcome of a plan: ``found`` with a trajectory, or a reason why not."""

    found: bool
    reason: str
    trajectory: Trajectory | None = None
    stats: PlanStats = field(default_factory=PlanStats)
    detail: str = ""
    min_clearance_m: float = math.nan

    def to_json(self) -> dict:
        """JSON-serialisable summary (no poses)."""
        t = self.trajectory
        return {
            "found": self.found,
            "reason": self.reason,
            "detail": self.detail,
            "length_m": None if t is None else round(t.length, 4),
            "cusps": None if t is None else t.cusps,
            "min_clearance_m": None if math.isnan(self.min_clearance_m) else self.min_clearance_m,
            "stats": dict(self.stats.__dict__),
        }


# ---------------------------------------------------------------------------------------
# Search trees


def tie_key(value: float, quantum: float) -> float:
    """``value`` (a cost or length, m) in units of ``quantum`` (0: as is), for ordering.

    Values within float noise of each other (a moved scene's last bits) get the same key,
    and the search breaks the tie by insertion order, the same in every frame; only a
    value within noise of a rounding boundary can still differ (odds ~1e-7 per compare
    at 1e-6 m)."""
    return float(round(value / quantum)) if quantum > 0 else value


@dataclass
class _Node:
    pose: tuple[float, float, float]
    g: float
    parent: int
    length: float  # arc length driven from the parent, m
    direction: int  # search direction of the arriving move (0 at the root)
    kappa: float
    h: float
    key: tuple = ()
    clr: float = 0.0  # estimated clearance of the pose, m (capped)
    rs_done: bool = False


class _Tree:
    """One search tree. ``backward``: grown from the goal, search direction = -real."""

    def __init__(
        self, root: _Node, target, holo: HolonomicHeuristic, backward: bool, quantum: float = 0.0
    ) -> None:
        self.backward = backward
        self.quantum = quantum
        self.target = target
        self.holo = holo
        self.nodes = [root]
        self.best: dict[tuple, int] = {root.key: 0}
        self.closed: set[tuple] = set()
        self.heap: list[tuple[float, int]] = [(0.0, 0)]  # (tie_key(f), node id)
        self.poses = np.zeros((1024, 3))
        self.poses[0] = root.pose
        self.expansions = 0

    def add(self, node: _Node, f: float) -> None:
        self.nodes.append(node)
        nid = len(self.nodes) - 1
        if nid >= len(self.poses):
            self.poses = np.concatenate([self.poses, np.zeros_like(self.poses)])
        self.poses[nid] = node.pose
        self.best[node.key] = nid
        heapq.heappush(self.heap, (tie_key(f, self.quantum), nid))

    def nearest(self, pose, k: int, radius: float) -> list[int]:
        """Up to k node ids closest to ``pose`` (xy distance + radius x heading gap)."""
        n = len(self.nodes)
        p = self.poses[:n]
        dth = np.abs((p[:, 2] - pose[2] + np.pi) % (2 * np.pi) - np.pi)
        d = np.hypot(p[:, 0] - pose[0], p[:, 1] - pose[1]) + radius * dth
        if self.quantum > 0:  # equal distances in id order, whatever the last bits
            d = np.round(d / self.quantum)
        return [int(i) for i in np.argsort(d, kind="stable")[:k]]


# ---------------------------------------------------------------------------------------
# The planner


class HybridAStar:
    """A reusable planner for one vehicle and config: ``plan(scene)`` -> PlanResult."""

    def __init__(self, cfg: PlanningConfig | None = None, geom: VehicleGeometry | None = None):
        self.cfg = cfg or PlanningConfig()
        self.geom = geom or VehicleGeometry()
        self.radius = min_turning_radius(self.geom)
        self.kmax = 1.0 / self.radius
        c = self.cfg
        n = max(1, math.ceil(c.primitive_length_m / c.sample_step_m - 1e-9))
        s = np.linspace(0.0, c.primitive_length_m, n + 1)
        prims, meta = [], []
        for d in (1, -1):
            for k in np.linspace(-self.kmax, self.kmax, c.n_steer):
                prims.append(rs.arc_poses((0.0, 0.0, 0.0), float(k), d * s))
                meta.append((d, float(k)))
        self.prim_poses = np.stack(prims)  # (K, n+1, 3) in the frame of the start pose
        self.prim_meta = meta
        self._nth = max(1, round(360.0 / c.heading_resolution_deg))
        self._nth_fine = max(1, round(360.0 / c.fine_heading_resolution_deg))

    # -- helpers ------------------------------------------------------------------------

    def _key(self, pose, clearance: float) -> tuple:
        c = self.cfg
        x, y, th = pose
        fine = clearance < c.fine_below_clearance_m
        res = c.fine_xy_resolution_m if fine else c.xy_resolution_m
        nth = self._nth_fine if fine else self._nth
        o = c.cell_offset
        a = (th % (2 * math.pi)) / (2 * math.pi) * nth + o
        return (fine, math.floor(x / res + o), math.floor(y / res + o), math.floor(a) % nth)

    def _move_cost(
        self,
        length: float,
        d_search: int,
        kappa: float,
        prev_dir: int,
        prev_kappa: float,
        backward: bool,
    ) -> float:
        c = self.cfg
        real = -d_search if backward else d_search
        cost = length * (c.reverse_cost if real < 0 else 1.0)
        cost += c.steer_cost * abs(kappa) / self.kmax * length
        if prev_dir != 0:
            cost += c.steer_change_cost * abs(kappa - prev_kappa) / self.kmax
            if prev_dir != d_search:
                cost += c.gear_switch_cost
        return cost

    # -- main ---------------------------------------------------------------------------

    def plan(self, scene) -> PlanResult:
        """Plan from ``scene.start`` to ``scene.goal`` (rear-axle poses) around obstacles."""
        t0 = time.perf_counter()
        stats = PlanStats()
        result = self._precheck(scene, scene.obstacle_arrays())
        if result is None:  # search in the canonical frame (frame.py), answer in the world's
            self._world = scene
            canon = CanonicalScene.of(scene, self.cfg.canonical_frame)
            self._canon = canon
            for w in (self.cfg.heuristic_weight, *self.cfg.retry_weights):
                self._w = w
                stats.attempts += 1
                result = self._plan(canon, stats, t0)
                if result.reason != "expansion budget exhausted":
                    break
            if stats.attempts > 1:
                result.detail += f" (heuristic weight {self._w:g}, search {stats.attempts})"
            if result.trajectory is not None:
                result.trajectory = canon.frame.to_world_trajectory(result.trajectory)
        result.stats = stats
        stats.time_s = time.perf_counter() - t0
        stats.search_time_s = max(0.0, stats.time_s - stats.setup_time_s - stats.verify_time_s)
        return result

    def _precheck(self, scene, obstacles) -> PlanResult | None:
        g, m = self.geom, self.cfg.safety_margin_m
        for name, pose in (("goal", scene.goal), ("start", scene.start)):
            if not geometry.inside_map([pose], g, scene)[0]:
                return PlanResult(False, f"{name} off the map", detail=f"{name} {pose}")
        for name, pose in (("goal", scene.goal), ("start", scene.start)):
            if obstacles:
                clr = float(geometry.clearance([pose], g, obstacles)[0])
                if clr < m:
                    return PlanResult(
                        False,
                        f"{name} in collision",
                        detail=f"{name} clearance {clr:.3f} m < margin {m:.3f} m",
                    )
        return None

    def _plan(self, scene, stats: PlanStats, t0: float) -> PlanResult:
        """Search the region around start and goal (:mod:`.region`), growing it (the margin
        doubles) while a failed search reached one of its cropped edges."""
        c = self.cfg
        obstacles = scene.obstacle_arrays()
        bounds = tuple(float(v) for v in scene.bounds)
        # obstacles farther than this from the region cannot change any grid value
        g = self.geom
        near = 3.0 * (math.hypot(g.length, g.width) + c.primitive_length_m) + 2.0
        margin, since = c.region_margin_m, t0
        result = None
        while True:
            region = search_region(scene, margin)
            try:
                check_grid_memory(
                    region, c.field_resolution_m, c.holonomic_resolution_m, c.max_grid_memory_mb
                )
            except GridMemoryError:
                if result is None:
                    raise
                result.detail += "; a larger search region would pass max_grid_memory_mb"
                return result
            local = [
                o
                for o in obstacles
                if o[:, 0].min() <= region[2] + near
                and o[:, 0].max() >= region[0] - near
                and o[:, 1].min() <= region[3] + near
                and o[:, 1].max() >= region[1] - near
            ]
            self._trees = []
            result = self._plan_region(scene, local, region, stats, t0, since)
            if result.found or region == bounds or result.reason == "time budget exhausted":
                return result
            xy = np.concatenate([t.poses[: len(t.nodes), :2] for t in self._trees] or [[]])
            reach = 2.0 * math.hypot(g.length, g.width) + c.primitive_length_m
            blocked = result.reason in ("goal unreachable", "search space exhausted")
            if not blocked and not near_cropped_edge(xy.reshape(-1, 2), region, bounds, reach):
                return result
            margin, since = 2.0 * margin, time.perf_counter()

    def _plan_region(self, scene, obstacles, region, stats, t0: float, since: float):
        """One search over ``region`` with ``obstacles`` (those near it); ``since``: when
        this attempt's setup began (s, perf_counter)."""
        c = self.cfg
        deadline = t0 + c.time_budget_s
        self._exp0 = stats.expansions
        start = tuple(float(v) for v in scene.start)
        goal = tuple(float(v) for v in scene.goal)
        checker = FieldChecker(
            obstacles,
            region,
            self.geom,
            c.safety_margin_m,
            resolution=c.field_resolution_m,
            tolerance=c.field_tolerance_m,
            max_step=c.dense.max_step_m,
            max_dheading=math.radians(c.dense.max_dheading_deg),
            inside_map=scene.inside_map,
        )
        if time.perf_counter() > deadline:
            return self._out_of_time(stats, t0, "building the collision field")
        self._checker = checker
        self._lips = np.array([checker.lipschitz(k) for _, k in self.prim_meta])
        self._lip_max = float(self._lips.max())
        clr = checker.clearance(np.array([start, goal]))
        # the direct connection (with lead-ins) first: easy scenes end here
        direct = _Tree(_Node(start, 0.0, -1, 0.0, 0, 0.0, 0.0), goal, None, False)
        stats.setup_time_s += time.perf_counter() - since
        done = self._connect(direct, 0, None, [0], stats)
        if done is not None:
            return done
        t1 = time.perf_counter()
        need = 0.5 * self.geom.width + c.safety_margin_m
        sweep = self._lip_max * c.primitive_length_m
        cap = max(need, checker.reach + sweep + checker.need) + 1.0
        grid = HolonomicGrid(
            obstacles, region, need, c.holonomic_resolution_m, cap, scene.map_edge_distance
        )
        checker.set_broad_phase(grid.dist_obstacle, grid.x0, grid.y0, grid.res)
        if time.perf_counter() > deadline:
            return self._out_of_time(stats, t0, "building the heuristic grid")
        holo_goal = grid.heuristic(goal[:2])
        if not math.isfinite(holo_goal(*start[:2])):
            return PlanResult(
                False,
                "goal unreachable",
                detail="no corridor wide enough for the car joins start and goal",
            )
        trees = []
        if c.search != "from_goal":
            root = self._root(start, clr[0], holo_goal)
            trees.append(_Tree(root, goal, holo_goal, False, c.tie_quantum))
        if c.search != "from_start":
            holo_start = grid.heuristic(start[:2])
            root = self._root(goal, clr[1], holo_start)
            trees.append(_Tree(root, start, holo_start, True, c.tie_quantum))
        stats.setup_time_s += time.perf_counter() - t1
        self._trees = trees
        return self._search(trees, stats, deadline)

    def _out_of_time(self, stats: PlanStats, t0: float, where: str) -> PlanResult:
        """The budget ran out while preparing the search (the budget covers setup too)."""
        stats.setup_time_s = time.perf_counter() - t0
        return PlanResult(
            False,
            "time budget exhausted",
            detail=f"{where}: {self.cfg.time_budget_s} s used before the search began",
        )

    def _root(self, pose, clr: float, holo: HolonomicHeuristic) -> _Node:
        return _Node(pose, 0.0, -1, 0.0, 0, 0.0, holo(*pose[:2]), self._key(pose, clr), clr)

    def _search(self, trees: list[_Tree], stats: PlanStats, deadline: float) -> PlanResult:
        c = self.cfg
        while any(t.heap for t in trees):
            for i, tree in enumerate(trees):
                if stats.expansions - self._exp0 >= c.max_expansions:
                    return PlanResult(
                        False,
                        "expansion budget exhausted",
                        detail=f"{stats.expansions} expansions without a connection",
                    )
                if time.perf_counter() > deadline:
                    return PlanResult(
                        False,
                        "time budget exhausted",
                        detail=f"{stats.expansions} expansions in {c.time_budget_s} s",
                    )
                nid = self._pop(tree)
                if nid is None:
                    continue
                other = trees[1 - i] if len(trees) == 2 else None
                done = self._expand(tree, nid, other, stats)
                if done is not None:
                    return done
        return PlanResult(
            False,
            "search space exhausted",
            detail=f"{stats.expansions} expansions, no Reeds-Shepp connection",
        )

    def _pop(self, tree: _Tree) -> int | None:
        """Pop the best open node (lazy Reeds-Shepp heuristic); None when empty."""
        w = self._w
        while tree.heap:
            _f, nid = heapq.heappop(tree.heap)
            node = tree.nodes[nid]
            key = node.key
            if key in tree.closed or tree.best.get(key) != nid:
                continue
            if not node.rs_done:
                node.rs_done = True
                # a CSC path no longer than the holonomic bound settles it cheaply
                h_rs = rs.csc_length(node.pose, tree.target, self.radius)
                if h_rs > node.h:
                    h_rs = rs.shortest_length(node.pose, tree.target, self.radius)
                if h_rs > node.h + 1e-9:
                    node.h = h_rs
                    nf = node.g + w * node.h
                    nk = tie_key(nf, tree.quantum)
                    if tree.heap and nk > tree.heap[0][0]:
                        heapq.heappush(tree.heap, (nk, nid))
                        continue
            tree.closed.add(key)
            return nid
        return None

    def _expand(self, tree: _Tree, nid: int, other: _Tree | None, stats: PlanStats):
        c = self.cfg
        node = tree.nodes[nid]
        tree.expansions += 1
        stats.expansions += 1
        # successors
        x0, y0, th0 = node.pose
        cs, sn = math.cos(th0), math.sin(th0)
        P = self.prim_poses
        world = np.empty_like(P)
        world[..., 0] = x0 + cs * P[..., 0] - sn * P[..., 1]
        world[..., 1] = y0 + sn * P[..., 0] + cs * P[..., 1]
        world[..., 2] = th0 + P[..., 2]
        ch = self._checker
        cx, cy = x0 + cs * ch.centre_offset, y0 + sn * ch.centre_offset
        sweep = self._lip_max * c.primitive_length_m
        if tree.holo.obstacle_distance(cx, cy) > ch.reach + sweep + ch.need:
            reach = np.full(len(P), float(P.shape[1] - 1))
        else:
            verts = ch.vertices_near(cx, cy, ch.reach + sweep + ch.need)
            reach = ch.reach_along(list(world), self._lips, verts)
        # connections: the other root, and nearest nodes of the other tree
        targets = []
        if node.h <= c.analytic_always_within_m or (tree.expansions - 1) % c.analytic_every == 0:
            targets.append(0)
        if other is not None and c.connect_neighbours and tree.expansions % c.connect_every == 0:
            for m in other.nearest(node.pose, c.connect_neighbours + 1, self.radius):
                if m not in targets:
                    targets.append(m)
        if targets and float(reach.max()) * c.sample_step_m >= c.connect_min_free_m:
            done = self._connect(tree, nid, other, targets, stats)
            if done is not None:
                return done
        w, q = self._w, c.tie_quantum
        cands = []
        for k, r in enumerate(reach):
            length = float(r) * c.sample_step_m
            if length < c.min_primitive_m - 1e-9:
                continue
            d, kap = self.prim_meta[k]
            j = round(r)
            if abs(r - j) < 1e-9:
                pose = (float(world[k, j, 0]), float(world[k, j, 1]), float(world[k, j, 2]))
            else:
                pose = tuple(float(v) for v in rs.arc_poses(node.pose, kap, [d * length])[0])
            cands.append((pose, length, d, kap))
        if not cands:
            return None
        clr = ch.clearance(np.array([p for p, *_ in cands]))
        for (pose, length, d, kap), cl in zip(cands, clr, strict=True):
            key = self._key(pose, cl)
            if key in tree.closed:
                continue
            h = tree.holo(pose[0], pose[1])
            if not math.isfinite(h):
                continue
            g = node.g + self._move_cost(length, d, kap, node.direction, node.kappa, tree.backward)
            old = tree.best.get(key)
            if old is not None and tie_key(tree.nodes[old].g, q) <= tie_key(g, q):
                continue
            tree.add(_Node(pose, g, nid, length, d, kap, h, key, float(cl)), g + w * h)
            stats.nodes += 1
        return None

    # -- connections and path assembly ---------------------------------------------------

    def _connect(self, tree: _Tree, nid: int, other: _Tree | None, targets, stats: PlanStats):
        """Try Reeds-Shepp paths from node ``nid`` of ``tree`` to the other tree's nodes.

        ``targets`` are node ids in ``other`` (0 = its root; with no other tree, 0 means
        ``tree.target``). Returns a PlanResult when a connection passes every check.
        """
        c = self.cfg
        node = tree.nodes[nid]
        cands = []
        for m in targets:
            mpose = other.nodes[m].pose if other is not None else tree.target
            a, b = (mpose, node.pose) if tree.backward else (node.pose, mpose)
            a_is_start = (m if tree.backward else nid) == 0
            stats.connections_tried += 1
            for path in rs.all_paths(a, b, self.radius)[: c.rs_candidates]:
                if path.length <= c.connect_max_m or m == 0:
                    cands.append((path.length, m, path))
            if a_is_start:  # "drive on, then manoeuvre": a straight lead-in from the start
                for d in c.start_lead_ins_m:
                    lead = (a[0] + d * math.cos(a[2]), a[1] + d * math.sin(a[2]), a[2])
                    for p in rs.all_paths(lead, b, self.radius)[: c.rs_candidates]:
                        path = rs.RSPath(
                            a, b, self.radius, "S" + p.word, (d / self.radius, *p.params)
                        )
                        cands.append((path.length, m, path))
        if not cands:
            return None
        cands.sort(key=lambda t: tie_key(t[0], c.tie_quantum))  # stable: ties in order
        stats.rs_checked += len(cands)
        ch = self._checker
        # cheap reject on a coarse sampling: corners or obstacle vertices within the margin
        coarse = [a[:, :3] for a in rs.sample_paths([p for *_, p in cands], 4 * c.sample_step_m)]
        flat_ok = ch.corners_free(np.concatenate(coarse))
        splits = np.cumsum([len(a) for a in coarse])[:-1]
        alive = [i for i, ok in enumerate(np.split(flat_ok, splits)) if ok.all()]
        if not alive:
            return None
        samples = [a[:, :3] for a in rs.sample_paths([cands[i][2] for i in alive], c.sample_step_m)]
        lip = ch.lipschitz(self.kmax)
        reach = ch.reach_along(samples, np.full(len(alive), lip))
        for i, smp, r in zip(alive, samples, reach, strict=True):
            if r < len(smp) - 1 - 1e-9:
                continue
            _, m, path = cands[i]
            tv = time.perf_counter()
            fwd_tree = tree if not tree.backward else other
            bwd_tree = tree if tree.backward else other
            fwd_id = nid if not tree.backward else (m if other is not None else None)
            bwd_id = nid if tree.backward else (m if other is not None else None)
            traj = self._assemble(fwd_tree, fwd_id, path, bwd_tree, bwd_id)
            ok, clr = self._verify(traj)
            stats.verify_time_s += time.perf_counter() - tv
            if ok:
                return PlanResult(True, "ok", traj, min_clearance_m=clr)
            stats.rejected_by_exact_check += 1
        return None

    def _chain(self, tree: _Tree | None, nid: int | None) -> list[tuple[np.ndarray, int, float]]:
        """Real-time pieces (poses, real direction, curvature) along a tree's chain.

        For the start tree: root -> nid in driving order. For the goal tree: nid ->
        root (the goal) in driving order.
        """
        if tree is None or nid is None:
            return []
        chain = []
        while nid is not None and nid > 0:
            chain.append(nid)
            nid = tree.nodes[nid].parent
        pieces = []
        for i in reversed(chain):
            n = tree.nodes[i]
            m = max(1, math.ceil(n.length / self.cfg.sample_step_m - 1e-9))
            s = n.direction * np.linspace(0.0, n.length, m + 1)
            poses = rs.arc_poses(tree.nodes[n.parent].pose, n.kappa, s)
            poses[-1] = n.pose
            pieces.append((poses, n.direction, n.kappa))
        if tree.backward:
            pieces = [(p[::-1].copy(), -d, k) for p, d, k in reversed(pieces)]
        return pieces

    def _assemble(self, fwd: _Tree | None, fid, path: rs.RSPath, bwd: _Tree | None, bid):
        pieces = self._chain(fwd, fid)
        for seg in path.segments:
            n = max(1, math.ceil(abs(seg.length) / self.cfg.sample_step_m - 1e-9))
            begin = pieces[-1][0][-1] if pieces else np.asarray(path.start, dtype=float)
            k = seg.curvature(self.radius)
            pieces.append(
                (rs.arc_poses(begin, k, np.linspace(0.0, seg.length, n + 1)), seg.direction, k)
            )
        if pieces:
            end = pieces[-1][0]
            end[-1, :2] = path.goal[:2]
        pieces += self._chain(bwd, bid)
        # one continuous heading along the whole path (the trees unwrap independently)
        prev = None
        for poses, _, _ in pieces:
            poses[:, 2] = np.unwrap(poses[:, 2])
            if prev is not None:
                poses[:, 2] += 2 * math.pi * round((prev - poses[0, 2]) / (2 * math.pi))
            prev = poses[-1, 2]
        segments: list[Segment] = []
        cur_p: list[np.ndarray] = []
        cur_k: list[np.ndarray] = []
        cur_dir = 0
        for poses, d, k in pieces:
            if len(poses) < 2:
                continue
            if d != cur_dir and cur_p:
                segments.append(self._segment(cur_p, cur_k, cur_dir))
                cur_p, cur_k = [], []
            body = poses if not cur_p else poses[1:]
            cur_p.append(body)
            cur_k.append(np.full(len(body), k))
            cur_dir = d
        if cur_p:
            segments.append(self._segment(cur_p, cur_k, cur_dir))
        info = {
            "planner": "hybrid_astar",
            "search": self.cfg.search,
            "turning_radius_m": self.radius,
        }
        return Trajectory(segments, source="hybrid_astar", info=info)

    def _segment(self, poses: list[np.ndarray], kappa: list[np.ndarray], d: int) -> Segment:
        p = np.concatenate(poses, axis=0)
        steer = np.asarray(steer_for_curvature(np.concatenate(kappa), self.geom), dtype=float)
        return Segment(p, int(d), steer=steer)

    def _verify(self, traj: Trajectory) -> tuple[bool, float]:
        """Exact dense check of a trajectory: (on the map and clearance >= margin, min m)."""
        world = self._canon.frame.to_world_trajectory(traj)
        return verify_trajectory(world, self._world, self.geom, self.cfg)


def verify_trajectory(traj: Trajectory, scene, geom: VehicleGeometry, cfg: PlanningConfig):
    """Exact dense check: (every pose on the map and clearance >= margin, min clearance m).

    Poses are densified to ``cfg.dense`` spacing per segment; clearance is exact polygon
    distance. A trajectory without segments is checked at the start pose.
    """
    obstacles = scene.obstacle_arrays()
    step, dh = cfg.dense.max_step_m, math.radians(cfg.dense.max_dheading_deg)
    parts = [geometry.densify(s.poses, step, dh) for s in traj.segments] or [
        np.asarray([scene.start], dtype=float)
    ]
    dense = np.concatenate(parts, axis=0)
    if not np.all(geometry.inside_map(dense, geom, scene)):
        return False, -1.0
    if not obstacles:
        return True, math.inf
    worst = float(geometry.clearance(dense, geom, obstacles, cutoff=1.0).min())
    return worst >= cfg.safety_margin_m - 1e-9, worst
