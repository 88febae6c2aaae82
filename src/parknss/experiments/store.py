"""The result store: every study fit's scores, kept in the repository as small JSON files.

A fit (an executor :class:`~parknss.executor.Job`, e.g. a
:func:`~parknss.experiments.folds.fold_job`) is stored under a key that hashes three
things: the job (its function and the keyword arguments that decide its numbers, the
function's defaults filled in, see :func:`bound_kwargs` and :func:`key_kwargs`), the
**data hash** of the campaign it reads (:meth:`parknss.data.trial.Campaign.data_hash`,
once per campaign and store) and the **training code version** (:func:`code_version`:
a hash of the code of the files in :data:`CODE_FILES`, less comments and docstrings, the
code that decides a fit's numbers; the
NSS config's values enter through the job, resolved). A changed campaign or an edited
training file therefore misses, and the fit runs again.

Layout: ``<store>/<function>/<key>.json``, one :class:`StoreEntry` per fit: the key, the
job, the data hash, the code version, the job's JSON result (scores; never weights) and
its :class:`Provenance` (git revision, the resolved NSS config, machine, Python and torch
versions, wall and CPU time, when it finished). Files are written atomically.

Where it is (:func:`store_dir`): ``--store DIR`` (or ``off``), else the environment variable
``PARKNSS_RESULTS``, else ``store.dir`` of configs/experiments.yaml: ``auto`` is the
checkout's ``results/`` (beside ``src/``), off when parknss runs from an installed wheel.
``parknss reproduce`` and ``parknss study`` read the run folder's cache, then the store,
then fit (:func:`open_store`: ``refit`` skips store hits but still writes; ``--quick`` runs
read but do not write, unless ``store.write_quick``). A store file that does not parse or
does not match its key is ignored with a one-line warning and refitted (overwritten);
``parknss results verify`` reports such files.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from parknss.config import PACKAGE_DIR, REPO_ROOT
from parknss.errors import ConfigError
from parknss.executor import Job, resolve
from parknss.experiments.jobs import ALIASES

ENV_VAR = "PARKNSS_RESULTS"
OFF = "off"
AUTO = "auto"

CODE_FILES: tuple[str, ...] = (
    "nss/*.py",  # the model, the fused engine, losses, training, limiter, linear baseline
    "data/trial.py",  # trials and campaigns
    "data/normalize.py",  # the normalizers
    "data/windows.py",  # the training windows
    "data/decimate.py",  # the coarse grid of the coarse-to-fine recipe
    "data/splits.py",  # which trials a fold trains and scores on
    "metrics/errors.py",  # the scores
    "signals.py",  # units, the blind zone, the MSE factors
    "vehicle.py",  # the kinematic prior of the residual yaw readout
    "cbuild.py",  # the compiler flags of the native fused kernels (nss/fused_native.py)
    "experiments/folds.py",  # the fold job and the limiter job
)
"""The training code: files (globs) under ``src/parknss/`` whose edits change a fit's
numbers. Editing their code changes :func:`code_version`, so every stored fit misses;
comments, docstrings and blank lines are not part of it (:func:`code_tokens`), so a
corrected docstring keeps the store.
Not listed: ``nss/config.py`` and ``configs/nss.yaml``, the NSS config's defaults: an NSS
fit's key holds the config it resolves to (:func:`key_kwargs`), so a changed default
misses exactly the fits it changes (tuning the fast recipe's defaults keeps the paper
recipe's fits, which do not read them)."""
CODE_EXCLUDED: tuple[str, ...] = ("nss/config.py",)



@dataclass(frozen=True)
class Derived:
    """A stored job that is not an NSS fit (:mod:`parknss.experiments.derived`): the
    ``code`` it runs (globs under ``src/parknss/``, hashed by :func:`code_version` in
    place of :data:`CODE_FILES`), the function (``"module:function"``) giving the content
    digests of what it reads besides its arguments (added to its key as ``inputs``), and
    whether it reads the campaign (else its data hash is :data:`NO_DATA`)."""

    code: tuple[str, ...]
    inputs: str
    reads_data: bool
    same_inputs: tuple[str, ...] = ()
    """Arguments that do not change what the job reads (a grid cell's index): its input
    digests are computed once for all their values."""


NO_DATA = "none"
"""The data hash of a stored job that reads no campaign (a closed-loop grid cell)."""

DERIVED: dict[str, Derived] = {
    "parknss.sim.grid:cell_job": Derived(
        ("sim/*.py", "sim/*/*.py", "chain/*.py", "actuators/*.py", "nss/*.py",
         "reference/*.py", "plant.py", "vehicle.py", "signals.py", "data/trial.py",
         "data/normalize.py"),
        "parknss.experiments.derived:cell_inputs", False, ("grid", "index")),
    "parknss.experiments.derived:ladder_job": Derived(
        ("experiments/derived.py", "chain/*.py", "actuators/*.py", "nss/*.py", "data/trial.py",
         "data/normalize.py", "data/windows.py", "data/io.py", "metrics/errors.py",
         "signals.py", "vehicle.py"),
        "parknss.experiments.derived:ladder_inputs", True),
    "parknss.experiments.derived:rating_job": Derived(
        ("experiments/derived.py", "metrics/*.py", "chain/*.py", "actuators/*.py", "nss/*.py",
         "data/trial.py", "data/io.py", "signals.py", "vehicle.py"),
        "parknss.experiments.derived:rating_inputs", True),
}
"""The report's stored results that are not NSS fits: Table V's grid cells, Table IV's
ladder of a chain artefact, Fig. 7's ratings (:mod:`parknss.experiments.derived`)."""

_DERIVED_CODES: dict[str, str] = {}


def job_code_version(fn: str) -> str:
    """The code version of job ``fn``: :func:`code_version` of its :data:`DERIVED` code,
    else of the training code (:data:`CODE_FILES`); computed once per process."""
    if fn not in _DERIVED_CODES:
        d = DERIVED.get(fn)
        _DERIVED_CODES[fn] = code_version(patterns=d.code) if d else code_version()
    return _DERIVED_CODES[fn]


KEY_IGNORED: tuple[str, ...] = ("data", "save_dir", "progress", "state_dir")
"""Job arguments that do not decide its numbers: the campaign folder (its content is the
data hash), where a model is saved, the progress bar."""


def code_files(root: Path = PACKAGE_DIR, patterns: tuple[str, ...] = CODE_FILES) -> list[Path]:
    """The files of :data:`CODE_FILES` under ``root`` but :data:`CODE_EXCLUDED`, sorted."""
    files = {p for pat in patterns for p in root.glob(pat) if p.is_file()}
    skip = {root / x for x in CODE_EXCLUDED}
    return sorted(files - skip)


def _chars(line: str, col_bytes: int) -> int:
    """The character column of ``ast``'s UTF-8 byte column ``col_bytes`` in ``line``."""
    return len(line.encode()[:col_bytes].decode(errors="ignore"))


def code_tokens(source: str) -> bytes:
    """``source`` with what does not run removed: comments, the docstrings of the module,
    its classes and functions, trailing spaces and blank lines. The ranges come from
    ``ast`` (docstrings) and ``tokenize`` (comments), whose positions are the same on
    every Python version that parses the file, so the hash is shared across machines."""
    import ast
    import io
    import tokenize

    lines = source.splitlines()
    cuts = []
    for node in ast.walk(ast.parse(source)):
        body = getattr(node, "body", None)
        if (isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            d = body[0]
            cuts.append(((d.lineno, _chars(lines[d.lineno - 1], d.col_offset)),
                         (d.end_lineno, _chars(lines[d.end_lineno - 1], d.end_col_offset))))
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            cuts.append((tok.start, tok.end))
    for (r0, c0), (r1, c1) in sorted(cuts, reverse=True):  # rows 1-based, columns 0-based
        lines[r0 - 1 : r1] = [lines[r0 - 1][:c0] + lines[r1 - 1][c1:]]
    return "\n".join(ln.rstrip() for ln in lines if ln.strip()).encode()


def code_version(root: Path = PACKAGE_DIR, patterns: tuple[str, ...] = CODE_FILES) -> str:
    """Hash of the training code: the relative paths of :func:`code_files` and their
    :func:`code_tokens`."""
    h = hashlib.sha256()
    for p in code_files(root, patterns):
        h.update(p.relative_to(root).as_posix().encode() + b"\0")
        h.update(code_tokens(p.read_text(encoding="utf-8")) + b"\0")
    return h.hexdigest()[:16]


def _file_digest(path: str | Path) -> str:
    try:
        return "sha256:" + hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the job's config ({exc.strerror})") from exc


def bound_kwargs(fn: str, kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """``kwargs`` as the job function sees them: its defaults filled in (so a job that
    spells out ``r=1`` and one that leaves it to the default are the same fit). Arguments
    the function does not take are left for the job itself to refuse."""
    import inspect

    kwargs = {k: v for k, v in kwargs.items() if k not in KEY_IGNORED}
    try:
        sig = inspect.signature(resolve(fn))
        bound = sig.bind_partial(**kwargs)
    except (ConfigError, TypeError, ValueError):
        return dict(kwargs)
    bound.apply_defaults()
    return dict(bound.arguments)


def key_kwargs(kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """The arguments that decide a job's numbers: :data:`KEY_IGNORED` dropped; an NSS fit's
    ``config`` file and ``overrides`` replaced by the config they resolve to
    (:func:`~parknss.nss.config.fit_identity`), so that two studies asking for the same fit
    in other words (``parknss cv`` with no overrides, ``reproduce`` with the cap spelled
    out) share one entry; another job's ``config`` file named by the hash of its content."""
    out = {k: v for k, v in kwargs.items() if k not in KEY_IGNORED}
    if "overrides" in out:
        from parknss.experiments.folds import fold_config
        from parknss.nss.config import fit_identity

        cfg = fold_config(out.pop("config", None), out.pop("overrides"))
        out["nss"] = fit_identity(cfg)
    elif out.get("config") is not None:
        out["config"] = _file_digest(out["config"])
    return out


def fit_key(fn: str, kwargs: Mapping[str, Any]) -> str:
    """The identity of the fit a job makes, data and code aside: the hash of its
    :func:`key_kwargs` with the function's defaults filled in. Names the folder of a sweep
    fit's resumable training state, so that two spellings of one fit share it and a fit
    whose resolved config changed (a default retuned) gets a fresh one instead of a
    state it would refuse."""
    doc = {"fn": fn, "kwargs": key_kwargs(bound_kwargs(fn, kwargs))}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:24]


def store_key(fn: str, kwargs: Mapping[str, Any], data_hash: str, code: str) -> str:
    """The store key of a job (``kwargs`` from :func:`key_kwargs`)."""
    doc = {"fn": fn, "kwargs": kwargs, "data_hash": data_hash, "code_version": code}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:24]


def short_name(fn: str) -> str:
    """The store folder of a job function: ``"pkg.mod:fold_job"`` -> ``"fold_job"``."""
    return fn.rpartition(":")[2] or fn


@dataclass
class Machine:
    platform: str
    cpu: str
    cores: int

    @classmethod
    def here(cls) -> Machine:
        cpu = platform.processor()
        try:
            for line in Path("/proc/cpuinfo").read_text().splitlines():
                if line.startswith("model name"):
                    cpu = line.partition(":")[2].strip()
                    break
        except OSError:
            pass
        return cls(platform.platform(), cpu or "unknown", os.cpu_count() or 1)


@dataclass
class Provenance:
    """Where and how a stored result was computed. ``wall_s``/``cpu_s``: the run of the
    job that stored it; a fit resumed from its training state counts from its resumption
    (the fit's own total is in its result, :func:`fit_cpu_s`)."""

    git_revision: str
    dirty: bool
    machine: Machine
    python: str
    torch: str
    wall_s: float
    cpu_s: float
    finished_utc: str
    data: str | None
    config: dict | None
    sittings: list[dict] | None = None
    """Every sitting of a fit resumed from its training state, oldest first: machine,
    Python, torch, git revision and the step it started from (:func:`sittings`); None
    for fits stored before sittings were recorded."""


def content_digest(doc: Mapping[str, Any]) -> str:
    """The SHA-256 of a store file's JSON ``doc`` less its ``digest`` field (key, job,
    data hash, code version, result with every score, provenance), canonical JSON."""
    body = {k: v for k, v in doc.items() if k != "digest"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


def digest_problem(doc: Mapping[str, Any]) -> str | None:
    """Why the file ``doc`` fails its content digest (None: it matches)."""
    got = doc.get("digest")
    if got is None:
        return "no content digest (stored before digests; parknss results seal adds it)"
    if got != content_digest(doc):
        return "its content does not match its digest (edited after it was stored)"
    return None


@dataclass
class StoreEntry:
    """One stored fit (one JSON file)."""

    key: str
    fn: str
    kwargs: dict[str, Any]
    name: str
    data_hash: str
    code_version: str
    result: Any
    provenance: Provenance

    def to_json(self) -> dict:
        """The file's JSON, with its :func:`content_digest`."""
        doc = asdict(self)
        doc["job"] = {"fn": doc.pop("fn"), "kwargs": doc.pop("kwargs"), "name": doc.pop("name")}
        doc["digest"] = content_digest(doc)
        return doc

    @classmethod
    def from_json(cls, doc: dict) -> StoreEntry:
        job, prov = doc["job"], dict(doc["provenance"])
        prov["machine"] = Machine(**prov["machine"])
        return cls(doc["key"], job["fn"], job["kwargs"], job.get("name", ""), doc["data_hash"],
                   doc["code_version"], doc["result"], Provenance(**prov))

    def expected_key(self) -> str:
        return store_key(self.fn, self.kwargs, self.data_hash, self.code_version)


def this_sitting(revision: str, code: str) -> dict:
    """Where and with what this process fits: machine, Python, torch, git revision (a
    sitting of :attr:`Provenance.sittings`)."""
    import torch

    return {"machine": asdict(Machine.here()), "python": platform.python_version(),
            "torch": torch.__version__, "git_revision": revision.removesuffix("+dirty"),
            "dirty": revision.endswith("+dirty"), "code_version": code,
            "started_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")}


def sittings(state_dir: str | Path | None) -> list[dict] | None:
    """The sittings recorded in a fit's state folder (None: the job has none)."""
    if state_dir is None:
        return None
    from parknss.experiments import parked

    return parked.read_sittings(state_dir) or None


def _warn(msg: str) -> None:
    print(f"parknss: warning: {msg}", file=sys.stderr)


def _nss_config(kwargs: Mapping[str, Any]) -> dict | None:
    """The resolved NSS config of a fold-like job (None for other jobs)."""
    if "overrides" not in kwargs:
        return None
    from parknss.experiments.folds import fold_config

    return fold_config(kwargs.get("config"), kwargs.get("overrides")).model_dump(mode="json")


class ResultStore:
    """The store at ``root`` (see the module doc); ``read``/``write`` switch the lookup and
    the recording off (``refit``, quick runs); ``fit_missing`` False makes a fit it lacks
    an error (``--stored-only``). Implements :class:`parknss.executor.Store`."""

    def __init__(self, root: str | Path, read: bool = True, write: bool = True,
                 log: Callable[[str], None] = _warn, fit_missing: bool = True) -> None:
        self.root = Path(root)
        self.read, self.write, self.log = read, write, log
        self.fit_missing = fit_missing
        self.code = code_version()
        self._codes: tuple[str, list[str]] | None = None
        self._data_hashes: dict[str | None, str] = {}
        self._revision: str | None = None

    @property
    def codes(self) -> list[str]:
        """The code versions whose entries answer a job: this checkout's (:attr:`code`),
        then those the lineage records equivalent to it
        (:mod:`parknss.experiments.lineage`); read once per code."""
        if self._codes is None or self._codes[0] != self.code:
            from parknss.experiments.lineage import accepted_versions

            self._codes = (self.code, accepted_versions(self.root, self.code))
        return self._codes[1]

    def data_hash(self, data: str | None) -> str:
        """The data hash of the campaign ``data`` (None: the default), computed once."""
        if data not in self._data_hashes:
            from parknss.nss.campaigns import load_campaign

            self._data_hashes[data] = load_campaign(data).data_hash()
        return self._data_hashes[data]

    def entry_key(self, job: Job, code: str | None = None) -> tuple[str, dict, str]:
        """(key, key arguments, data hash) of ``job`` under code version ``code`` (None:
        this checkout's); a :data:`DERIVED` job's key arguments hold the digests of what
        it reads (``inputs``), its data hash is :data:`NO_DATA` when it reads no campaign."""
        kw = key_kwargs(bound_kwargs(job.fn, job.kwargs))
        derived = DERIVED.get(job.fn)
        if derived is None:
            dh = self.data_hash(job.kwargs.get("data"))
            return store_key(job.fn, kw, dh, code or self.code), kw, dh
        kw["inputs"] = self._inputs(derived, job.kwargs)
        dh = self.data_hash(job.kwargs.get("data")) if derived.reads_data else NO_DATA
        return store_key(job.fn, kw, dh, code or job_code_version(job.fn)), kw, dh

    def _inputs(self, derived: Derived, kwargs: Mapping[str, Any]) -> dict[str, str]:
        """The input digests of a derived job, computed once per arguments."""
        memo = self.__dict__.setdefault("_input_memo", {})
        rest = {k: v for k, v in kwargs.items() if k not in derived.same_inputs}
        ident = (derived.inputs, json.dumps(rest, sort_keys=True, default=str))
        if ident not in memo:
            memo[ident] = resolve(derived.inputs)(kwargs)
        return dict(memo[ident])

    def accepted_keys(self, job: Job) -> list[str]:
        """The keys of ``job`` under every accepted code version (:attr:`codes`; a
        :data:`DERIVED` job: its own code version only, the canary lineage vouches for
        the training code alone)."""
        if job.fn in DERIVED:
            return [self.entry_key(job)[0]]
        return [self.entry_key(job, c)[0] for c in self.codes]

    def path(self, job: Job) -> Path:
        return self.root / short_name(job.fn) / f"{self.entry_key(job)[0]}.json"

    def get(self, job: Job) -> tuple[bool, Any]:
        """(True, result) of ``job`` from its own entry, else from the entry of a job that
        answers it (:data:`ALIASES`); (False, None) when neither is stored."""
        hit, value = self._get(job)
        if hit or job.fn not in ALIASES:
            return hit, value
        fn, part = ALIASES[job.fn]
        hit, value = self._get(Job(fn, job.kwargs, job.name))
        if not hit:
            return False, None
        if not isinstance(value, dict) or not isinstance(value.get(part), dict):
            self.log(f"the stored {short_name(fn)} result of {job.name or 'a job'} has no "
                     f"{part!r} part; ignored, refitting")
            return False, None
        return True, {**value[part], "model_dir": None}  # the answering job's model is gone

    def parked_step(self, job: Job) -> int:
        """The step of the training state parked for ``job``, or for the job that answers
        it (:data:`ALIASES`), whichever is further along; 0 when neither has one
        (:mod:`parknss.experiments.parked`)."""
        from parknss.experiments import parked

        jobs = [job] + ([Job(ALIASES[job.fn][0], job.kwargs, job.name)]
                        if job.fn in ALIASES else [])
        steps = [parked.read_step(parked.parked_dir(self.root, k))
                 for j in jobs for k in self.accepted_keys(j)]
        return max((s for s in steps if s is not None), default=0)

    def _get(self, job: Job) -> tuple[bool, Any]:
        """The entry of ``job`` under the first accepted code version that has one."""
        if not self.read:
            return False, None
        for key in self.accepted_keys(job):
            p = self.root / short_name(job.fn) / f"{key}.json"
            if p.is_file():
                return self._read(p, key)
        return False, None

    def _read(self, p: Path, key: str) -> tuple[bool, Any]:
        try:
            doc = json.loads(p.read_text())
            entry = StoreEntry.from_json(doc)
            ok = entry.key == key == entry.expected_key()
        except (OSError, ValueError, KeyError, TypeError) as exc:
            self.log(f"{p}: not a store entry ({exc.__class__.__name__}); ignored, refitting")
            return False, None
        if not ok:
            self.log(f"{p}: its contents do not match its key; ignored, refitting")
            return False, None
        if "digest" in doc and digest_problem(doc) is not None:
            self.log(f"{p}: {digest_problem(doc)}; ignored, refitting")
            return False, None
        return True, entry.result

    def _git(self) -> str:
        if self._revision is None:
            from parknss.outputs import git_revision

            self._revision = git_revision()
        return self._revision

    def put(self, job: Job, result: Any, wall_s: float, cpu_s: float) -> None:
        if not self.write:
            return
        key, kw, dh = self.entry_key(job)
        import torch

        rev = self._git()
        prov = Provenance(
            git_revision=rev.removesuffix("+dirty"), dirty=rev.endswith("+dirty"),
            machine=Machine.here(), python=platform.python_version(), torch=torch.__version__,
            wall_s=round(wall_s, 3), cpu_s=round(cpu_s, 3),
            finished_utc=datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            data=job.kwargs.get("data"), config=_nss_config(job.kwargs),
            sittings=sittings(job.kwargs.get("state_dir")),
        )
        code = job_code_version(job.fn) if job.fn in DERIVED else self.code
        entry = StoreEntry(key, job.fn, kw, job.name, dh, code, result, prov)
        p = self.root / short_name(job.fn) / f"{key}.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        # durable: a kill or power loss right after this keeps the whole entry (the next
        # grid cell, the next fit, may be where the run is stopped)
        from parknss import durable

        text = json.dumps(entry.to_json(), indent=1, sort_keys=True) + "\n"
        durable.write_bytes(p, text.encode())
        from parknss.experiments import parked

        if any([parked.unpark(self.root, k) for k in self.accepted_keys(job)]):
            self.log(f"{job.name or key}: stored; its parked state is removed")

    def resume(self, job: Job) -> None:
        """Before ``job`` is computed: label its state folder (if it has one) with the job
        and its key, and seed it from the state parked under that key when that is further
        along (:mod:`parknss.experiments.parked`; not under ``refit``)."""
        state_dir = job.kwargs.get("state_dir")
        if state_dir is None:
            return
        from parknss.experiments import parked

        key = self.entry_key(job)[0]
        parked.label(state_dir, job.fn, job.kwargs, job.name, key)
        info = None
        for k in self.accepted_keys(job) if self.read else []:
            info = parked.seed(self.root, k, state_dir)
            if info is not None:
                break
        parked.add_sitting(state_dir, this_sitting(self._git(), self.code))
        if info is not None:
            cpu = "" if info.cpu_s is None else f", {info.cpu_s:.0f} CPU s"
            self.log(f"{job.name or key}: resumes from its parked state (step {info.step}{cpu})")


def store_dir(option: str | Path | None, setting: str = AUTO,
              env: Mapping[str, str] = os.environ) -> Path | None:
    """Where the store is: ``option`` (``--store``), else ``$PARKNSS_RESULTS``, else the
    config's ``setting``; ``off`` is none, ``auto`` the checkout's ``results/`` (none when
    parknss runs from an installed wheel, which has no checkout)."""
    spec = str(option) if option is not None else env.get(ENV_VAR) or setting
    if spec == OFF:
        return None
    if spec == AUTO:
        checkout = (REPO_ROOT / "src" / "parknss").resolve() == PACKAGE_DIR
        return REPO_ROOT / "results" if checkout else None
    return Path(spec)


def open_store(option: str | Path | None, cfg, quick: bool, refit: bool,
               log: Callable[[str], None] = _warn,
               stored_only: bool = False) -> ResultStore | None:
    """The store of a study run (None when off): ``cfg`` is the
    :class:`~parknss.experiments.config.ExperimentsConfig` (``store`` section); ``refit``
    skips its hits; a ``quick`` run does not write unless ``store.write_quick``;
    ``stored_only``: read, never fit (refused with ``refit`` or without a store)."""
    root = store_dir(option, cfg.store.dir)
    if stored_only and (root is None or refit):
        raise ConfigError("--stored-only reads the result store: it needs one (not --store "
                          "off) and cannot --refit")
    if root is None:
        return None
    return ResultStore(root, read=not refit, write=not quick or cfg.store.write_quick, log=log,
                       fit_missing=not stored_only)


NOT_ENTRIES: tuple[str, ...] = ("inflight", "lineage")
"""Folders of the store that hold no entries (parked states, the lineage)."""


def entries(root: str | Path) -> list[tuple[Path, StoreEntry | str]]:
    """Every ``*.json`` under the store ``root`` with its entry, or why it is not a valid
    one (does not parse, lacks a field, its key does not match its contents or path, its
    content does not match its digest or it has none)."""
    root = Path(root)
    out: list[tuple[Path, StoreEntry | str]] = []
    for p in sorted(root.glob("*/*.json")):
        if p.parent.name in NOT_ENTRIES:
            continue
        try:
            doc = json.loads(p.read_text())
            e = StoreEntry.from_json(doc)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            out.append((p, f"not a store entry ({exc.__class__.__name__}: {exc})"))
            continue
        if digest_problem(doc) is not None:
            out.append((p, str(digest_problem(doc))))
        elif e.key != e.expected_key():
            out.append((p, f"key {e.key} does not match its contents ({e.expected_key()})"))
        elif p.stem != e.key or p.parent.name != short_name(e.fn):
            out.append((p, f"misplaced: belongs at {short_name(e.fn)}/{e.key}.json"))
        else:
            out.append((p, e))
    return out


def results_root(option: str | Path | None, config: Path | None = None) -> Path:
    """The store ``parknss results`` reads (:func:`store_dir` with the experiments config
    ``config``); a one-line ConfigError when there is none or it is not a folder."""
    if option is not None or os.environ.get(ENV_VAR):  # the config is not read (start-up)
        root = store_dir(option)
    else:
        from parknss.experiments.config import load_experiments_config

        root = store_dir(option, load_experiments_config(config).store.dir)
    if root is None:
        raise ConfigError("no result store (off, or no checkout): name one with --store DIR "
                          f"or ${ENV_VAR}")
    if not root.is_dir():
        raise ConfigError(f"{root}: no result store there (not a folder)")
    return root


def fit_cpu_s(fn: str, result: Any) -> float | None:
    """The training CPU s the result of job ``fn`` records for its whole fit (every
    resumption included: the training state carries it): its own ``cpu_s``, or that of
    its part that answers another job (:data:`ALIASES`: a limiter result's fold); None
    when it records none."""
    parts = [part for answering, part in ALIASES.values() if answering == fn]
    inner = result.get(parts[0]) if parts and isinstance(result, dict) else result
    cpu = inner.get("cpu_s") if isinstance(inner, dict) else None
    return float(cpu) if isinstance(cpu, int | float) and not isinstance(cpu, bool) else None


def seal(root: str | Path) -> tuple[int, int]:
    """Add its :func:`content_digest` to every entry of the store ``root`` that has none
    (the entries stored before digests existed; a one-time migration) and whose key
    matches its contents; (sealed, already sealed). Files that are not valid entries are
    left alone (``parknss results verify`` names them)."""
    done = already = 0
    for p in sorted(Path(root).glob("*/*.json")):
        if p.parent.name in NOT_ENTRIES:
            continue
        try:
            doc = json.loads(p.read_text())
            e = StoreEntry.from_json(doc)
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if "digest" in doc:
            already += 1
            continue
        if e.key != e.expected_key():
            continue
        doc["digest"] = content_digest(doc)
        tmp = p.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        tmp.replace(p)
        done += 1
    return done, already


def _match(rel: str, pattern: str) -> bool:
    """``rel`` (a path under ``src/parknss/``) matches the glob ``pattern`` part by part,
    as :meth:`pathlib.Path.glob` does (``*`` stays inside one folder)."""
    from fnmatch import fnmatchcase

    a, b = rel.split("/"), pattern.split("/")
    return len(a) == len(b) and all(fnmatchcase(x, y) for x, y in zip(a, b, strict=True))


_REV_CODES: dict[tuple[str, tuple[str, ...]], str | None] = {}


def revision_code_version(rev: str, patterns: tuple[str, ...] = CODE_FILES) -> str | None:
    """:func:`code_version` of the files ``patterns`` as committed at git revision ``rev``
    of this checkout (None: no git, or the revision is unknown here). A fit made from a
    *dirty* tree whose recorded code version equals its revision's ran the committed
    training code: the uncommitted edits were elsewhere (or comments only)."""
    import subprocess

    ident = (rev, patterns)
    if ident in _REV_CODES:
        return _REV_CODES[ident]
    prefix = "src/parknss/"
    try:
        names = subprocess.run(["git", "-C", str(REPO_ROOT), "ls-tree", "-r", "--name-only",
                                rev, prefix], capture_output=True, text=True, check=True,
                               timeout=30).stdout.splitlines()
        rels = sorted(n[len(prefix):] for n in names if n.startswith(prefix)
                      and n[len(prefix):] not in CODE_EXCLUDED
                      and any(_match(n[len(prefix):], pat) for pat in patterns))
        batch = subprocess.run(["git", "-C", str(REPO_ROOT), "cat-file", "--batch"],
                               input="".join(f"{rev}:{prefix}{r}\n" for r in rels).encode(),
                               capture_output=True, check=True, timeout=60).stdout
        h, pos = hashlib.sha256(), 0
        for rel in rels:  # "<sha> blob <size>\n<content>\n" per file, in order
            head_end = batch.index(b"\n", pos)
            size = int(batch[pos:head_end].split()[2])
            text = batch[head_end + 1 : head_end + 1 + size].decode()
            pos = head_end + 2 + size
            h.update(rel.encode() + b"\0")
            h.update(code_tokens(text) + b"\0")
        out: str | None = h.hexdigest()[:16] if rels else None
    except (OSError, ValueError, IndexError, subprocess.SubprocessError):
        out = None
    _REV_CODES[ident] = out
    return out


def dirty_note(e: StoreEntry) -> str:
    """For an entry fitted from a dirty tree, whether its code version is that of the
    code committed at its git revision: ``"code as committed"``, ``"code not as
    committed"`` or ``"revision unknown here"``; empty for a clean one."""
    if not e.provenance.dirty:
        return ""
    d = DERIVED.get(e.fn)
    got = revision_code_version(e.provenance.git_revision, d.code if d else CODE_FILES)
    if got is None:
        return "revision unknown here"
    return "code as committed" if got == e.code_version else "code not as committed"


def _derived_state(e: StoreEntry) -> str:
    """``current`` when a derived entry's code version and input digests are this
    checkout's, else ``stale`` (another chain, config or simulator)."""
    d = DERIVED[e.fn]
    if e.code_version != job_code_version(e.fn):
        return "stale"
    kwargs = {k: v for k, v in e.kwargs.items() if k != "inputs"}
    try:
        now = resolve(d.inputs)(kwargs)
    except Exception:  # an input that no longer reads (a removed chain): not this checkout's
        return "stale"
    return "current" if now == e.kwargs.get("inputs") else "stale"


def listing(root: Path) -> tuple[list[str], list[str]]:
    """(one line per valid entry, one line per invalid file) of the store at ``root``;
    an entry of this checkout's code version is ``current``, one of a version the
    lineage accepts ``lineage`` (:mod:`parknss.experiments.lineage`), any other
    ``stale`` (a :data:`DERIVED` entry: ``current`` when its code and input digests are
    this checkout's); a dirty entry says whether its code is its revision's
    (:func:`dirty_note`)."""
    from parknss.experiments.lineage import accepted_versions

    current = code_version()
    accepted = accepted_versions(root, current)
    rows, bad = [], []
    for p, e in entries(root):
        if isinstance(e, str):
            bad.append(f"{p.relative_to(root)}: {e}")
            continue
        pv = e.provenance
        if e.fn in DERIVED:
            state = _derived_state(e)
        else:
            state = ("current" if e.code_version == current
                     else "lineage" if e.code_version in accepted else "stale")
        dirty = f"+dirty ({dirty_note(e)})" if pv.dirty else ""
        total = fit_cpu_s(e.fn, e.result)
        fit = f" (fit {total:.0f} s)" if total is not None and total > pv.cpu_s + 1 else ""
        if fit:  # resumed: where its earlier sittings ran, when recorded
            cpus = sorted({str(x.get("machine", {}).get("cpu", "?"))[:20]
                           for x in pv.sittings or []})
            fit = (fit[:-1] + f"; {len(pv.sittings)} sittings on {', '.join(cpus)})"
                   if pv.sittings else fit[:-1] + "; earlier sittings not recorded)")
        rows.append(f"{short_name(e.fn)}/{e.key}  {e.name:28s} data {e.data_hash[:10]}  "
                    f"code {e.code_version} {state:7s}  {pv.git_revision[:10]}"
                    f"{dirty}  wall {pv.wall_s:.1f} s cpu {pv.cpu_s:.1f} s"
                    f"{fit}  {pv.finished_utc}")
    return rows, bad
