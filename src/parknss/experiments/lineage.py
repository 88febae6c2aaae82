"""The store's lineage: which training-code versions compute the same numbers.

A stored fit is keyed by the training-code version it was fitted with
(:func:`~parknss.experiments.store.code_version`). An edit of the training code that
changes no number (an atomic write, a range check, an option defaulting to the old
behaviour) still changes the version. The lineage lets the store keep its fits across
such edits, on evidence: the canary (:mod:`parknss.experiments.canary`, tiny fits down
every code path the stored fits use) gives bit-identical results under both versions on
the same kind of machine.

Layout: ``<store>/lineage/<code version>.json``, one :class:`VersionRecord` per version
(one file each, so branches that record different versions merge without conflict):

* ``canaries``: the canary's digest under that version, one :class:`CanaryRecord` per
  machine kind (CPU model string) and canary definition (``spec``) it was run with,
  with the Python and torch versions, the git revision and when;
* ``equivalent_to``: the older versions it was found equal to (:class:`Equivalence`:
  which version, on which CPU, with which digest).

``parknss results canary --record`` records the current version's canary;
``parknss results migrate`` (:func:`migrate`) records it and, where the digest equals one
recorded for another version **on the same CPU model with the same canary definition**,
records the current version equivalent to that one. The store then answers a job from an
entry of the current version or of any version it is equivalent to, transitively
(:func:`accepted_versions`). A digest that differs records nothing but the canary: the
stored fits then stay stale, as without a lineage.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from parknss.errors import ParknssError

LINEAGE = "lineage"
"""The store's folder of :class:`VersionRecord` files."""


class LineageError(ParknssError):
    """A lineage file that does not read."""


@dataclass
class CanaryRecord:
    """The canary's ``digest`` under one code version on one machine (``cpu``: its
    model string; ``platform``, ``python``, ``torch``: as recorded), with the canary
    definition's ``spec`` digest and per-case digests."""

    digest: str
    spec: str
    cpu: str
    platform: str
    python: str
    torch: str
    git_revision: str
    recorded_utc: str
    seconds: float
    cases: dict[str, str] = field(default_factory=dict)


@dataclass
class Equivalence:
    """This version computes what ``version`` does: their canaries gave ``digest`` on
    ``cpu``."""

    version: str
    cpu: str
    digest: str
    recorded_utc: str


@dataclass
class VersionRecord:
    code_version: str
    canaries: list[CanaryRecord] = field(default_factory=list)
    equivalent_to: list[Equivalence] = field(default_factory=list)

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, doc: dict) -> VersionRecord:
        return cls(str(doc["code_version"]),
                   [CanaryRecord(**c) for c in doc.get("canaries", [])],
                   [Equivalence(**e) for e in doc.get("equivalent_to", [])])


def lineage_dir(root: str | Path) -> Path:
    return Path(root) / LINEAGE


def read_lineage(root: str | Path) -> dict[str, VersionRecord]:
    """Every version recorded in the store ``root`` (empty when none); a
    :class:`LineageError` naming a file that does not read."""
    out: dict[str, VersionRecord] = {}
    folder = lineage_dir(root)
    if not folder.is_dir():
        return out
    for p in sorted(folder.glob("*.json")):
        try:
            rec = VersionRecord.from_json(json.loads(p.read_text()))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise LineageError(f"{p}: not a lineage record ({exc.__class__.__name__}: "
                               f"{exc})") from exc
        if rec.code_version != p.stem:
            raise LineageError(f"{p}: records version {rec.code_version}, not {p.stem}")
        out[rec.code_version] = rec
    return out


def write_record(root: str | Path, rec: VersionRecord) -> Path:
    """Write ``rec`` to ``<root>/lineage/<version>.json`` atomically."""
    from parknss.nss.checkpoint import atomic_write_text

    p = lineage_dir(root) / f"{rec.code_version}.json"
    p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(p, json.dumps(rec.to_json(), indent=1, sort_keys=True) + "\n")
    return p


