"""Parked training states: an unfinished study fit carried from one sitting to the next.

A study fit (a job of :data:`~parknss.experiments.jobs.STATEFUL_JOBS`) checkpoints its
resumable training state (:mod:`parknss.nss.train_state`: ``train_state.json`` and the
tensor file it names, about 2 MB for the paper's 6x128 net) in its run folder,
``OUT/state/<folder>/``, every ``train.checkpoint_every`` steps. Run folders are scratch
(``runs/`` is not committed, and a fresh checkout has none), so a paper-recipe fit (about
one CPU hour here) still running when a sitting ends would start over at step 0 in the
next. Parking carries it over:

* When the executor is about to compute a job, the store labels its state folder with
  ``job.json`` (:data:`JOB_FILE`: the job's function, arguments, name and **store key**,
  the key its result will be stored under: the job, the campaign's data hash and the
  training-code version; :func:`label`).
* ``parknss results park OUT`` copies the state of every labelled fit of run folder ``OUT``
  that the store does not hold yet into ``<store>/inflight/<store key>/`` (the newest
  generation's JSON and tensor file, and ``job.json``; :func:`park_run`), to be committed
  with the store. A state is copied only when it is further along than the one already
  parked, and only whole: the tensor file's SHA-256 must match the one its JSON records (a
  fit that checkpoints during the copy is copied again).
* A later run of a job with that key, in any run folder and on any machine with the same
  training code, starts from the parked state when it is further along than its own
  folder's (:func:`seed`); the fit checks the state's fingerprint (config, data, split)
  again when it loads it, so a parked state is resumed only by its own fit. The fit's CPU
  and wall time carry over (the state holds them), so its stored result counts the whole
  fit; its provenance names the machine that finished it.
* When the fit's result enters the store, its parked state is removed (:func:`unpark`).

A parked state is filed under the key of the job that fitted it: a fold fit parked by the
limiter study (whose jobs fit their fold through the fold job) resumes the limiter job of
that fold, not a bare fold job of the same arguments.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from parknss import durable
from parknss.errors import CheckpointError
from parknss.nss import state_files
from parknss.nss.state_files import FORMAT, META

INFLIGHT = "inflight"
"""The store's folder of parked states: ``<store>/inflight/<store key>/``."""
JOB_FILE = "job.json"
"""The label of a state folder: ``{"fn", "kwargs", "name", "key"}`` of the job it fits."""
SITTINGS = "sittings.json"
"""The sittings of a state folder's fit, oldest first (:func:`add_sitting`): carried with
the state when it is parked and seeded, and recorded in the stored result's provenance."""
COPY_TRIES = 3
"""Copies of a state that a checkpoint write tore before :func:`copy_state` gives up."""


@dataclass
class StateInfo:
    """A state folder as the JSON halves read: the job's ``name``, ``fn`` and store
    ``key`` (from ``job.json``), the last step written and the fit's CPU and wall seconds
    so far (``cpu_s`` None: a state written without it)."""

    folder: Path
    key: str
    fn: str
    name: str
    step: int
    cpu_s: float | None
    wall_s: float

    def line(self) -> str:
        cpu = "-" if self.cpu_s is None else f"{self.cpu_s:.0f}"
        return f"{self.name:<40} step {self.step:>6}  cpu {cpu:>6} s"


def _write_json(path: Path, doc: Any) -> None:
    """Write ``doc`` as sorted, indented JSON to ``path`` durably."""
    durable.write_bytes(path, (json.dumps(doc, indent=1, sort_keys=True) + "\n").encode())


