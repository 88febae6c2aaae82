"""The synthetic field-test campaign: 16 trials of the reference vehicle driven by the APS.

Shape of the paper's campaign (§IV-A): 4 classes (MANEUVER_CLASSES) x 4 repetitions at
100 Hz, multi-segment park-in with reversals and single-segment park-out, toward the
left and the right, about 21-64 s each, about 70 direction changes in all. Each trial
keeps the noise-free ``truth_*`` channels beside the logged ones (ground-truth
evaluation only). Everything follows from (seed, vehicle parameters, conditions profile):
same inputs, same bits.

Per-trial conditions (:mod:`parknss.reference.conditions`) are drawn from the vehicle
YAML's ``conditions`` block under the profile it names (or the one passed in), from a
stream of their own; they go into each trial's provenance (``conditions``, ground truth)
and the campaign meta (``conditions_profile``, ``conditions_digest``). Profile ``none``
draws nothing and writes nothing: the campaign is the one generated before conditions.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parknss.data.trial import MANEUVER_CLASSES, Campaign, Trial
from parknss.errors import ConfigError
from parknss.reference.conditions import CONDITIONS_KEY, TrialConditions, draw_conditions
from parknss.reference.driver import ApsDriver, DriverParams
from parknss.reference.maneuvers import ManeuverPlan, make_plan
from parknss.reference.params import ReferenceVehicleParams, load_vehicle_params
from parknss.reference.vehicle import COMMAND_COLUMNS, ReferenceVehicle, records_to_arrays
from parknss.signals import SAMPLE_RATE_HZ

GENERATOR = "parknss.reference.campaign"
GENERATOR_VERSION = "1"
REPETITIONS = 4
LENGTH_RANGE_S = (21.0, 64.0)
MAX_ATTEMPTS = 20
MAX_TRIAL_S = 90.0


def trial_seeds(
    seed: int, maneuver: str, repetition: int, vehicle_seed: int, attempt: int = 0
) -> tuple[int, int]:
    """(plan seed, noise seed) of one trial, derived from the campaign and vehicle seeds."""
    if maneuver not in MANEUVER_CLASSES:
        raise ConfigError(
            f"unknown maneuver class {maneuver!r}; expected one of {MANEUVER_CLASSES}"
        )
    cls = MANEUVER_CLASSES.index(maneuver)
    ss = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, cls, int(repetition), int(attempt)])
    plan_seed = int(ss.generate_state(1)[0])
    return plan_seed, noise_seed_of(vehicle_seed, plan_seed)


def noise_seed_of(vehicle_seed: int, plan_seed: int) -> int:
    """The sensor-noise seed of a trial driven from ``plan_seed`` on a vehicle of
    ``vehicle_seed``."""
    noise_ss = np.random.SeedSequence([int(vehicle_seed) & 0xFFFFFFFF, int(plan_seed)])
    return int(noise_ss.generate_state(1)[0])


def drive_plan(
    plan: ManeuverPlan,
    params: ReferenceVehicleParams,
    noise_seed: int,
    driver_params: DriverParams | None = None,
    conditions: TrialConditions | None = None,
) -> dict[str, np.ndarray]:
    """Drive one plan closed loop under ``conditions``; return all channels (commands,
    logged, truth), (T,). The driver is calibrated on the nominal vehicle: it knows
    nothing of the conditions but what the logged signals show it."""
    car = ReferenceVehicle(params, seed=noise_seed, conditions=conditions)
    driver = ApsDriver(plan, params, driver_params, dt=car.dt)
    y = car.reset()
    rows: list[tuple[float, ...]] = []
    cmds: list[tuple[float, float, float, float]] = []
    limit = round(MAX_TRIAL_S * SAMPLE_RATE_HZ)
    while not driver.done and len(rows) < limit:
        c = driver.command(y)
        rows.append(car.record())
        cmds.append((c.gear, c.torque_cmd, c.decel_cmd, c.steer_cmd))
        y = car.step(c)
    return trial_channels(rows, cmds)


def trial_channels(
    rows: list[tuple[float, ...]], cmds: list[tuple[float, float, float, float]] | np.ndarray
) -> dict[str, np.ndarray]:
    """The channels of a synthetic trial, (T,) each: row k of ``rows``
    (:meth:`ReferenceVehicle.record` before command k acts: the logged and ``truth_*``
    channels, ``gear`` the engaged one) beside command k of ``cmds`` ((T, 4) [gear,
    torque_cmd, decel_cmd, steer_cmd]; its gear column is not logged), and ``t`` at 100 Hz.
    The one assembly of every synthetic trial (the APS campaign and the stack trials)."""
    out = records_to_arrays(rows)
    cmd = np.asarray(cmds, dtype=np.float64).reshape(len(rows), len(COMMAND_COLUMNS))
    for j, name in enumerate(COMMAND_COLUMNS):
        if name != "gear":
            out[name] = cmd[:, j].copy()
    out["t"] = np.arange(len(rows)) / SAMPLE_RATE_HZ
    return out


def synthetic_trial(
    trial_id: str,
    maneuver: str,
    repetition: int,
    channels: dict[str, np.ndarray],
    params: ReferenceVehicleParams,
    provenance: dict,
    conditions: TrialConditions | None = None,
    vehicle_hash: str | None = None,
) -> Trial:
    """A synthetic trial with the provenance every generated trial carries (generator
    keys of ``provenance`` first, then synthetic, the vehicle id, parameter digest and
    YAML SHA-256, and the drawn conditions as ground truth)."""
    prov = {
        **provenance,
        "synthetic": True,
        "vehicle_id": params.vehicle_id,
        "vehicle_params_digest": params.digest(),
        "vehicle_yaml_sha256": vehicle_hash,
    }
    if conditions is not None:
        prov[CONDITIONS_KEY] = conditions.model_dump()
    return Trial(
        id=trial_id,
        maneuver=maneuver,
        repetition=repetition,
        channels=channels,
        vehicle_id=params.vehicle_id,
        sample_rate_hz=SAMPLE_RATE_HZ,
        provenance=json.dumps(prov, sort_keys=True),
    )


@dataclass(frozen=True)
class TrialCar:
    """The car of one synthetic trial: the vehicle parameters, the noise seed and the
    trial's conditions (ground truth). Another driver of the reference vehicle (the
    closed-loop stack of :mod:`parknss.sim.stack_trials`) takes its car from
    :func:`trial_car` and its trial from :meth:`trial`, so the conditions are drawn and
    recorded here, the one place, and never read by the driver."""

    params: ReferenceVehicleParams
    noise_seed: int
    conditions: TrialConditions | None

    def vehicle(self) -> ReferenceVehicle:
        """A fresh reference vehicle under the trial's conditions and noise seed."""
        return ReferenceVehicle(self.params, seed=self.noise_seed, conditions=self.conditions)

    def trial(
        self,
        trial_id: str,
        maneuver: str,
        repetition: int,
        channels: dict[str, np.ndarray],
        provenance: dict,
        vehicle_hash: str | None = None,
    ) -> Trial:
        """The trial of ``channels`` (:func:`trial_channels`) with the common provenance
        (:func:`synthetic_trial`) and ``noise_seed`` added."""
        prov = {**provenance, "noise_seed": self.noise_seed}
        return synthetic_trial(
            trial_id, maneuver, repetition, channels, self.params, prov, self.conditions,
            vehicle_hash,
        )


