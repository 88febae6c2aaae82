"""Per-channel scaling of trials to [-1, 1], fitted on the training trials only (paper §II).

Every channel c is mapped by one affine rule after an optional clip,

    scaled = (clip(x, clip_lo, clip_hi) - offset) / scale,

with three kinds:

* ``clipped`` (the paper's): clip to the 0.5th-99.5th percentile range [p_lo, p_hi] of
  the training samples, then min-max to [-1, 1] (offset = (p_lo + p_hi)/2,
  scale = (p_hi - p_lo)/2). Rare actuator transients no longer compress the resolution
  of the other samples, and the scaled signals stay bounded.
* ``minmax``: the same without the clip (percentiles 0 and 100).
* ``zscore``: offset = mean, scale = standard deviation, no clip.

The gear is categorical with the fixed range {-1, 0, +1}; it is passed through unchanged
(offset 0, scale 1, no clip), which is what min-max gives whenever both reverse and drive
occur and which cannot merge reverse into neutral when reverse is rarer than the clip
percentile. ``inverse`` undoes the affine part only (a clip is not invertible).

A :class:`Normalizer` works on NumPy arrays and torch tensors alike and serialises to and
from plain JSON; it is saved with every model.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from parknss.data.trial import Trial
from parknss.errors import CheckpointError, DataError

KINDS: tuple[str, ...] = ("clipped", "minmax", "zscore")
CATEGORICAL: tuple[str, ...] = ("gear",)
FORMAT = "parknss-normalizer/1"


@dataclass(frozen=True)
class ChannelScale:
    """Scaling of one channel: clip to [clip_lo, clip_hi] (None: no clip), then affine."""

    offset: float
    scale: float
    clip_lo: float | None = None
    clip_hi: float | None = None

    def to_json(self) -> dict:
        return {
            "offset": self.offset,
            "scale": self.scale,
            "clip_lo": self.clip_lo,
            "clip_hi": self.clip_hi,
        }


def _clip(x, lo: float | None, hi: float | None):
    if lo is None and hi is None:
        return x
    if isinstance(x, np.ndarray) or np.isscalar(x):
        return np.clip(x, lo, hi)
    return x.clamp(min=lo, max=hi)  # torch tensor


def _fit_channel(name: str, x: np.ndarray, kind: str, pct: tuple[float, float]) -> ChannelScale:
    if name in CATEGORICAL:
        return ChannelScale(0.0, 1.0)
    if kind == "zscore":
        offset, scale = float(np.mean(x)), float(np.std(x))
        lo = hi = None
    else:
        p = pct if kind == "clipped" else (0.0, 100.0)
        lo, hi = (float(v) for v in np.percentile(x, p))
        offset, scale = 0.5 * (lo + hi), 0.5 * (hi - lo)
        if kind == "minmax":
            lo = hi = None
    if not (math.isfinite(scale) and scale > 0.0):
        raise DataError(
            f"channel {name!r} has no spread on the training trials ({kind} scale {scale!r}); "
            "it cannot be normalised"
        )
    return ChannelScale(offset, scale, lo, hi)


@dataclass(frozen=True)
class Normalizer:
    """Fitted scaling of named channels (see the module docstring for the rules)."""

    kind: str
    percentiles: tuple[float, float]
    channels: dict[str, ChannelScale]

    @classmethod
    def fit(
        cls,
        trials: Iterable[Trial],
        names: Sequence[str],
        kind: str = "clipped",
        percentiles: tuple[float, float] = (0.5, 99.5),
    ) -> Normalizer:
        """Fit on the concatenated samples of ``trials`` (training trials only)."""
        if kind not in KINDS:
            raise DataError(f"unknown normalizer kind {kind!r}; expected one of {KINDS}")
        trials = list(trials)
        if not trials:
            raise DataError("cannot fit a normalizer on no trials")
        fitted = {}
        for nm in names:
            x = np.concatenate([np.asarray(tr[nm], dtype=np.float64) for tr in trials])
            if not np.all(np.isfinite(x)):
                raise DataError(f"channel {nm!r} has non-finite samples on the training trials")
            fitted[nm] = _fit_channel(nm, x, kind, percentiles)
        return cls(kind, (float(percentiles[0]), float(percentiles[1])), fitted)

    def _get(self, name: str) -> ChannelScale:
        try:
            return self.channels[name]
        except KeyError:
            raise DataError(f"normalizer has no channel {name!r}") from None

    def transform(self, name: str, x, clip: bool = True):
        """Scaled value(s) of channel ``name``; ``clip=False`` skips the clip."""
        c = self._get(name)
        if clip:
            x = _clip(x, c.clip_lo, c.clip_hi)
        return (x - c.offset) / c.scale

    def inverse(self, name: str, s):
        """Physical value(s) from scaled ones (the affine part; a clip is not undone)."""
        c = self._get(name)
        return s * c.scale + c.offset

    def scale_of(self, name: str) -> float:
        """Physical units per scaled unit of channel ``name`` (for differences, no offset)."""
        return self._get(name).scale

    def transform_array(self, names: Sequence[str], arr, clip: bool = True):
        """Scale the last axis of ``arr`` (..., C), whose columns are ``names``."""
        cols = [self.transform(nm, arr[..., j], clip) for j, nm in enumerate(names)]
        if isinstance(arr, np.ndarray):
            return np.stack(cols, axis=-1)
        import torch

        return torch.stack(cols, dim=-1)

    def to_json(self) -> dict:
        return {
            "format": FORMAT,
            "kind": self.kind,
            "percentiles": list(self.percentiles),
            "channels": {k: v.to_json() for k, v in self.channels.items()},
        }

    @classmethod
    def from_json(cls, doc: dict) -> Normalizer:
        """Rebuild from :meth:`to_json`; CheckpointError on anything malformed."""
        try:
            if doc.get("format") != FORMAT:
                raise ValueError(f"format {doc.get('format')!r} is not {FORMAT!r}")
            kind = doc["kind"]
            if kind not in KINDS:
                raise ValueError(f"unknown kind {kind!r}")
            pct = tuple(float(v) for v in doc["percentiles"])
            chans = {}
            for nm, c in doc["channels"].items():
                cs = ChannelScale(
                    float(c["offset"]),
                    float(c["scale"]),
                    None if c["clip_lo"] is None else float(c["clip_lo"]),
                    None if c["clip_hi"] is None else float(c["clip_hi"]),
                )
                if not (math.isfinite(cs.offset) and math.isfinite(cs.scale) and cs.scale > 0):
                    raise ValueError(f"channel {nm!r} has offset/scale {cs.offset}/{cs.scale}")
                chans[nm] = cs
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise CheckpointError(f"normalizer is malformed: {exc}") from exc
        return cls(kind, (pct[0], pct[1]), chans)