def label(folder: str | Path, fn: str, kwargs: Mapping[str, Any], name: str, key: str) -> None:
    """Write ``job.json`` into the state ``folder`` (created): which job, under which store
    key, fits there."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"fn": fn, "kwargs": dict(kwargs), "name": name, "key": key}
    _write_json(folder / JOB_FILE, doc)


def read_step(folder: Path) -> int | None:
    """The step of the training state in ``folder`` (None: no readable state)."""
    try:
        meta = json.loads((folder / META).read_text())
        return int(meta["epoch"]) if meta.get("format") == FORMAT else None
    except (OSError, ValueError, KeyError, TypeError):
        return None


def read_info(folder: Path) -> StateInfo:
    """The labelled state in ``folder``; a :class:`CheckpointError` saying what is missing
    or unreadable (no label, no state, a torn pair)."""
    try:
        job = json.loads((folder / JOB_FILE).read_text())
        fn, name, key = str(job["fn"]), str(job.get("name", "")), str(job["key"])
    except FileNotFoundError as exc:
        raise CheckpointError(f"{folder}: no {JOB_FILE} (a fit started before parking "
                              "existed, or not a study fit)") from exc
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CheckpointError(f"{folder / JOB_FILE}: unreadable ({exc})") from exc
    try:
        meta = json.loads((folder / META).read_text())
        if meta.get("format") != FORMAT:
            raise ValueError("not a parknss training state")
        step, wall = int(meta["epoch"]), float(meta["wall_s"])
        cpu = None if meta.get("cpu_s") is None else float(meta["cpu_s"])
        sha = meta["sha256"]
        tensors = folder / state_files.tensors_name(meta)
    except FileNotFoundError as exc:
        raise CheckpointError(f"{folder}: no training state written yet") from exc
    except (OSError, ValueError, KeyError, TypeError, AttributeError, CheckpointError) as exc:
        raise CheckpointError(f"{folder / META}: unreadable ({exc})") from exc
    if not tensors.is_file() or durable.sha256_file(tensors) != sha:
        raise CheckpointError(f"{tensors}: missing or does not match its {META} (torn)")
    return StateInfo(folder, key, fn, name or key, step, cpu, wall)


def copy_state(src: Path, dst: Path) -> StateInfo:
    """Copy the labelled state ``src`` to ``dst`` whole (replacing it): into a sibling
    temporary folder, checked with :func:`read_info`, then committed in ``dst`` as its
    newest generation (:func:`parknss.nss.state_files.commit`); a copy that a
    checkpoint write in ``src`` tore is made again, up to :data:`COPY_TRIES` times."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(dst.name + ".tmp")
    last: CheckpointError | None = None
    for _ in range(COPY_TRIES):
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        try:
            meta = (src / META).read_bytes()  # the JSON first: it names the tensor file
            (tmp / META).write_bytes(meta)
            tensors = state_files.tensors_name(json.loads(meta))
            for name in (JOB_FILE, tensors):
                shutil.copyfile(src / name, tmp / name)
            if (src / SITTINGS).is_file():
                shutil.copyfile(src / SITTINGS, tmp / SITTINGS)
            info = read_info(tmp)
        except (OSError, ValueError, AttributeError, CheckpointError) as exc:
            last = exc if isinstance(exc, CheckpointError) else CheckpointError(str(exc))
            continue
        # into dst as its newest generation: the state parked there before stays whole
        # until the commit (state_files.commit), so a kill never loses both; then only the
        # new one is kept (what is committed to git)
        dst.mkdir(parents=True, exist_ok=True)
        for name in (JOB_FILE, tensors):
            durable.write_bytes(dst / name, (tmp / name).read_bytes())
        if (tmp / SITTINGS).is_file():
            durable.write_bytes(dst / SITTINGS, (tmp / SITTINGS).read_bytes())
        state_files.commit(dst, meta, keep_previous=False)
        shutil.rmtree(tmp, ignore_errors=True)
        info.folder = dst
        return info
    shutil.rmtree(tmp, ignore_errors=True)
    raise CheckpointError(f"{src}: the state changed during {COPY_TRIES} copies ({last})")


def parked_dir(root: Path, key: str) -> Path:
    return Path(root) / INFLIGHT / key


def seed(root: Path, key: str, state_dir: str | Path) -> StateInfo | None:
    """Copy the state parked under ``key`` in the store ``root`` into ``state_dir`` when it
    is further along than the state there (or there is none); the parked state's info, or
    None when nothing was copied. A parked state that does not read is left alone (and
    reported by ``parknss results verify``); the fit then runs from its own folder."""
    src, dst = parked_dir(root, key), Path(state_dir)
    if not (src / META).is_file():
        return None
    try:
        info = read_info(src)
    except CheckpointError:
        return None
    if info.key != key:
        return None
    own = read_step(dst)
    if own is not None and own >= info.step:
        return None
    dst.mkdir(parents=True, exist_ok=True)
    try:
        meta = (src / META).read_bytes()
        name = state_files.tensors_name(json.loads(meta))
        blob = (src / name).read_bytes()
    except (OSError, ValueError, AttributeError, CheckpointError):
        return None
    if json.loads(meta).get("sha256") != hashlib.sha256(blob).hexdigest():
        return None
    # the tensors first, then the JSON committed as the newest generation (train_state)
    durable.write_bytes(dst / name, blob)
    if (src / SITTINGS).is_file():
        durable.write_bytes(dst / SITTINGS, (src / SITTINGS).read_bytes())
    state_files.commit(dst, meta)
    return info


