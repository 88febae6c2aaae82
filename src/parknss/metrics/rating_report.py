"""The ISO/TS 18571 rating table of a campaign (paper §V-F, Fig. 7).

Input: per trial and channel a (measured, predicted) pair on the trial's grid. Every
pair is rated twice: raw, and after the identical zero-phase low-pass of both signals
(:func:`parknss.metrics.iso18571.lowpass`, 5 Hz by default). The ratings are scale
invariant, so channels are rated in their schema units without conversion.

:class:`RatingTable` holds one row per (trial, channel, conditioning) and writes the CSV,
the JSON document and the summary: the mean of each sub-rating per channel, and the
mean overall rating over channels (the mean of the per-channel means), raw and filtered.
:func:`truth_pairs` and :func:`model_pairs` pair a campaign's logged channels with its
truth channels or with a model's predictions; which model or chain predicts is
:mod:`parknss.chain.rating`.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np
from pydantic import Field

from parknss.config import StrictModel
from parknss.data.trial import Trial
from parknss.errors import DataError
from parknss.metrics.iso18571 import ISORatingConfig, LowpassConfig, grade_of, lowpass, rate_many
from parknss.outputs import atomic_file
from parknss.signals import DT

RATED_CHANNELS: tuple[str, ...] = ("vx", "yaw_rate", "ax", "ay")
CONDITIONINGS: tuple[str, ...] = ("raw", "filtered")
SUB_RATINGS: tuple[str, ...] = ("corridor", "phase", "magnitude", "slope", "overall")

PairMap = Mapping[str, Mapping[str, tuple[np.ndarray, np.ndarray]]]


class RateConfig(StrictModel):
    """What ``parknss rate`` rates and how: channels, the standard, the conditioning."""

    channels: tuple[str, ...] = Field(RATED_CHANNELS, min_length=1)
    iso: ISORatingConfig = ISORatingConfig()
    lowpass: LowpassConfig = LowpassConfig()


@dataclass(frozen=True)
class RatingRow:
    """One rated pair: a trial's channel, raw or filtered."""

    trial_id: str
    channel: str
    conditioning: str
    corridor: float
    phase: float
    magnitude: float
    slope: float
    overall: float
    grade: str
    shift_samples: int


@dataclass(frozen=True)
class ChannelSummary:
    """Means over trials of one channel under one conditioning."""

    channel: str
    conditioning: str
    n_trials: int
    corridor: float
    phase: float
    magnitude: float
    slope: float
    overall: float
    grade: str


@dataclass(frozen=True)
class RatingSummary:
    """Per-channel means and the mean over channels, raw and filtered."""

    channels: tuple[ChannelSummary, ...]
    mean_raw: float
    mean_filtered: float
    grade_raw: str
    grade_filtered: str

    def get(self, channel: str, conditioning: str) -> ChannelSummary:
        """The summary of one channel under one conditioning."""
        for c in self.channels:
            if c.channel == channel and c.conditioning == conditioning:
                return c
        raise KeyError((channel, conditioning))

    def to_json(self) -> dict:
        return {
            "channels": [asdict(c) for c in self.channels],
            "mean_raw": self.mean_raw,
            "mean_filtered": self.mean_filtered,
            "grade_raw": self.grade_raw,
            "grade_filtered": self.grade_filtered,
        }


@dataclass
class RatingTable:
    """All ratings of a campaign; ``channels`` in report order."""

    rows: list[RatingRow]
    channels: tuple[str, ...]
    config: RateConfig = field(default_factory=RateConfig)

    def trial_ids(self) -> list[str]:
        """Trial ids in first-seen order."""
        return list(dict.fromkeys(r.trial_id for r in self.rows))

    def values(self, channel: str, conditioning: str, what: str = "overall") -> np.ndarray:
        """One sub-rating of every trial for a channel and conditioning, shape (trials,)."""
        return np.array(
            [
                getattr(r, what)
                for r in self.rows
                if r.channel == channel and r.conditioning == conditioning
            ]
        )

    def summary(self) -> RatingSummary:
        """Means per channel and over channels, raw and filtered."""
        iso = self.config.iso
        per: list[ChannelSummary] = []
        means: dict[str, list[float]] = {c: [] for c in CONDITIONINGS}
        for cond in CONDITIONINGS:
            for ch in self.channels:
                vals = {k: self.values(ch, cond, k) for k in SUB_RATINGS}
                if vals["overall"].size == 0:
                    continue
                m = {k: float(v.mean()) for k, v in vals.items()}
                per.append(
                    ChannelSummary(
                        ch, cond, int(vals["overall"].size), **m, grade=grade_of(m["overall"], iso)
                    )
                )
                means[cond].append(m["overall"])
        raw = float(np.mean(means["raw"])) if means["raw"] else float("nan")
        filt = float(np.mean(means["filtered"])) if means["filtered"] else float("nan")
        return RatingSummary(tuple(per), raw, filt, grade_of(raw, iso), grade_of(filt, iso))

    def to_csv(self, path: str | Path) -> Path:
        """Write one line per rating (trial, channel, conditioning, sub-ratings, grade)."""
        p = Path(path)
        names = [f.name for f in fields(RatingRow)]
        with atomic_file(p) as tmp, tmp.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(names)
            for r in self.rows:
                w.writerow([_csv_value(getattr(r, n)) for n in names])
        return p

    def to_json(self) -> dict:
        """The whole table as one JSON-ready document: config, rows, summary."""
        return {
            "standard": "ISO/TS 18571:2014",
            "config": self.config.model_dump(mode="json"),
            "channels": list(self.channels),
            "rows": [asdict(r) for r in self.rows],
            "summary": self.summary().to_json(),
        }

    @classmethod
    def from_json(cls, doc: Mapping) -> RatingTable:
        """The table back from :meth:`to_json` (its rows, channels and config; the
        summary is recomputed from the rows)."""
        return cls([RatingRow(**r) for r in doc["rows"]], tuple(doc["channels"]),
                   RateConfig.model_validate(doc["config"]))

    def table(self) -> str:
        """A fixed-width text table of the summary."""
        s = self.summary()
        head = (
            f"{'channel':<10} {'cond':<9} {'n':>3} {'Z':>6} {'EP':>6} {'EM':>6} "
            f"{'ES':>6} {'R':>6}  grade"
        )
        lines = [head, "-" * len(head)]
        for c in s.channels:
            lines.append(
                f"{c.channel:<10} {c.conditioning:<9} {c.n_trials:>3} {c.corridor:>6.3f} "
                f"{c.phase:>6.3f} {c.magnitude:>6.3f} {c.slope:>6.3f} {c.overall:>6.3f}  "
                f"{c.grade}"
            )
        lines.append("-" * len(head))
        lines.append(
            f"mean over channels: raw {s.mean_raw:.3f} ({s.grade_raw}), "
            f"filtered {s.mean_filtered:.3f} ({s.grade_filtered})"
        )
        return "\n".join(lines)