def trial_car(
    params: ReferenceVehicleParams,
    seed: int,
    class_index: int,
    repetition: int,
    plan_seed: int,
    conditions: str | None = None,
) -> TrialCar:
    """The car of trial (``seed``, ``class_index``, ``repetition``): conditions drawn from
    that key under the profile ``conditions`` (default: the YAML's), noise seed from the
    vehicle seed and ``plan_seed`` as :func:`trial_seeds` derives it."""
    cond = draw_conditions(params.conditions, seed, class_index, repetition, conditions)
    return TrialCar(params, noise_seed_of(params.seed, plan_seed), cond)


def generate_trial(
    maneuver: str,
    repetition: int,
    seed: int = 0,
    params: ReferenceVehicleParams | None = None,
    driver_params: DriverParams | None = None,
    vehicle_hash: str | None = None,
    conditions: str | None = None,
) -> Trial:
    """One synthetic trial, e.g. ``generate_trial("park_in_left", 1)`` -> park_in_left_r1.

    The plan is drawn from (seed, class, repetition); a plan whose driven trial falls
    outside LENGTH_RANGE_S (the paper's 21-64 s) is redrawn with the next attempt index,
    deterministically, so the same inputs always give the same trial. The trial's
    conditions are drawn once from (seed, class, repetition) under the profile
    ``conditions`` (default: ``params.conditions.profile``) and kept across redraws.
    """
    params = params or ReferenceVehicleParams()
    if repetition < 1:
        raise ConfigError(f"repetition must be >= 1, got {repetition}")
    trial_seeds(seed, maneuver, repetition, params.seed)  # checks the class
    cond = draw_conditions(
        params.conditions, seed, MANEUVER_CLASSES.index(maneuver), repetition, conditions
    )
    lo, hi = LENGTH_RANGE_S
    for attempt in range(MAX_ATTEMPTS):
        plan_seed, noise_seed = trial_seeds(seed, maneuver, repetition, params.seed, attempt)
        plan = make_plan(
            maneuver, repetition, np.random.default_rng(plan_seed), params.geometry.steer_lock_deg
        )
        channels = drive_plan(plan, params, noise_seed, driver_params, cond)
        if lo <= len(channels["t"]) / SAMPLE_RATE_HZ <= hi:
            break
    else:
        raise ConfigError(
            f"vehicle {params.vehicle_id}: no {maneuver} plan within {lo}-{hi} s in "
            f"{MAX_ATTEMPTS} attempts (vehicle too slow or too fast for the APS driver)"
        )
    provenance = {
        "generator": GENERATOR,
        "generator_version": GENERATOR_VERSION,
        "seed": int(seed),
        "plan_seed": plan_seed,
        "noise_seed": noise_seed,
        "attempt": attempt,
        "planned_reversals": plan.reversals,
    }
    return synthetic_trial(
        f"{maneuver}_r{repetition}", maneuver, repetition, channels, params, provenance,
        cond, vehicle_hash,
    )


