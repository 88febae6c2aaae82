"""The ``data`` stage of ``parknss identify``: import (or read) the campaign, describe it,
refuse early, and measure what the model card reports about the data.

:func:`campaign_facts` is what the card's "identified on" and "domain of validity"
sections read: trials per class, the logged channels and the absent ones, the
conditions recorded per trial, and the range of every command, actual and state channel
(min, max and the 0.5th-99.5th percentiles, the clip range the NSS normalizes with).
"""

from __future__ import annotations

import hashlib
from collections import Counter
from pathlib import Path

import numpy as np

from parknss.data.trial import Campaign
from parknss.data.workflows import WORKFLOWS, require
from parknss.signals import DT, REQUIRED_CHANNELS, ms_to_kmh

NEEDED_WORKFLOWS: tuple[str, ...] = ("nss", "actuators", "rate", "closed_loop")
"""What identify runs: every workflow of :mod:`parknss.data.workflows`."""

RANGE_CHANNELS: dict[str, str] = {
    "torque_cmd": "N·m", "decel_cmd": "m/s²", "steer_cmd": "deg",
    "torque": "N·m", "brake_pressure": "bar", "steer": "deg",
    "vx": "m/s", "yaw_rate": "rad/s", "ax": "m/s²", "ay": "m/s²",
}
"""Channels whose seen range the card lists, with their schema units."""


def logs_digest(logs: Path, mapping: Path | None) -> str:
    """SHA-256 of the log folder's files (names and contents, sorted) and the mapping."""
    h = hashlib.sha256()
    for p in sorted(q for q in Path(logs).rglob("*") if q.is_file()):
        h.update(p.relative_to(logs).as_posix().encode() + b"\0")
        with p.open("rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    if mapping is not None:
        h.update(b"mapping\0" + Path(mapping).read_bytes())
    return h.hexdigest()


def refuse_early(campaign: Campaign, where: str) -> None:
    """One DataError line unless the campaign supports every workflow identify runs."""
    for name in NEEDED_WORKFLOWS:
        require(campaign, name, f"{where} (stage {WORKFLOWS[name].name})")


def _range(x: np.ndarray) -> dict:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return {"min": None, "max": None, "p0_5": None, "p99_5": None}
    lo, hi = np.percentile(x, [0.5, 99.5])
    return {"min": float(x.min()), "max": float(x.max()), "p0_5": float(lo), "p99_5": float(hi)}


def _conditions(campaign: Campaign) -> dict | None:
    from parknss.reference.conditions import conditions_summary

    per = conditions_summary(list(campaign))
    if not per:
        return None
    out: dict[str, object] = {"trials": len(per)}
    keys = sorted({k for c in per.values() for k in c})
    for k in keys:
        vals = [c[k] for c in per.values() if k in c]
        if all(isinstance(v, int | float) and not isinstance(v, bool) for v in vals):
            out[k] = {"min": float(min(vals)), "max": float(max(vals))}
        else:
            out[k] = sorted({str(v) for v in vals})
    return out


def campaign_facts(campaign: Campaign) -> dict:
    """What the card reports about the data (module doc); plain JSON."""
    present = [c for c in REQUIRED_CHANNELS if all(c in tr.channels for tr in campaign)]
    absent = [c for c in REQUIRED_CHANNELS if c not in present]
    ranges = {}
    for ch, unit in RANGE_CHANNELS.items():
        if ch in present:
            ranges[ch] = {"unit": unit,
                          **_range(np.concatenate([tr[ch] for tr in campaign]))}
    vx = np.concatenate([tr["vx"] for tr in campaign]) if "vx" in present else np.zeros(0)
    gears = np.concatenate([tr["gear"] for tr in campaign]) if "gear" in present else None
    return {
        "name": campaign.name,
        "trials": len(campaign),
        "classes": dict(Counter(tr.maneuver for tr in campaign)),
        "duration_s": float(sum(tr.n for tr in campaign) * DT),
        "synthetic": bool(campaign.meta.get("synthetic", False)),
        "channels_present": present,
        "channels_absent": absent,
        "speed_kmh": {"forward_max": float(ms_to_kmh(vx.max())) if vx.size else None,
                      "reverse_max": float(ms_to_kmh(-vx.min())) if vx.size else None},
        "reverse_fraction": (float(np.mean(gears < 0)) if gears is not None else None),
        "ranges": ranges,
        "conditions": _conditions(campaign),
        "data_hash": campaign.data_hash(),
    }
