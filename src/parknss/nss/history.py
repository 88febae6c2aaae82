"""Loss history of a fit and the smoothed best-checkpoint criterion (paper §IV-B, Fig. 4).

Each epoch gets a row of training-loss terms; every ``val_every`` epochs a validation
row (open-loop rollout of the held-out trials over their whole length) adds the
moving-region state and output losses. The criterion is the raw validation state loss,
or the training loss when there is no validation set (deployment fit), smoothed by a
trailing moving average over ``window`` points; the best checkpoint is the weights at
the epoch where the smoothed criterion is lowest so far.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass
class History:
    """Per-epoch rows (dicts of floats, JSON-ready) and the criterion series."""

    criterion: str
    window: int
    rows: list[dict] = field(default_factory=list)
    crit_epochs: list[int] = field(default_factory=list)
    crit_raw: list[float] = field(default_factory=list)
    crit_smooth: list[float] = field(default_factory=list)

    def add_row(self, row: dict) -> None:
        self.rows.append(row)

    def add_criterion(self, epoch: int, value: float) -> float:
        """Record a raw criterion point; return its trailing moving average."""
        self.crit_epochs.append(epoch)
        self.crit_raw.append(value)
        tail = self.crit_raw[-self.window :]
        sm = math.fsum(tail) / len(tail)
        self.crit_smooth.append(sm)
        return sm

    def best(self) -> tuple[int, float]:
        """(epoch, smoothed value) of the lowest smoothed criterion; (0, inf) if none."""
        if not self.crit_smooth:
            return 0, math.inf
        i = min(range(len(self.crit_smooth)), key=lambda j: (self.crit_smooth[j], j))
        return self.crit_epochs[i], self.crit_smooth[i]

    def to_json(self) -> dict:
        return {
            "criterion": self.criterion,
            "window": self.window,
            "rows": self.rows,
            "crit_epochs": self.crit_epochs,
            "crit_raw": self.crit_raw,
            "crit_smooth": self.crit_smooth,
        }

    @classmethod
    def from_json(cls, d: dict) -> History:
        return cls(
            d["criterion"],
            int(d["window"]),
            list(d["rows"]),
            [int(e) for e in d["crit_epochs"]],
            [float(v) for v in d["crit_raw"]],
            [float(v) for v in d["crit_smooth"]],
        )
