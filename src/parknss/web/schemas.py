"""Request and response models of the simulator API (JSON). Units are in the field names
or descriptions: lengths m, angles rad unless named _deg, speeds m/s, times s."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, FiniteFloat, model_validator

Pose = tuple[FiniteFloat, FiniteFloat, FiniteFloat]
"""A rear-axle pose (x m, y m, heading rad, counter-clockwise from +x)."""

Grid = Literal["36", "252"]


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SceneRequest(_Request):
    """Which scene: a grid cell (``grid`` + ``index``) or a scene JSON, optionally with an
    edited start pose."""

    grid: Grid = Field("36", description="36: scenario grid; 252: robustness grid")
    index: int | None = Field(None, description="cell index in the grid (0-35 or 0-251)")
    scene: dict[str, Any] | None = Field(None, description="a scene in the parknss.scene format")
    start: Pose | None = Field(None, description="replaces the scene's start pose")

    @model_validator(mode="after")
    def _one_source(self) -> SceneRequest:
        if (self.index is None) == (self.scene is None):
            raise ValueError("give exactly one of 'index' (a grid cell) or 'scene' (scene JSON)")
        return self


class ImportRequest(_Request):
    """A benchmark scene file's text: a TPCAP case (.csv) or a CommonRoad scenario (.xml)."""

    filename: str = Field(..., min_length=5, max_length=200, description="e.g. Case13.csv")
    text: str = Field(..., max_length=5_000_000, description="the file's content")


class ImportResponse(BaseModel):
    """The imported scene (parknss.scene JSON) and what loading normalised."""

    scene: dict[str, Any]
    notes: list[str]


class SimulateRequest(SceneRequest):
    """A scene, the plant that executes its plan, and an optional plant noise seed."""

    plant: str = Field("kinematic", description="kinematic, reference or chain")
    seed: int | None = Field(None, description="reference-plant sensor-noise seed")


class FidelityRequest(SceneRequest):
    """A scene whose plan is driven under the learned chain and under the truth."""

    seed: int | None = Field(
        None, description="plant noise seed of both runs (None: the cell's parknss fidelity seed)"
    )


class ErrorResponse(BaseModel):
    """Every error: HTTP status and one line saying what is wrong."""

    error: str
    status: int


class VehicleInfo(BaseModel):
    """The car body drawn in the page (pose reference: rear-axle centre)."""

    length_m: float
    width_m: float
    rear_overhang_m: float
    wheelbase_m: float
    track_m: float
    steer_ratio: float = Field(description="steering-wheel to road-wheel angle ratio")


class PlantInfo(BaseModel):
    """Whether a plant can be built on this server, and its colour in the page."""

    kind: str
    available: bool
    reason: str = ""
    colour: str


class Health(BaseModel):
    """Server status: version, plants, vehicle, grid sizes, colours."""

    status: Literal["ok"] = "ok"
    version: str
    plants: list[PlantInfo]
    vehicle: VehicleInfo
    grids: dict[str, int]
    planned_colour: str
    accel_smoothing_s: float = Field(description="window of the page's smoothed ax/ay, s")
    plan_budget_s: float = Field(description="wall-clock budget of a plan request, s")
    simulate_budget_s: float = Field(description="wall-clock budget of a simulate request, s")
    view_zoom_above_m: float = Field(
        description="maps larger than this (m) are shown zoomed to start and goal"
    )
    view_zoom_pad_m: float = Field(description="...with this border, m")


class CellInfo(BaseModel):
    """One cell of a grid."""

    grid: Grid
    index: int
    cell: int = Field(description="the 36-grid cell it perturbs (= index on grid 36)")
    name: str
    bay: str
    approach: str
    tier: int
    barrier: bool
    perturbation: str
    slot_size_m: float | None


class CellList(BaseModel):
    grid: Grid
    cells: list[CellInfo]


class SceneResponse(BaseModel):
    """A scene in the parknss.scene JSON format (what POST bodies accept as ``scene``)."""

    grid: Grid
    index: int
    scene: dict[str, Any]


class PathSegment(BaseModel):
    """One gear segment of a path: +1 drive / -1 reverse, poses resampled for drawing."""

    direction: int
    poses: list[Pose]


