"""Settings of the optimisation-based refinement (``refine:`` in configs/planning.yaml).

Units are in the field names or descriptions: m, s, m/s, m/s², m/s³, and degrees of
steering-wheel angle (deg, deg/s). The defaults follow H-OBCA (Zhang et al. 2018) in
spirit: a minimum-time objective with small smoothness and warm-start-deviation terms,
parking speeds (3 km/h), comfortable acceleration and the steering-wheel rate of a
parking-capable electric power steering.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from parknss.config import StrictModel


class RefineConfig(StrictModel):
    """Problem size, vehicle limits, cost weights, solver budget and the fallback profile."""

    # collision avoidance
    safety_margin_m: float | None = Field(
        None, ge=0.0, description="min footprint-obstacle distance, m (None: planning margin)"
    )
    margin_buffer_m: float = Field(
        0.02, ge=0.0, description="added to the margin at the knots (covers between knots), m"
    )
    broadphase_m: float = Field(
        0.8, ge=0.0, description="obstacles this far beyond the margin from the warm start enter, m"
    )
    broadphase_knots: int = Field(
        3, ge=0, description="...counting the warm start this many knots either side"
    )
    repair_rounds: int = Field(
        3, ge=0, description="re-solves raising the knot margin where the dense check fails"
    )
    # discretisation
    dt_target_s: float = Field(1.0, gt=0.0, description="warm-start time step, s")
    min_intervals: int = Field(8, ge=2, description="fewest intervals per gear segment")
    max_intervals: int = Field(
        40, ge=2, description="most intervals per gear segment (more where dt_max_s needs them)"
    )
    dt_min_s: float = Field(0.02, gt=0.0, description="lower bound of the free time step, s")
    dt_max_s: float = Field(1.0, gt=0.0, description="upper bound of the free time step, s")
    min_segment_m: float = Field(
        0.02, ge=0.0, description="shorter gear segments keep the coarse poses, m"
    )
    # The end pose is met within a thin box rather than exactly: a coarse segment at full
    # lock on both sides of a steering change ends on the boundary of the reachable set,
    # where the exact constraint leaves IPOPT no interior. The output ends exactly on it.
    end_tolerance_m: float = Field(
        0.002, ge=0.0, description="solver's tolerance on the end pose position, m"
    )
    end_tolerance_deg: float = Field(0.1, ge=0.0, description="...and heading, deg")
    end_blend_m: float = Field(
        1.0, gt=0.0, description="the end offset is blended in over this much path, m"
    )
    # vehicle limits
    speed_max_ms: float = Field(0.8333, gt=0.0, description="parking speed limit, m/s")
    accel_max_ms2: float = Field(0.5, gt=0.0, description="|acceleration| limit, m/s²")
    jerk_max_ms3: float = Field(1.5, gt=0.0, description="|jerk| limit, m/s³")
    steer_rate_max_dps: float = Field(300.0, gt=0.0, description="steering-wheel rate limit, deg/s")
    # cost J = w_time T + ∫(w_accel a² + w_steer_rate ω²) dt + w_dev mean(|Δp|² + ρ² Δθ²)
    w_time: float = Field(1.0, ge=0.0, description="per second of segment duration")
    w_accel: float = Field(0.5, ge=0.0, description="per (m/s²)² s")
    w_steer_rate: float = Field(2.0, ge=0.0, description="per (rad/s of road wheel)² s")
    w_deviation: float = Field(2.0, ge=0.0, description="per m² of mean position offset")
    deviation_heading_m: float = Field(
        2.0, ge=0.0, description="ρ: heading offset counted as this lever arm, m/rad"
    )
    # solver
    max_iter: int = Field(300, ge=1, description="IPOPT iterations per gear segment")
    cpu_time_s: float = Field(
        30.0,
        gt=0.0,
        description="CPU-time guard of each IPOPT solve and of the whole path, s (max_iter binds)",
    )
    program_cache_size: int = Field(
        16,
        ge=0,
        description="segment programs kept built, by structure, ~3 MiB each (0: build every solve)",
    )
    tol: float = Field(1e-6, gt=0.0, description="IPOPT convergence tolerance")
    mu_strategy: Literal["adaptive", "monotone"] = Field("adaptive", description="IPOPT barrier")
    linear_solver: Literal["mumps", "spral"] = Field(
        "mumps", description="IPOPT's sparse linear solver (both ship with casadi's IPOPT)"
    )
    hessian_approximation: Literal["exact", "limited-memory"] = Field(
        "exact", description="IPOPT Hessian: exact (CasADi) or L-BFGS"
    )
    warm_start_init_point: bool = Field(
        False, description="IPOPT starts from the given primal and dual guess as is"
    )
    mu_init: float = Field(0.1, gt=0.0, description="IPOPT's initial barrier parameter")
    # output and fallback
    output_step_m: float = Field(0.05, gt=0.0, description="pose spacing of the result, m")
    fallback_speed_ms: float = Field(0.6, gt=0.0, description="coarse fallback cruise, m/s")
    fallback_accel_ms2: float = Field(0.3, gt=0.0, description="coarse fallback ramps, m/s²")
