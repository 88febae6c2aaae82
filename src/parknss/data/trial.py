"""Trial and Campaign: the in-memory form of field-test logs.

A Trial holds one maneuver's channels as float64 1-D arrays of equal length on a 100 Hz
grid, in schema units (see :mod:`parknss.signals`), plus metadata. A synthetic trial may
also carry noise-free ``truth_*`` channels; identification code must never read them.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from parknss.errors import DataError
from parknss.signals import DT, TRUTH_PREFIX

MANEUVER_CLASSES: tuple[str, ...] = (
    "park_in_left",
    "park_in_right",
    "park_out_left",
    "park_out_right",
)
UNLABELLED = "unlabelled"  # class of trials whose file names carry no <class>_r<N>


@dataclass
class Trial:
    """One logged maneuver.

    Attributes:
        id: unique name within its campaign (e.g. ``park_in_left_r1``).
        maneuver: one of MANEUVER_CLASSES (or a user's own class name, or UNLABELLED).
        repetition: repetition index within the class, from 1.
        channels: channel name -> float64 array of shape (T,), schema units.
        vehicle_id: which vehicle the log comes from.
        sample_rate_hz: nominal sample rate (100 Hz for the paper's data).
        provenance: where the data came from (file path, generator seed, ...).
    """

    id: str
    maneuver: str
    repetition: int
    channels: dict[str, np.ndarray]
    vehicle_id: str = "reference"
    sample_rate_hz: float = 100.0
    provenance: str = ""

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.channels[name]
        except KeyError:
            raise DataError(f"trial {self.id}: channel {name!r} missing") from None

    def __contains__(self, name: str) -> bool:
        return name in self.channels

    @property
    def n(self) -> int:
        """Number of samples T."""
        return len(self.channels["t"])

    @property
    def duration_s(self) -> float:
        return self.n * DT

    def array(self, names: Iterable[str]) -> np.ndarray:
        """Stack channels into shape (T, C), float64, in the order given."""
        return np.stack([self[nm] for nm in names], axis=-1)

    def logged_channels(self) -> list[str]:
        """Channel names without the ground-truth ``truth_*`` ones."""
        return [c for c in self.channels if not c.startswith(TRUTH_PREFIX)]

    def truth(self, name: str) -> np.ndarray:
        """The noise-free ``truth_<name>`` channel (synthetic trials only; evaluation only)."""
        key = TRUTH_PREFIX + name
        if key not in self.channels:
            raise DataError(
                f"trial {self.id}: no ground-truth channel {key!r} (real logs have none)"
            )
        return self.channels[key]

    def has_truth(self) -> bool:
        return any(c.startswith(TRUTH_PREFIX) for c in self.channels)

    def slice(self, start: int, stop: int) -> Trial:
        """A copy of samples [start, stop), time re-based to zero."""
        ch = {k: v[start:stop].copy() for k, v in self.channels.items()}
        ch["t"] = ch["t"] - ch["t"][0]
        return Trial(
            self.id,
            self.maneuver,
            self.repetition,
            ch,
            self.vehicle_id,
            self.sample_rate_hz,
            self.provenance,
        )


@dataclass
class Campaign:
    """An ordered set of trials from one vehicle, with free-form metadata."""

    trials: list[Trial]
    name: str = "campaign"
    meta: dict = field(default_factory=dict)

    def __iter__(self) -> Iterator[Trial]:
        return iter(self.trials)

    def __len__(self) -> int:
        return len(self.trials)

    def __getitem__(self, key: int | str) -> Trial:
        if isinstance(key, int):
            return self.trials[key]
        for tr in self.trials:
            if tr.id == key:
                return tr
        raise DataError(f"campaign {self.name}: no trial {key!r}")

    @property
    def ids(self) -> list[str]:
        return [tr.id for tr in self.trials]

    def classes(self) -> list[str]:
        """Maneuver classes in first-appearance order."""
        seen: dict[str, None] = {}
        for tr in self.trials:
            seen.setdefault(tr.maneuver, None)
        return list(seen)

    def by_class(self) -> dict[str, list[Trial]]:
        out: dict[str, list[Trial]] = {c: [] for c in self.classes()}
        for tr in self.trials:
            out[tr.maneuver].append(tr)
        for lst in out.values():
            lst.sort(key=lambda tr: tr.repetition)
        return out

    def subset(self, ids: Iterable[str]) -> Campaign:
        want = list(ids)
        return Campaign([self[i] for i in want], self.name, dict(self.meta))

    def data_hash(self) -> str:
        """SHA-256 over the logged (non-truth) channels of all trials, in order."""
        h = hashlib.sha256()
        for tr in self.trials:
            h.update(tr.id.encode())
            for name in sorted(tr.logged_channels()):
                h.update(name.encode())
                h.update(np.ascontiguousarray(tr.channels[name], dtype=np.float64).tobytes())
        return h.hexdigest()
