"""Sign and offset checks of a campaign's IMU and yaw rate, each with the mapping line
that fixes it (``parknss campaign describe``, docs/data.md).

parknss's convention (ISO 8855, the one of :mod:`parknss.signals`): ``ax`` is positive
when ``vx`` grows, ``ay`` is the centripetal acceleration ``vx · ω_z`` (positive to the
left in a left turn), ``yaw_rate`` is zero at standstill. Pooled over all trials:

* ``ax`` against ``dvx/dt`` and ``ay`` against ``vx · ω_z`` on the moving region
  (|vx| >= 0.5 km/h), both smoothed by a centred moving average of ``sign_smooth_s``:
  a correlation below ``sign_corr_min`` (negative) means the channel's sign is the
  opposite of parknss's: fix ``invert: true``;
* the yaw rate's median at standstill (|vx| < ``standstill_kmh``): beyond
  ``yaw_offset_min_dps`` it is an offset: fix ``offset: -median`` (in the unit of the
  mapping's yaw rate; given in deg/s and rad/s), with the yaw R² and the steering-ratio
  fit of eq. 4 after removing it;
* frames too short for a signal (CAN logs; masked on import), per trial and source.

The checks advise; nothing is changed or refused because of them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from parknss.data.trial import Campaign
from parknss.signals import KMH_PER_MS, moving_mask


@dataclass(frozen=True)
class SignCheck:
    """One check: its name, the figure, whether it passed, one line, the fixing line."""

    check: str
    value: float | None
    ok: bool | None
    detail: str
    fix: str | None = None
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"check": self.check, "value": self.value, "ok": self.ok,
                "detail": self.detail, "fix": self.fix, **self.extra}


def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    if n <= 1 or len(x) < n:
        return x
    return np.convolve(x, np.ones(n) / n, mode="same")


def _corr(a: np.ndarray, b: np.ndarray) -> float | None:
    if len(a) < 3 or np.std(a) == 0.0 or np.std(b) == 0.0:
        return None
    return float(np.corrcoef(a, b)[0, 1])


def _pooled(campaign: Campaign, ch: str, ref, smooth_n: int) -> tuple[np.ndarray, np.ndarray]:
    xs, rs = [], []
    for tr in campaign:
        m = moving_mask(tr["vx"])
        xs.append(_smooth(tr[ch], smooth_n)[m])
        rs.append(_smooth(ref(tr), smooth_n)[m])
    return np.concatenate(xs or [np.zeros(0)]), np.concatenate(rs or [np.zeros(0)])


def sign_check(campaign, ch: str, what: str, ref, smooth_n: int, corr_min: float):
    x, r = _pooled(campaign, ch, ref, smooth_n)
    c = _corr(x, r)
    if c is None:
        return SignCheck(f"{ch}_sign", None, None, f"{ch} vs {what}: n/a (no motion)")
    if c < corr_min:
        return SignCheck(
            f"{ch}_sign", c, False,
            f"{ch} vs {what}: correlation {c:.3f}: {ch} has the opposite sign of parknss's "
            "convention",
            f"{ch}: {{..., invert: true}}",
        )
    return SignCheck(f"{ch}_sign", c, True, f"{ch} vs {what}: correlation {c:.3f} (sign ok)")


def yaw_offset(campaign: Campaign, standstill_kmh: float) -> tuple[float | None, int]:
    """(median yaw rate at standstill in rad/s, samples), None without standstill."""
    parts = [tr["yaw_rate"][np.abs(tr["vx"]) * KMH_PER_MS < standstill_kmh] for tr in campaign]
    y = np.concatenate(parts or [np.zeros(0)])
    return (float(np.median(y)) if len(y) else None), len(y)


def short_frames(campaign: Campaign) -> dict[str, dict[str, int]]:
    """{trial id: {source: frames too short for it}} from the import provenance."""
    out = {}
    for tr in campaign:
        try:
            prov = json.loads(tr.provenance or "{}")
            if isinstance(prov.get("file_provenance"), str):
                prov = json.loads(prov["file_provenance"])
        except (json.JSONDecodeError, TypeError):
            continue
        short = prov.get("short_frames") if isinstance(prov, dict) else None
        if short:
            out[tr.id] = {str(k): int(v) for k, v in short.items()}
    return out