def _csv_value(v):
    return f"{v:.6f}" if isinstance(v, float) else v


def rate_pair(
    trial_id: str, channel: str, measured, predicted, dt: float, config: RateConfig
) -> list[RatingRow]:
    """Rate one pair raw and filtered; two RatingRows."""
    return rate_trial(trial_id, {channel: (measured, predicted)}, dt, config)


def rate_trial(
    trial_id: str, pairs: Mapping[str, tuple], dt: float, config: RateConfig
) -> list[RatingRow]:
    """Rate a trial's pairs (channel -> (measured, predicted)) raw and filtered, all in
    one :func:`~parknss.metrics.iso18571.rate_many` call; per channel a raw then a
    filtered RatingRow, channels in the order of ``pairs``."""
    lp = config.lowpass
    rated, labels = [], []
    for channel, (measured, predicted) in pairs.items():
        label = f"trial {trial_id} channel {channel}"
        m = np.asarray(measured, dtype=np.float64)
        p = np.asarray(predicted, dtype=np.float64)
        rated.append((m, p))
        labels.append(f"{label} (raw)")
        fm = lowpass(m, dt, lp.cutoff_hz, lp.order, label=f"{label} measured")
        fp = lowpass(p, dt, lp.cutoff_hz, lp.order, label=f"{label} predicted")
        rated.append((fm, fp))
        labels.append(f"{label} (filtered)")
    ratings = rate_many(rated, dt, config.iso, labels)
    conds = ("raw", "filtered") * len(pairs)
    channels = [ch for ch in pairs for _ in range(2)]
    return [
        RatingRow(trial_id, ch, cond, **r.as_dict())
        for ch, cond, r in zip(channels, conds, ratings, strict=True)
    ]


def rate_campaign(
    pairs: PairMap,
    dt: float | Mapping[str, float] = DT,
    config: RateConfig | None = None,
    progress=None,
) -> RatingTable:
    """Rate every trial's channels raw and filtered.

    pairs: trial id -> channel -> (measured, predicted), arrays of shape (T,).
    dt: the grid spacing in s, one for all trials or per trial id.
    progress: optional callable(str) told about each trial as it is rated.
    Raises DataError naming the trial and channel when a pair is missing or malformed.
    """
    cfg = config or RateConfig()
    if not pairs:
        raise DataError("rating: no trials to rate")
    rows: list[RatingRow] = []
    for tid, chans in pairs.items():
        step = dt[tid] if isinstance(dt, Mapping) else dt
        for ch in cfg.channels:
            if ch not in chans:
                raise DataError(f"trial {tid}: channel {ch!r} missing from the pairs to rate")
        rows.extend(rate_trial(str(tid), {ch: chans[ch] for ch in cfg.channels},
                               float(step), cfg))
        if progress is not None:
            progress(f"rated {tid}")
    return RatingTable(rows, tuple(cfg.channels), cfg)


def truth_pairs(campaign: Iterable[Trial], channels: Sequence[str]) -> dict:
    """trial id -> channel -> (logged, truth_<channel>) of a synthetic campaign: the rating a
    perfect model would get (the ceiling set by sensor noise and the blind zone)."""
    return {tr.id: {ch: (tr[ch], tr.truth(ch)) for ch in channels} for tr in campaign}


def model_pairs(
    campaign: Iterable[Trial],
    predictions: Mapping[str, Mapping[str, np.ndarray]],
    channels: Sequence[str],
    model: object,
) -> dict:
    """trial id -> channel -> (logged, predicted); one-line DataError naming ``model`` for a
    trial or channel without a prediction."""
    pairs = {}
    for tr in campaign:
        pred = predictions.get(tr.id)
        if pred is None:
            raise DataError(f"{model}: no prediction for trial {tr.id}")
        missing = [ch for ch in channels if ch not in pred]
        if missing:
            raise DataError(f"{model}: trial {tr.id}: no prediction of {', '.join(missing)}")
        pairs[tr.id] = {ch: (tr[ch], pred[ch]) for ch in channels}
    return pairs