def read_sittings(folder: str | Path) -> list[dict]:
    """The sittings recorded in the state ``folder`` (empty: none, or unreadable)."""
    try:
        doc = json.loads((Path(folder) / SITTINGS).read_text())
    except (OSError, ValueError):
        return []
    return [s for s in doc if isinstance(s, dict)] if isinstance(doc, list) else []


def add_sitting(folder: str | Path, sitting: dict) -> None:
    """Append ``sitting`` (where and with what this sitting of the fit runs) to the
    state ``folder``'s :data:`SITTINGS`, with the step it starts from."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rows = [*read_sittings(folder), {**sitting, "from_step": read_step(folder) or 0}]
    _write_json(folder / SITTINGS, rows)


def unpark(root: Path, key: str) -> bool:
    """Remove the state parked under ``key`` (its fit is stored); True if there was one."""
    p = parked_dir(root, key)
    if not p.exists():
        return False
    shutil.rmtree(p)
    return True


@dataclass
class ParkOutcome:
    """What :func:`park_run` did with one state folder: ``parked`` (the copy's info) or
    ``why`` it did not."""

    folder: Path
    parked: StateInfo | None = None
    why: str = ""

    def line(self) -> str:
        if self.parked is not None:
            return f"parked  {self.parked.line()}  -> {INFLIGHT}/{self.parked.key}"
        return f"skipped {self.folder.name}: {self.why}"


def is_stored(root: Path, key: str) -> bool:
    """Whether the store ``root`` holds an entry under ``key`` (any job function)."""
    root = Path(root)
    return root.is_dir() and any(
        p.is_dir() and p.name != INFLIGHT and (p / f"{key}.json").is_file()
        for p in root.iterdir())


def park_run(out_dir: str | Path, root: Path) -> list[ParkOutcome]:
    """Park every labelled state of the run folder ``out_dir`` (``OUT/state/*``) in the
    store ``root``: those whose fit the store holds are skipped, as are those no further
    along than the state already parked under their key."""
    states = Path(out_dir) / "state"
    if not states.is_dir():
        raise CheckpointError(f"{states} does not exist: no fit of this run has written a "
                              "training state (is it a parknss reproduce or study run folder?)")
    out = []
    for folder in sorted(p for p in states.iterdir() if p.is_dir()):
        try:
            info = read_info(folder)
        except CheckpointError as exc:
            out.append(ParkOutcome(folder, why=str(exc).removeprefix(f"{folder}: ")))
            continue
        if is_stored(root, info.key):
            out.append(ParkOutcome(folder, why=f"{info.name}: finished, in the store"))
            continue
        there = read_step(parked_dir(root, info.key))
        if there is not None and there >= info.step:
            out.append(ParkOutcome(folder, why=f"{info.name}: the parked state is at step "
                                               f"{there}, this one at {info.step}"))
            continue
        out.append(ParkOutcome(folder, parked=copy_state(folder, parked_dir(root, info.key))))
    return out


def parked_states(root: Path) -> list[tuple[Path, StateInfo | str]]:
    """Every folder under ``<root>/inflight`` with its info, or why it is not a valid
    parked state (unreadable, torn, or filed under another key than its label's)."""
    out: list[tuple[Path, StateInfo | str]] = []
    base = Path(root) / INFLIGHT
    if not base.is_dir():
        return out
    for p in sorted(base.iterdir()):
        if not p.is_dir() or p.name.endswith(".tmp"):
            out.append((p, "not a parked state folder"))
            continue
        try:
            info = read_info(p)
        except CheckpointError as exc:
            out.append((p, str(exc)))
            continue
        out.append((p, info if info.key == p.name else
                    f"labelled with key {info.key}: belongs at {INFLIGHT}/{info.key}"))
    return out


def listing(root: Path) -> tuple[list[str], list[str]]:
    """(one line per parked state, one line per invalid folder) under ``<root>/inflight``."""
    rows, bad = [], []
    for p, info in parked_states(root):
        if isinstance(info, str):
            bad.append(f"{p.relative_to(root)}: {info}")
        else:
            rows.append(f"{INFLIGHT}/{info.key}  {info.line()}  (unfinished)")
    return rows, bad