def generate_campaign(
    seed: int = 0,
    vehicle_yaml: Path | None = None,
    progress: bool = False,
    conditions: str | None = None,
) -> Campaign:
    """The 16-trial synthetic campaign (4 classes x 4 repetitions) of one vehicle YAML,
    its trials under conditions of the profile ``conditions`` (default: the YAML's
    ``conditions.profile``; ``none``, ``typical`` or ``harsh``)."""
    params = load_vehicle_params(vehicle_yaml)
    if conditions is not None:
        params = params.replace(conditions={"profile": conditions})
    yaml_hash = (
        hashlib.sha256(Path(vehicle_yaml).read_bytes()).hexdigest() if vehicle_yaml else None
    )
    jobs = [(m, r) for m in MANEUVER_CLASSES for r in range(1, REPETITIONS + 1)]
    if progress:
        from tqdm import tqdm

        jobs = tqdm(jobs, desc="campaign", unit="trial")
    trials = [generate_trial(m, r, seed, params, vehicle_hash=yaml_hash) for m, r in jobs]
    meta = {
        "synthetic": True,
        "note": "synthetic campaign of the parknss reference vehicle, not field data",
        "generator": GENERATOR,
        "generator_version": GENERATOR_VERSION,
        "seed": int(seed),
        "vehicle_id": params.vehicle_id,
        "vehicle_yaml": str(vehicle_yaml) if vehicle_yaml else None,
        "vehicle_yaml_sha256": yaml_hash,
        "vehicle_params_digest": params.digest(),
        "vehicle_geometry": params.to_geometry().to_dict(),
    }
    if params.conditions.profile != "none":
        meta["conditions_profile"] = params.conditions.profile
        meta["conditions_digest"] = params.conditions.digest()
    return Campaign(trials, name=f"reference_seed{seed}", meta=meta)