def accepted_versions(root: str | Path, current: str) -> list[str]:
    """``current`` and every version it is recorded equivalent to, transitively (either
    direction of an :class:`Equivalence`), ``current`` first, then sorted."""
    try:
        records = read_lineage(root)
    except LineageError:
        return [current]
    edges: dict[str, set[str]] = {}
    for rec in records.values():
        for eq in rec.equivalent_to:
            edges.setdefault(rec.code_version, set()).add(eq.version)
            edges.setdefault(eq.version, set()).add(rec.code_version)
    seen, todo = {current}, [current]
    while todo:
        for v in edges.get(todo.pop(), ()):
            if v not in seen:
                seen.add(v)
                todo.append(v)
    return [current, *sorted(seen - {current})]


def now_utc() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def canary_record(result, machine) -> CanaryRecord:
    """A :class:`CanaryRecord` of a :class:`~parknss.experiments.canary.CanaryResult` run
    here, on ``machine`` (:meth:`parknss.experiments.store.Machine.here`)."""
    import platform

    import torch

    from parknss.outputs import git_revision

    m = machine
    return CanaryRecord(result.digest, result.spec, m.cpu, m.platform,
                        platform.python_version(), torch.__version__, git_revision(),
                        now_utc(), round(result.seconds, 1), dict(result.cases))


def add_canary(rec: VersionRecord, can: CanaryRecord) -> None:
    """Add ``can`` to ``rec``, replacing a record of the same CPU, spec and digest."""
    rec.canaries = [c for c in rec.canaries
                    if (c.cpu, c.spec, c.digest) != (can.cpu, can.spec, can.digest)] + [can]


@dataclass
class Migration:
    """What :func:`migrate` found: the current ``version``, its canary, the versions it
    is (now) ``equivalent`` to directly, the versions whose canary on this CPU
    ``differs`` (version -> their digest), and ``accepted`` (transitively)."""

    version: str
    canary: CanaryRecord
    equivalent: list[str]
    differs: dict[str, str]
    accepted: list[str]
    own: list[str] = field(default_factory=list)
    """Digests recorded for this same version on this CPU before (a rerun)."""

    def lines(self) -> list[str]:
        c = self.canary
        out = [f"canary of code version {self.version} on {c.cpu}: {c.digest} "
               f"({c.seconds:.1f} s)"]
        out += [f"  equals the canary of {v}: fits of {v} are accepted"
                for v in self.equivalent]
        out += [f"  differs from the canary of {v} ({d}): its fits stay stale"
                for v, d in self.differs.items()]
        out += [f"  this version's canary recorded before on this CPU: {d} "
                f"({'equal' if d == c.digest else 'DIFFERS: not deterministic here?'})"
                for d in self.own]
        if not self.equivalent and not self.differs and not self.own:
            out.append(f"  no other version has a canary recorded on {c.cpu}: nothing "
                       "to compare with (run this on such a machine)")
        out.append("the store accepts fits of code versions: " + ", ".join(self.accepted))
        return out


def migrate(root: str | Path, version: str, can: CanaryRecord) -> Migration:
    """Record ``can`` (the canary of code ``version``, run here) in the store ``root`` and
    the version's equivalence to every other version whose canary on the same CPU model
    and canary definition has the same digest."""
    records = read_lineage(root)
    rec = records.get(version) or VersionRecord(version)
    own = sorted({c.digest for c in rec.canaries if c.cpu == can.cpu and c.spec == can.spec})
    add_canary(rec, can)
    equal, differs = [], {}
    for other in records.values():
        if other.code_version == version:
            continue
        same = [c for c in other.canaries if c.cpu == can.cpu and c.spec == can.spec]
        if any(c.digest == can.digest for c in same):
            equal.append(other.code_version)
        elif same:
            differs[other.code_version] = same[-1].digest
    for v in equal:
        if not any(e.version == v and e.cpu == can.cpu for e in rec.equivalent_to):
            rec.equivalent_to.append(Equivalence(v, can.cpu, can.digest, now_utc()))
    write_record(root, rec)
    return Migration(version, can, equal, differs, accepted_versions(root, version), own)


def describe(root: str | Path, current: str) -> str:
    """One line: which versions' fits the store accepts for code ``current`` and why."""
    accepted = accepted_versions(root, current)
    if len(accepted) == 1:
        return f"code version {current}; no lineage (fits of other versions are stale)"
    return (f"code version {current}; lineage accepts fits of {', '.join(accepted[1:])} "
            f"(canary digests equal, {LINEAGE}/)")