class PlanResponse(BaseModel):
    """The plan of a scene, or why there is none."""

    scene_key: str = Field(description="digest of the planned scene (the plan cache key)")
    name: str
    plannable: bool
    reason: str = Field(description="'ok' or why no plan was found")
    refined: bool = Field(description="the optimisation refinement replaced the coarse path")
    cached: bool = Field(description="the plan came from the server's plan cache")
    plan_s: float = Field(description="planning wall time, s")
    length_m: float | None
    cusps: int | None
    min_clearance_cm: float | None = Field(description="exact dense clearance of the plan, cm")
    start: Pose
    goal: Pose
    path: list[PathSegment] = Field(description="the path the tracker follows")
    coarse: list[PathSegment] = Field(description="the Hybrid A* / Reeds-Shepp path")
    cusp_poses: list[Pose]
    footprints: list[list[tuple[float, float]]] = Field(
        description="car outlines along the path (m), every footprint_step_m and at cusps"
    )


class RunOutcome(BaseModel):
    """How a closed-loop run ended (parknss.sim.closed_loop.Outcome)."""

    plant: str
    completed: bool
    reason: str = Field(description="completed, collision, livelock, timeout or not plannable")
    goal_error_cm: float | None
    heading_error_deg: float | None
    clearance_cm: float | None = Field(description="driven exact clearance, cm")
    duration_s: float = Field(description="simulated time, s")
    wall_s: float = Field(description="wall-clock time of the run, s")
    realtime_factor: float | None
    driven_length_m: float
    gear_changes: int
    steps: int = Field(description="10 ms steps simulated")
    seed: int | None


class Series(BaseModel):
    """Time series of one run, decimated from 100 Hz to ``rate_hz`` (last sample kept)."""

    rate_hz: float
    stride: int = Field(description="every stride-th 10 ms sample is sent")
    t: list[float | None] = Field(description="time, s")
    x: list[float | None] = Field(description="rear-axle x, m")
    y: list[float | None] = Field(description="rear-axle y, m")
    heading: list[float | None] = Field(description="heading, rad")
    vx: list[float | None] = Field(description="longitudinal velocity, m/s (signed)")
    yaw_rate: list[float | None] = Field(description="yaw rate, rad/s")
    ax: list[float | None] = Field(description="longitudinal acceleration, m/s²")
    ay: list[float | None] = Field(description="lateral acceleration, m/s²")
    gear: list[float | None] = Field(description="engaged gear -1 R, 0 P/N, +1 D")
    steer: list[float | None] = Field(description="steering-wheel angle, deg")
    torque: list[float | None] = Field(description="motor torque, N·m")
    brake_pressure: list[float | None] = Field(description="brake pressure, bar")
    gear_cmd: list[float | None] = Field(description="gear command")
    torque_cmd: list[float | None] = Field(description="torque command, N·m")
    decel_cmd: list[float | None] = Field(description="deceleration command, m/s² (<= 0)")
    steer_cmd: list[float | None] = Field(description="steering-wheel command, deg")
    speed_req: list[float | None] = Field(description="tracker speed request, m/s (signed)")


class SimulateResponse(BaseModel):
    """A plan and its execution through one plant."""

    plan: PlanResponse
    outcome: RunOutcome
    series: Series | None = Field(description="None when the scene was not plannable")


class Run(BaseModel):
    """One plant's execution of the plan."""

    outcome: RunOutcome
    series: Series | None


class TargetCheck(BaseModel):
    """One fidelity target on this cell (parknss.sim.fidelity.TargetLine)."""

    label: str
    measured: float | None
    limit: float
    passed: bool


class FidelityResponse(BaseModel):
    """The plan driven under the chain and the truth (same plan, same noise seed) and the
    chain's closed-loop fidelity (parknss fidelity's numbers for this one cell)."""

    plan: PlanResponse
    seed: int = Field(description="plant noise seed of both runs")
    chain: Run
    truth: Run = Field(description="the reference vehicle's run")
    fidelity: dict[str, Any] | None = Field(
        description="parknss.sim.fidelity.CellFidelity fields (diff = chain - truth; cm, deg, "
        "s); None when the scene was not plannable"
    )
    targets: list[TargetCheck] = Field(description="the fidelity targets on this cell")
