"""The FastAPI app of the interactive simulator: a JSON API and the static page.

Endpoints (docs/web.md has examples):

* ``GET /api/health``: version, plants (available or why not), vehicle, grid sizes.
* ``GET /api/cells?grid=36|252``: every cell of a grid.
* ``GET /api/scene?grid=36&index=26``: one grid scene as scene JSON.
* ``POST /api/plan``: plan a cell or a scene JSON (optionally with an edited start).
* ``POST /api/simulate``: plan (or reuse the plan) and execute it through one plant.
* ``POST /api/import``: a TPCAP case (.csv) or CommonRoad scenario (.xml) as scene JSON.

Every error is JSON ``{"error": "<one line>", "status": <code>}``: 400 malformed JSON,
422 invalid request (unknown plant, cell out of range, non-finite numbers, bad
polygons, start pose in collision), 503 plant unavailable or server busy, 504 over the
wall-clock budget. Unexpected failures are logged and answered 500 without a traceback.
"""

from __future__ import annotations

import logging
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

import parknss
from parknss.errors import ParknssError
from parknss.web.config import WebConfig, load_web_config
from parknss.web.errors import WebError
from parknss.web.jobs import ComputeRunner
from parknss.web.schemas import (
    CellList,
    ErrorResponse,
    Grid,
    Health,
    ImportRequest,
    ImportResponse,
    PlanResponse,
    SceneRequest,
    SceneResponse,
    SimulateRequest,
    SimulateResponse,
)
from parknss.web.service import SimulatorService

STATIC_DIR = Path(__file__).resolve().parent / "static"
log = logging.getLogger("parknss.web")

_ERRORS = {
    400: {"model": ErrorResponse},
    422: {"model": ErrorResponse},
    503: {"model": ErrorResponse},
    504: {"model": ErrorResponse},
}


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message, "status": status}, status_code=status)


def _validation_message(exc: RequestValidationError) -> tuple[int, str]:
    """(status, one line) for the first problem of a request that failed validation."""
    errs = exc.errors()
    if not errs:
        return 422, "invalid request"
    err = errs[0]
    if err.get("type") == "json_invalid":
        ctx = err.get("ctx", {}).get("error", "")
        return 400, "request body is not valid JSON" + (f" ({ctx})" if ctx else "")
    loc = ".".join(str(p) for p in err.get("loc", ()) if p not in ("body", "query"))
    msg = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
    more = f" (and {len(errs) - 1} more)" if len(errs) > 1 else ""
    return 422, (f"{loc}: {msg}" if loc else msg) + more


def _install_error_handlers(app: FastAPI) -> None:
    @app.exception_handler(WebError)
    async def _web_error(_req: Request, exc: WebError) -> JSONResponse:
        return _error(exc.status, str(exc))

    @app.exception_handler(ParknssError)
    async def _parknss_error(_req: Request, exc: ParknssError) -> JSONResponse:
        return _error(422, str(exc))

    @app.exception_handler(RequestValidationError)
    async def _invalid(_req: Request, exc: RequestValidationError) -> JSONResponse:
        return _error(*_validation_message(exc))

    @app.exception_handler(StarletteHTTPException)
    async def _http(_req: Request, exc: StarletteHTTPException) -> JSONResponse:
        return _error(exc.status_code, str(exc.detail))

    @app.exception_handler(Exception)
    async def _unexpected(req: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error in %s %s", req.method, req.url.path)
        return _error(500, f"internal error ({type(exc).__name__}); see the server log")


def create_app(config: WebConfig | None = None) -> FastAPI:
    """The simulator app; ``config`` defaults to configs/web.yaml."""
    cfg = config or load_web_config()
    service = SimulatorService(cfg)
    runner = ComputeRunner(cfg.workers, cfg.max_pending)

    @asynccontextmanager
    async def lifespan(_app: FastAPI):
        yield
        runner.shutdown()

    app = FastAPI(
        title="parknss simulator",
        version=parknss.__version__,
        description="Plan a parking scene and execute it in closed loop through a plant.",
        lifespan=lifespan,
        docs_url=None,  # Swagger UI and ReDoc load from a CDN; the page must work offline
        redoc_url=None,
    )
    app.state.service = service
    app.state.runner = runner
    _install_error_handlers(app)

    @app.get("/api/health", response_model=Health)
    def health() -> Health:  # not queued behind long plans and runs
        return service.health()

    @app.get("/api/cells", response_model=CellList, responses=_ERRORS)
    def cells(grid: Grid = "36") -> CellList:
        return service.cells(grid)

    @app.get("/api/scene", response_model=SceneResponse, responses=_ERRORS)
    def scene(index: int, grid: Grid = "36") -> SceneResponse:
        return service.scene_response(grid, index)

    @app.post("/api/import", response_model=ImportResponse, responses=_ERRORS)
    async def import_scene(req: ImportRequest) -> ImportResponse:
        return await runner.run(cfg.plan_budget_s, "the import", service.import_scene, req)

    @app.post("/api/plan", response_model=PlanResponse, responses=_ERRORS)
    async def plan(req: SceneRequest) -> PlanResponse:
        return await runner.run(cfg.plan_budget_s, "planning", service.plan_request, req)

    @app.post("/api/simulate", response_model=SimulateResponse, responses=_ERRORS)
    async def simulate(req: SimulateRequest) -> SimulateResponse:
        return await runner.run(cfg.simulate_budget_s, "the simulation", service.simulate, req)

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html")

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app
