"""The FastAPI app of the interactive simulator: a JSON API and the static page.

Endpoints (docs/web.md has examples):

* ``GET /api/health``: version, plants (available or why not), vehicle, grid sizes.
* ``GET /api/cells?grid=36|252``: every cell of a grid.
* ``GET /api/scene?grid=36&index=26``: one grid scene as scene JSON.
* ``POST /api/plan``: plan a cell or a scene JSON (optionally with an edited start).
* ``POST /api/simulate``: plan (or reuse the plan) and execute it through one plant.
* ``POST /api/import``: a TPCAP case (.csv) or CommonRoad scenario (.xml) as scene JSON.

Every error is JSON ``{"error": "<one line>", "status": <code>}``: 400 malformed JSON or
a Host header that does not name the server, 401 no token (when one is set), 413 body
over ``max_body_bytes``, 422 invalid request (unknown plant, cell out of range,
non-finite or out-of-range numbers, bad polygons, start pose in collision), 503 plant
unavailable or server busy, 504 over the wall-clock budget. Unexpected failures are
logged and answered 500 without a traceback, on a connection that stays open
(:mod:`parknss.web.guard`). POST bodies are decoded off the event loop
(:mod:`parknss.web.bodies`).
"""

from __future__ import annotations

from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

import parknss
from parknss.errors import ParknssError
from parknss.web.bodies import openapi_body, parse_body
from parknss.web.config import WebConfig, load_web_config
from parknss.web.errors import WebError
from parknss.web.guard import Guard, HostPolicy
from parknss.web.jobs import ComputeRunner
from parknss.web.schemas import (
    CellList,
    ErrorResponse,
    FidelityRequest,
    FidelityResponse,
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

_ERRORS = {
    400: {"model": ErrorResponse},
    413: {"model": ErrorResponse},
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

    # exceptions nothing above handles reach parknss.web.guard.Guard: logged, 500 JSON,
    # and the connection stays open (an Exception handler here would re-raise to uvicorn)


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
    app.add_middleware(
        Guard,
        hosts=HostPolicy(cfg.host, cfg.allowed_hosts),
        token=cfg.token,
        max_body_bytes=cfg.max_body_bytes,
    )

    @app.get("/api/health", response_model=Health)
    def health() -> Health:  # not queued behind long plans and runs
        return service.health()

    @app.get("/api/cells", response_model=CellList, responses=_ERRORS)
    def cells(grid: Grid = "36") -> CellList:
        return service.cells(grid)

    @app.get("/api/scene", response_model=SceneResponse, responses=_ERRORS)
    def scene(index: int, grid: Grid = "36") -> SceneResponse:
        return service.scene_response(grid, index)

    def _post(path: str, model, response_model, budget_s: float, what: str, method: str):
        """POST ``path``: the body decoded as ``model`` off the event loop, then
        ``service.<method>`` on the compute pool within ``budget_s``."""

        async def endpoint(request: Request):
            req = await parse_body(request, model)
            return await runner.run(budget_s, what, getattr(app.state.service, method), req)

        endpoint.__name__ = method
        app.post(path, response_model=response_model, responses=_ERRORS,
                 openapi_extra=openapi_body(model))(endpoint)

    _post("/api/import", ImportRequest, ImportResponse, cfg.plan_budget_s, "the import",
          "import_scene")
    _post("/api/plan", SceneRequest, PlanResponse, cfg.plan_budget_s, "planning",
          "plan_request")
    _post("/api/simulate", SimulateRequest, SimulateResponse, cfg.simulate_budget_s,
          "the simulation", "simulate")
    _post("/api/fidelity", FidelityRequest, FidelityResponse, cfg.simulate_budget_s,
          "the fidelity runs", "fidelity")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html")

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app
