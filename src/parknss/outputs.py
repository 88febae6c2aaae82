"""Artefact folders written atomically, never over another artefact without ``--overwrite``.

Every command that writes an artefact folder (a campaign, a model, a chain, a run) writes
it through :func:`artefact_folder`::

    with artefact_folder(out, overwrite=overwrite, kind="campaign") as tmp:
        write_campaign(campaign, tmp)          # everything goes into tmp

The writer fills a fresh temporary sibling ``.<name>.tmp-<pid>``; only when it returns
normally is that folder flushed to disk (every file and folder ``fsync``ed,
:func:`parknss.durable.fsync_tree`) and renamed into place as ``out`` (the rename flushed
too), so that even a power loss leaves the old or the new artefact, never a renamed
folder of empty files. A writer that fails (or is
interrupted) leaves ``out`` as it was and the temporary folder deleted; one that is killed
leaves ``out`` as it was and a stale temporary folder, which the next writer of ``out``
removes. An ``out`` that already holds something is refused with a one-line
:class:`OutputExistsError` unless ``overwrite=True``; then the new folder and the old one
swap names in one atomic step (Linux ``renameat2(RENAME_EXCHANGE)``,
:func:`parknss.durable.exchange`) and the old one, now under the temporary name, is
deleted: ``out`` is the old or the new artefact at every instant. Where the exchange is
not available, the old folder is renamed away (``.<name>.old-<pid>``), the new one renamed
in and only then the old one deleted (a crash between the two renames leaves the old one
under its ``.old`` name; the next writer of ``out`` puts it back before it looks at
``out``).

Run folders
-----------

Every command that writes a *run* folder (``cv``, ``evaluate``, ``study``, ``reproduce``,
``demo``, ``plan``, ``simulate``, ``grid``, ``tune``, ``rate``, ``actuators study``) claims
it through :func:`run_folder`::

    with run_folder(out, command="parknss cv", args=identity, overwrite=overwrite) as run:
        ...                                    # work in out (its cache resumes)
        run.write_json("cv.json", doc)         # final products: atomic files

The folder carries a manifest, ``run.json`` (:data:`RUN_MANIFEST`): the command, the
arguments that decide its results (``args``, paths resolved, and where the command loads
a config, that config's digest), their ``digest``, the parknss version, the git revision
and the start and finish times. Then:

* an absent or empty ``out`` is a **new** run;
* an ``out`` whose manifest names the same command with the same arguments is **resumed**:
  the run works in it as it is, so a result cache under it (``cv``, ``study``,
  ``reproduce``) is reused and an interrupted sweep goes on where it stopped;
* anything else (a campaign, model or chain, a run of another command or of other
  arguments, a folder without a manifest) is refused with one
  :class:`OutputExistsError` line naming what it holds, unless ``overwrite``: then the
  earlier content is renamed away (``.<name>.replaced-<pid>``), the run starts afresh in
  ``out``, and the earlier content is deleted only when the run finishes; a run that
  fails puts it back whole, and one that is killed leaves it beside ``out`` for the next
  look at ``out`` to put back (:func:`recover_stale`: the killed run's manifest has no
  finish time).

Every final product is written atomically (:func:`atomic_file`: a temporary sibling
renamed over the target), so a failing or killed run never leaves a torn table, JSON or
figure: each product is the earlier run's or this run's, whole. A new run that fails
before it wrote anything but its manifest removes the folder it created.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import subprocess
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from parknss import durable
from parknss.errors import ParknssError

MARKERS: tuple[tuple[str, str], ...] = (
    ("campaign.json", "campaign"),
    ("model.json", "model"),
    ("chain.json", "chain"),
)
"""(file, what) pairs that identify an artefact folder, checked in this order."""

RUN_MANIFEST = "run.json"
"""The manifest of a run folder (see "Run folders" in the module doc)."""


class OutputExistsError(ParknssError):
    """The output folder holds something already and ``--overwrite`` was not given."""


def describe_contents(out: str | Path) -> str | None:
    """What the existing path ``out`` holds, for a message (``"a campaign (campaign.json)"``,
    ``"a run of parknss cv (run.json)"``, ``"a run (3 entries)"``, ``"a file"``), or None
    when it is absent or an empty folder."""
    p = Path(out)
    if not p.exists() and not p.is_symlink():
        return None
    if not p.is_dir():
        return "a file"
    entries = list(p.iterdir())
    if not entries:
        return None
    for marker, what in MARKERS:
        if (p / marker).is_file():
            return f"a {what} ({marker})"
    command = (read_manifest(p) or {}).get("command")
    if command:
        return f"a run of {command} ({RUN_MANIFEST})"
    return f"a run ({len(entries)} entr{'y' if len(entries) == 1 else 'ies'})"


def check_writable(out: str | Path, *, overwrite: bool, kind: str) -> Path:
    """Refuse, before any long work, an ``out`` that :func:`artefact_folder` would refuse.

    Args:
        out: the artefact folder to be written.
        overwrite: whether an existing artefact may be replaced (``--overwrite``).
        kind: what is about to be written ("campaign", "model", "chain", "run"), for the
            message.

    What a killed writer left beside ``out`` is tidied first (:func:`recover_stale`).

    Returns:
        ``out`` as a Path.

    Raises:
        OutputExistsError: ``out`` holds something and ``overwrite`` is False; ``out`` is
            a file; or ``out`` contains the working directory (never replaced).
    """
    p = Path(out)
    recover_stale(p)
    held = describe_contents(p)
    if held is None:
        return p
    if held == "a file":
        raise OutputExistsError(f"{p}: is a file, not a folder; cannot write the {kind} there")
    if not overwrite:
        raise OutputExistsError(
            f"{p}: holds {held} already; pass --overwrite to replace it with the {kind}"
        )
    cwd = Path.cwd().resolve()
    target = p.resolve()
    if target == cwd or target in cwd.parents:
        raise OutputExistsError(
            f"{p}: contains the working directory; refusing to replace it with the {kind}"
        )
    return p


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, owned by someone else
    return True


def recover_stale(out: str | Path) -> None:
    """Tidy what a killed writer of ``out`` left beside it: put back an old artefact
    renamed away (``.<name>.old-<pid>``) when ``out`` is missing; put back the earlier
    content a killed ``--overwrite`` run replaced (``.<name>.replaced-<pid>``) unless that
    run finished; delete the rest."""
    out = Path(out)
    parent = out.absolute().parent
    if not parent.is_dir():
        return
    for kind in ("replaced", "old", "tmp"):
        for p in sorted(parent.glob(f".{out.name}.{kind}-*")):
            pid = p.name.rsplit("-", 1)[-1]
            if not pid.isdigit() or _alive(int(pid)):
                continue
            if kind == "replaced" and not (read_manifest(out) or {}).get("finished_utc"):
                _remove(out)  # the killed run's partial folder, if it got that far
                os.replace(p, out)
            elif kind == "old" and not out.exists() and not out.is_symlink():
                os.replace(p, out)
            else:
                _remove(p)


def _remove(path: Path) -> None:
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.exists():
        shutil.rmtree(path)


@contextlib.contextmanager
def artefact_folder(out: str | Path, *, overwrite: bool, kind: str) -> Iterator[Path]:
    """Yield a fresh temporary folder to write the artefact into; move it to ``out`` on
    normal exit (see the module docstring).

    Args:
        out: where the artefact ends up (its parent folders are created).
        overwrite: replace an existing ``out`` (else it is refused, before the body runs).
        kind: what is written ("campaign", "model", "chain", "run"), for messages.

    Raises:
        OutputExistsError: as :func:`check_writable`, before the body runs; or when ``out``
            appeared while the body ran and ``overwrite`` is False.
    """
    out = check_writable(out, overwrite=overwrite, kind=kind)
    parent = out.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = parent / f".{out.name}.tmp-{os.getpid()}"
    old = parent / f".{out.name}.old-{os.getpid()}"
    _remove(tmp)
    tmp.mkdir()
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    try:
        durable.fsync_tree(tmp)
        durable.crash_point("artefact.tmp")
        check_writable(out, overwrite=overwrite, kind=kind)
        if describe_contents(out) is None:
            _remove(out)  # absent, or an empty folder: nothing to keep
            os.replace(tmp, out)
            durable.fsync_dir(parent)
            return
        if durable.exchange(tmp, out):  # one atomic step: out is never missing
            durable.fsync_dir(parent)
            shutil.rmtree(tmp, ignore_errors=True)  # now the old artefact
            return
        _remove(old)
        os.replace(out, old)
        try:
            os.replace(tmp, out)
        except BaseException:
            os.replace(old, out)
            raise
        durable.fsync_dir(parent)
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


# ----------------------------------------------------------------------------- atomic files


@contextlib.contextmanager
def atomic_file(path: str | Path) -> Iterator[Path]:
    """Yield a temporary sibling of ``path`` (``.<stem>.tmp-<pid><suffix>``: the suffix
    kept for writers that read the format from it) to write; flush it and rename it over
    ``path`` on normal exit (:func:`parknss.durable.replace`), delete it if the body
    raises. ``path``'s folder is created."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.stem}.tmp-{os.getpid()}{p.suffix}")
    try:
        yield tmp
        durable.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` through :func:`atomic_file`; ``path``."""
    with atomic_file(path) as tmp:
        tmp.write_text(text)
    return Path(path)


_STALE_FILE = re.compile(r"^\..+\.tmp-(\d+)(\.[^.]*)?$")


def _remove_stale_files(folder: Path) -> None:
    """Delete the temporary files (:func:`atomic_file`) killed writers left in ``folder``."""
    for p in folder.rglob(".*.tmp-*"):
        m = _STALE_FILE.match(p.name)
        if m and p.is_file() and not _alive(int(m.group(1))):
            p.unlink()


# ------------------------------------------------------------------------------ run folders


def git_revision() -> str:
    """The source checkout's HEAD (with '+dirty' if tracked files changed), or 'unknown'
    outside a git checkout."""
    from parknss.config import REPO_ROOT

    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
        ).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("parknss")
    except PackageNotFoundError:
        return "unknown"


def _plain(value: Any) -> Any:
    """``value`` as plain JSON for a manifest: paths resolved, tuples as lists."""
    if isinstance(value, Path):
        return str(value.expanduser().resolve())
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _digest(command: str, args: dict) -> str:
    blob = json.dumps({"command": command, "args": args}, sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def _now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def read_manifest(out: str | Path) -> dict | None:
    """The manifest (``run.json``) of the run folder ``out`` as written by
    :func:`run_folder`, or None (no manifest, or a file that is not one)."""
    p = Path(out) / RUN_MANIFEST
    try:
        doc = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) and "command" in doc and "digest" in doc else None


@dataclass
class RunFolder:
    """A claimed run folder: its ``path``, how it was claimed (``state``: "new", "resumed"
    or "replacing") and the ``manifest`` written to ``run.json`` when the run finishes
    (a command may add fields to it, e.g. its summary)."""

    path: Path
    state: str
    manifest: dict = field(default_factory=dict)

    def write_text(self, name: str, text: str) -> Path:
        """Write the product ``name`` (relative to the folder) atomically; its path."""
        return write_text_atomic(self.path / name, text)

    def write_json(self, name: str, doc: Any, **dumps: Any) -> Path:
        """Write ``doc`` as indented JSON to the product ``name`` atomically; its path."""
        return self.write_text(name, json.dumps(doc, indent=2, **dumps))


def _refusal(out: Path, command: str, args: dict, held: str) -> OutputExistsError:
    stored = read_manifest(out)
    if stored and stored.get("command") == command:
        old = stored.get("args") or {}
        keys = sorted(k for k in set(old) | set(args) if old.get(k) != args.get(k))
        what = f"a run of {command} with other arguments ({', '.join(keys) or 'digest'})"
        return OutputExistsError(f"{out}: holds {what} already; pass --overwrite to replace it")
    return OutputExistsError(
        f"{out}: holds {held} already; pass --overwrite to replace it with this run of {command}"
    )


def _first_missing(path: Path) -> Path | None:
    """The outermost ancestor of ``path`` (or ``path``) that does not exist yet."""
    missing = None
    for p in (path, *path.parents):
        if p.exists():
            break
        missing = p
    return missing


def _unclaim(out: Path, created: Path | None) -> None:
    """Undo a new claim that wrote nothing but its manifest: the manifest, and the
    folders the claim created while they are empty."""
    (out / RUN_MANIFEST).unlink()
    if created is None:
        return
    for d in (out.absolute(), *out.absolute().parents):
        try:
            d.rmdir()
        except OSError:
            return
        if d == created:
            return


@contextlib.contextmanager
def run_folder(
    out: str | Path, *, command: str, args: Mapping[str, Any], overwrite: bool
) -> Iterator[RunFolder]:
    """Claim ``out`` as the run folder of ``command`` with ``args``; see "Run folders" in
    the module doc.

    Args:
        out: the run folder (its parent folders are created).
        command: the command as a user types it ("parknss cv", "parknss simulate").
        args: the arguments that decide the run's results (not the executor, workers or
            output format), JSON-able; Path values are resolved.
        overwrite: replace whatever ``out`` holds (``--overwrite``), a resumable run of
            the same arguments included.

    Yields:
        The :class:`RunFolder`; work and write the products in ``run.path`` (``out``).

    Raises:
        OutputExistsError: before the body runs, when ``out`` holds something other than
            a run of ``command`` with ``args`` and ``overwrite`` is False; when ``out`` is
            a file; or when it contains the working directory and would be replaced.
    """
    out = Path(out)
    recover_stale(out)
    plain = _plain(dict(args))
    digest = _digest(command, plain)
    held = describe_contents(out)
    stored = read_manifest(out)
    same = bool(stored) and stored["command"] == command and stored["digest"] == digest
    if held == "a file":
        raise OutputExistsError(f"{out}: is a file, not a folder; cannot write the run there")
    if held is None:
        state = "new"
    elif same and not overwrite:
        state = "resumed"
    elif overwrite:
        check_writable(out, overwrite=True, kind=f"run of {command}")
        state = "replacing"
    else:
        raise _refusal(out, command, plain, held)
    replaced = out.absolute().parent / f".{out.name}.replaced-{os.getpid()}"
    created = _first_missing(out.absolute())
    if state == "replacing":
        _remove(replaced)
        os.replace(out, replaced)
        created = out.absolute()
    out.mkdir(parents=True, exist_ok=True)
    _remove_stale_files(out)
    stamp = {"parknss": _version(), "git_revision": git_revision()}
    if state == "resumed":
        manifest = {**stored, **stamp, "resumed_utc": _now(), "finished_utc": None}
    else:
        manifest = {
            "command": command,
            "args": plain,
            "digest": digest,
            **stamp,
            "started_utc": _now(),
            "finished_utc": None,
        }
        write_text_atomic(out / RUN_MANIFEST, json.dumps(manifest, indent=2))
    run = RunFolder(out, state, manifest)
    try:
        yield run
    except BaseException:
        if state == "replacing":
            _remove(out)
            os.replace(replaced, out)
        elif state == "new" and [p.name for p in out.iterdir()] == [RUN_MANIFEST]:
            _unclaim(out, created)
        raise
    run.manifest["finished_utc"] = _now()
    write_text_atomic(out / RUN_MANIFEST, json.dumps(run.manifest, indent=2, default=str))
    if state == "replacing":
        _remove(replaced)
