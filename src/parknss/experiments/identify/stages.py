"""The stage book of ``parknss identify``: one durable record per stage, skip and resume.

Each stage of the pipeline has a record ``CAR/stages/<stage>.json`` (:class:`StageRecord`)
holding the stage's **inputs** (the digests of what it reads: the campaign's data hash,
the fitted NSS's manifest, the options that decide its numbers, the code version where
it matters) and their digest, its status, its **product** (paths and the numbers the
model card reads) and, when a product was taken over rather than computed, **why**.

:meth:`StageBook.run` decides per stage:

* ``done`` with the same inputs digest: skipped (its product is reused as it is);
* ``running`` with the same digest (a run was interrupted inside it): the stage runs again
  and resumes from what its own mechanism kept (the NSS's training state, the run folders
  of the grid and the fidelity, cell by cell);
* otherwise (new, or inputs changed): the stage runs from the start, replacing its old
  products (``fresh``).

The record is written atomically before the body (``running``) and after it (``done``),
so a kill at any instant leaves a record that says which of the three applies. The crash
point ``identify.stage`` (:mod:`parknss.durable`) sits between a finished body and its
``done`` record, where the tests kill the process.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from parknss import durable
from parknss.outputs import plain_json, write_text_atomic

Say = Callable[[str], None]


def digest_of(inputs: Mapping[str, Any]) -> str:
    """The 16-hex digest of a stage's inputs (sorted-key JSON of
    :func:`parknss.outputs.plain_json`)."""
    blob = json.dumps(plain_json(inputs), sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def fmt_s(s: float) -> str:
    """Seconds as ``45 s``, ``12 min`` or ``1 h 58 min``."""
    s = max(0.0, float(s))
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


@dataclass
class StageRecord:
    """One stage's durable record (see the module doc). ``wall_s``: the wall seconds of
    the last body run (summed over resumed sittings in ``wall_total_s``)."""

    stage: str
    digest: str
    inputs: dict
    status: str = "running"
    sittings: int = 0
    started_utc: str = ""
    finished_utc: str | None = None
    wall_s: float = 0.0
    wall_total_s: float = 0.0
    product: dict = field(default_factory=dict)
    reused: str | None = None

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, doc: dict) -> StageRecord:
        return cls(**{k: doc[k] for k in cls.__dataclass_fields__ if k in doc})


@dataclass
class StageOutcome:
    """What a stage body returns: its ``product`` and, when it took a product over rather
    than computing it, ``reused`` (why, in one line)."""

    product: dict
    reused: str | None = None


def _same_inputs(recorded: Mapping[str, Any], now: Mapping[str, Any],
                 equivalent: Mapping[str, Callable[[Any, Any], bool]]) -> bool:
    """Every input equal, or equivalent by its ``equivalent`` rule."""
    if set(recorded) != set(now):
        return False
    return all(recorded[k] == now[k] or (k in equivalent and equivalent[k](recorded[k], now[k]))
               for k in now)


class StageBook:
    """The records of one car folder and the progress display (stderr lines via ``say``)."""

    def __init__(self, car: Path, say: Say, estimates: Mapping[str, float],
                 order: tuple[str, ...]) -> None:
        self.car, self.say, self.estimates, self.order = car, say, dict(estimates), order
        self.t0 = time.perf_counter()
        self.log: list[dict] = []

    def path(self, stage: str) -> Path:
        return self.car / "stages" / f"{stage}.json"

    def read(self, stage: str) -> StageRecord | None:
        """The stage's record, or None (none yet, or a file that does not read: the stage
        then runs again from the start, which is always correct)."""
        try:
            doc = json.loads(self.path(stage).read_text())
            return StageRecord.from_json(doc) if doc.get("stage") == stage else None
        except (OSError, ValueError, TypeError, AttributeError):
            return None

    def _write(self, rec: StageRecord) -> None:
        write_text_atomic(self.path(rec.stage), json.dumps(rec.to_json(), indent=1,
                                                           default=str) + "\n")

    def _left(self, stage: str) -> float:
        i = self.order.index(stage)
        return sum(self.estimates.get(s, 0.0) for s in self.order[i:])

    def run(self, stage: str, inputs: Mapping[str, Any],
            body: Callable[[bool], StageOutcome],
            equivalent: Mapping[str, Callable[[Any, Any], bool]] | None = None
            ) -> StageRecord:
        """Skip, resume or run ``stage`` (module doc); ``body(fresh)`` computes it
        (``fresh``: replace whatever an earlier run of the stage left). ``equivalent``
        maps an input name to ``same(recorded, now)``: a recorded input that differs but
        is equivalent (e.g. a training-code version the canary lineage accepts) still
        counts as the same, and the record keeps what it recorded."""
        n, i = len(self.order), self.order.index(stage) + 1
        head = f"stage {i}/{n} {stage}"
        inputs = plain_json(dict(inputs))
        digest = digest_of(inputs)
        old = self.read(stage)
        if old is not None and old.digest != digest and equivalent and _same_inputs(
                old.inputs, inputs, equivalent):
            inputs, digest = dict(old.inputs), old.digest
        if old is not None and old.status == "done" and old.digest == digest:
            why = f" ({old.reused})" if old.reused else ""
            self.say(f"{head}: finished earlier with the same inputs, skipped{why}")
            self.log.append({"stage": stage, "action": "skipped", "reused": old.reused})
            return old
        resumed = old is not None and old.status == "running" and old.digest == digest
        if resumed:
            action = "resuming the interrupted stage"
        elif old is not None:
            changed = sorted(k for k in set(inputs) | set(old.inputs)
                             if inputs.get(k) != old.inputs.get(k))
            action = f"inputs changed ({', '.join(changed) or 'format'}), running it again"
        else:
            action = "running"
        est = self.estimates.get(stage, 0.0)
        self.say(f"{head}: {action}; estimate {fmt_s(est)} for it, about "
                 f"{fmt_s(self._left(stage))} left in all ({fmt_s(time.perf_counter() - self.t0)}"
                 " elapsed)")
        rec = StageRecord(stage, digest, inputs, started_utc=_now(),
                          sittings=(old.sittings if resumed else 0) + 1,
                          wall_total_s=old.wall_total_s if resumed else 0.0)
        self._write(rec)
        t0 = time.perf_counter()
        outcome = body(not resumed)
        durable.crash_point("identify.stage")
        rec.wall_s = time.perf_counter() - t0
        rec.wall_total_s += rec.wall_s
        rec.status, rec.finished_utc = "done", _now()
        rec.product, rec.reused = plain_json(outcome.product), outcome.reused
        self._write(rec)
        done = f"reused: {outcome.reused}" if outcome.reused else f"done in {fmt_s(rec.wall_s)}"
        self.say(f"{head}: {done}")
        self.log.append({"stage": stage, "action": "reused" if outcome.reused else
                         ("resumed" if resumed else "ran"), "wall_s": rec.wall_s,
                         "reused": outcome.reused})
        return rec
