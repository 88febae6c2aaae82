"""The model card of an identified plant: ``CAR/model_card.json`` (a :class:`ModelCard`
serialised) and ``CAR/model_card.html`` (one self-contained page, :mod:`.card_html`).

It says what the plant was identified on (trials, classes, speed and steering coverage,
conditions, channels absent), how good it is open loop (the NSS and the chain against the
logged channels and, on a synthetic campaign, the truth; Table IV), its ISO/TS 18571
rating, its closed-loop Table V on the car's own grid, its fidelity against the truth
where one exists, its domain of validity (the command and state ranges seen in the data
and the FMU's identified domain), what it must not be used for, and how each stage was
obtained (ran, resumed, reused and why).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime

from parknss.experiments.identify.config import STAGES, IdentifyInputs
from parknss.experiments.identify.stages import StageRecord
from parknss.outputs import git_revision
from parknss.signals import ms_to_kmh

CARD_FORMAT = "parknss-model-card/1"

OPEN_LOOP_KEYS: tuple[tuple[str, str], ...] = (
    ("vx_mse_moving_kmh2", "vx moving [(km/h)²]"),
    ("vx_mse_reverse_kmh2", "vx reverse [(km/h)²]"),
    ("vx_mse_full_kmh2", "vx full [(km/h)²]"),
    ("yaw_mse_moving_degs2", "ω_z moving [(°/s)²]"),
    ("ax_mse_moving_ms2", "ax moving [(m/s²)²]"),
    ("ay_mse_moving_ms2", "ay moving [(m/s²)²]"),
)
"""Open-loop error columns of the card (Table II style), with their units."""


@dataclass
class ModelCard:
    """Everything the card says, as plain JSON-able fields (module doc)."""

    format: str
    generated_utc: str
    parknss_git: str
    car: str
    chain: str | None
    recipe: str
    data: dict
    nss: dict
    open_loop: dict
    table4: dict | None
    iso: dict | None
    closed_loop: dict | None
    fidelity: dict | None
    domain: dict
    not_for: list[str]
    stages: list[dict] = field(default_factory=list)

    def to_json(self) -> dict:
        return asdict(self)


def _pick(doc: dict | None) -> dict | None:
    if not doc:
        return None
    return {k: doc.get(k) for k, _ in OPEN_LOOP_KEYS}


def open_loop_section(rating: StageRecord | None) -> dict:
    """NSS and chain errors vs logged and truth; the seed spread where measured."""
    if rating is None:
        return {"note": "rating stage not run"}
    p = rating.product
    out = {}
    for name in ("nss_open_loop", "chain_open_loop"):
        doc = p.get(name) or {}
        out[name] = {"logged": _pick(doc), "truth": _pick(doc.get("truth"))}
    out["seed_spread"] = ("not measured: one fit with one seed (the spread of refits is the "
                          "seed-noise study, parknss study seed-noise)")
    return out


def not_for(facts: dict, rec: dict[str, StageRecord]) -> list[str]:
    """What the plant must not be used for, from what its data did and did not cover."""
    out = []
    sp = facts.get("speed_kmh") or {}
    fwd, rev = sp.get("forward_max"), sp.get("reverse_max")
    if fwd is not None:
        out.append(f"speeds above those in its data: {fwd:.2f} km/h forward, "
                   f"{rev:.2f} km/h reverse (the NSS is a parking-speed model; nothing "
                   "beyond is identified)")
    r = (facts.get("ranges") or {})
    if "steer_cmd" in r and r["steer_cmd"]["min"] is not None:
        out.append(f"steering-wheel commands outside [{r['steer_cmd']['min']:.0f}, "
                   f"{r['steer_cmd']['max']:.0f}] deg (clamped by the chain's envelope)")
    if "decel_cmd" in r and r["decel_cmd"]["min"] is not None:
        out.append(f"deceleration requests beyond {r['decel_cmd']['min']:.2f} m/s² "
                   "(clamped by the envelope: no emergency braking is identified)")
    cond = facts.get("conditions")
    if cond:
        slope = cond.get("lot_slope_pct")
        load = cond.get("payload_kg")
        bits = []
        if isinstance(slope, dict):
            bits.append(f"floor grade {slope['min']:.1f}-{slope['max']:.1f} %")
        if isinstance(load, dict):
            bits.append(f"payload {load['min']:.0f}-{load['max']:.0f} kg")
        if bits:
            out.append("conditions outside those of its trials (" + ", ".join(bits) + ")")
    else:
        out.append("conclusions about grade, load, surface or temperature: the campaign "
                   "records no per-trial conditions")
    if facts.get("channels_absent"):
        out.append("anything about the channels its data lacks: "
                   + ", ".join(facts["channels_absent"]))
    out.append("dynamics beyond low-speed manoeuvring: lateral tyre limits, highway "
               "speeds, kerb strikes or any maneuver class it was not identified on "
               f"({', '.join(sorted(facts.get('classes', {})))})")
    if facts.get("synthetic"):
        out.append("claims about a real car: the campaign is synthetic (the parknss "
                   "reference vehicle)")
    fid = rec.get("fidelity")
    if fid is not None and fid.product.get("summary"):
        out.append("safety validation without the fidelity targets met: see the fidelity "
                   "section for which of them this plant meets")
    return out


def domain_section(facts: dict, export: StageRecord | None) -> dict:
    ranges = {}
    for ch, r in (facts.get("ranges") or {}).items():
        ranges[ch] = r
    dom = {"seen": ranges}
    vx = ranges.get("vx")
    if vx and vx["min"] is not None:
        dom["vx_kmh"] = [float(ms_to_kmh(vx["min"])), float(ms_to_kmh(vx["max"]))]
    if export is not None:
        dom["fmu"] = export.product.get("domain")
    return dom


def _gains_source(tune: StageRecord | None) -> str | None:
    if tune is None:
        return None
    return tune.reused or "tuned on this chain (parknss tune, the 12-cell core)"


def build_card(rec: dict[str, StageRecord], recipe: str, inputs: IdentifyInputs) -> ModelCard:
    """The card of the stage records ``rec`` (missing stages: sections say "not run")."""
    facts = rec["data"].product["facts"]
    nss = rec.get("nss")
    chain = rec.get("chain")
    grid = rec.get("grid")
    fid = rec.get("fidelity")
    stages = []
    for s in STAGES:
        r = rec.get(s)
        status = "not run" if r is None else r.status
        if s == "card":
            status = "this card"
        stages.append({"stage": s, "status": status,
                       "reused": None if r is None else r.reused,
                       "wall_s": None if r is None else round(r.wall_total_s, 1),
                       "sittings": None if r is None else r.sittings,
                       "finished_utc": None if r is None else r.finished_utc})
    nss_doc = {"recipe": recipe}
    if nss is not None:
        p = nss.product
        nss_doc.update({"model": p.get("model"), "reused": nss.reused,
                        "code": p.get("code"), "fitted_code_version":
                        p.get("fitted_code_version"),
                        "epochs": (p.get("config") or {}).get("train", {}).get("epochs"),
                        "training": p.get("training")})
    return ModelCard(
        format=CARD_FORMAT,
        generated_utc=datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        parknss_git=git_revision(),
        car=str(inputs.out),
        chain=None if chain is None else chain.product["chain"],
        recipe=recipe,
        data=facts,
        nss=nss_doc,
        open_loop=open_loop_section(rec.get("rating")),
        table4=None if chain is None else {"rows": chain.product["rows"],
                                           "winners": chain.product["winners"]},
        iso=None if rec.get("rating") is None else rec["rating"].product["iso"],
        closed_loop=None if grid is None else {"grid": grid.product.get("grid"),
                                               "cells": grid.product.get("cells"),
                                               "summary": grid.product.get("summary"),
                                               "gains": (rec["tune"].product.get("gains")
                                                         if rec.get("tune") else None),
                                               "gains_source": _gains_source(rec.get("tune"))},
        fidelity=None if fid is None else fid.product,
        domain=domain_section(facts, rec.get("export")),
        not_for=not_for(facts, rec),
        stages=stages,
    )

