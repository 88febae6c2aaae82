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
  finish time). Either way the unfinished run's own work (a result cache, training
  states, partial products) is never deleted: it moves to ``<name>.unfinished-<UTC>``
  beside ``out`` with a one-line warning, and ``--out`` there resumes it.

Every final product is written atomically (:func:`atomic_file`: a temporary sibling
renamed over the target), so a failing or killed run never leaves a torn table, JSON or
figure: each product is the earlier run's or this run's, whole. A new run that fails
before it wrote anything but its manifest removes the folder it created.

Names never become paths
------------------------

A name a user supplies (a scene's ``meta.name``, a CommonRoad benchmark id, a TPCAP case
name, a trial id from a log's file name) becomes part of a file or folder name only
through :func:`safe_stem`, which returns it unchanged or refuses it in one line
(:class:`UnsafeNameError`); names are never repaired, so two scenes cannot silently share
a file. A safe stem is 1 to :data:`NAME_MAX_CHARS` characters (and at most
:data:`NAME_MAX_BYTES` bytes in UTF-8, so that a prefix and suffix still fit a file
system's 255-byte limit) of letters, digits, marks, punctuation, symbols and plain spaces;
it does not start with ``.``, ``-`` or a space nor end with a space, and holds no path
separator (``/``, ``\\``), no ``..``, no glob character (``* ? [ ]``), and no control,
format (bidirectional marks such as U+200F, U+202E), surrogate, private-use, unassigned
or line/paragraph-separator character. Every product path is then checked after path
resolution to lie inside its run folder (:func:`inside`: symbolic links included), and a
command's default run folder is ``runs/<command>/<safe stem>`` (:func:`default_run_folder`),
so ``--overwrite`` only ever replaces that folder.

Interrupts
----------

A command stopped by SIGINT or SIGTERM exits 130 or 143 with one line saying what was
kept and how to resume (``parknss.cli``). The line comes from the innermost writer the
interrupt passed through: :func:`run_folder` (the run's cache kept and the same command
resumes it, or the earlier run put back), :func:`artefact_folder` (nothing written, the
folder as it was) or a command's own :func:`keep_on_interrupt` (``parknss train``: the
training state and ``--resume``); :func:`interrupt_note` reads it.

Where an output can go
----------------------

:func:`check_location` refuses, before any work, an ``--out`` that cannot be written: one
under a regular file, in a read-only folder, or on a file system that refuses new folders
(``/proc``); :func:`check_writable` and :func:`run_folder` call it. An ``OSError`` while
writing (disk full, ENOSPC) removes what the failing write left (the temporary file or
folder, and the folders the claim created) and reaches the user as one line.
"""

from __future__ import annotations

import contextlib
import errno
import glob
import hashlib
import json
import os
import re
import shutil
import subprocess
import tempfile
import unicodedata
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from parknss import durable
from parknss.errors import ParknssError, ParknssWarning

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


class UnsafeNameError(ParknssError):
    """A user-supplied name cannot be part of a file name, or a path would leave its
    output folder."""


class OutputLocationError(ParknssError):
    """An output folder cannot be written where it was asked for (under a file, in a
    read-only folder, on a pseudo file system)."""


# -------------------------------------------------------------------------- interrupts

_NOTE: list[str] = []
"""What the command being interrupted keeps and how to resume it (at most one entry)."""


def interrupt_note(*, clear: bool = False) -> str | None:
    """The line an interrupted command prints after ``parknss: interrupted:`` (what was
    kept, how to resume), set by the innermost writer the interrupt passed through, or
    None; ``clear`` forgets it (the CLI, after printing it)."""
    note = _NOTE[0] if _NOTE else None
    if clear:
        _NOTE.clear()
    return note


def _note_interrupt(exc: BaseException | None, describe: Callable[[], str]) -> None:
    if isinstance(exc, KeyboardInterrupt) and not _NOTE:
        _NOTE.append(describe())


@contextlib.contextmanager
def keep_on_interrupt(describe: Callable[[], str]) -> Iterator[None]:
    """Run the body; if SIGINT or SIGTERM (a KeyboardInterrupt) stops it, record
    ``describe()`` as :func:`interrupt_note` (unless an inner writer did) and re-raise."""
    try:
        yield
    except KeyboardInterrupt as exc:
        _note_interrupt(exc, describe)
        raise


# ------------------------------------------------------------------------------- names

NAME_MAX_CHARS = 100
"""The longest user-supplied name accepted as a file-name stem, in characters."""

NAME_MAX_BYTES = 150
"""The longest user-supplied name accepted as a file-name stem, in UTF-8 bytes."""

_REFUSED_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"})
_REFUSED_CHARS = frozenset("/\\*?[]")


def _why_unsafe(name: str) -> str | None:
    if not name:
        return "is empty"
    if len(name) > NAME_MAX_CHARS:
        return f"is {len(name)} characters long (at most {NAME_MAX_CHARS})"
    if len(name.encode("utf-8", "surrogatepass")) > NAME_MAX_BYTES:
        return f"is longer than {NAME_MAX_BYTES} bytes in UTF-8"
    for ch in name:
        cat = unicodedata.category(ch)
        if ch in _REFUSED_CHARS:
            return f"contains {ch!r} (path separators and glob characters are refused)"
        if cat in _REFUSED_CATEGORIES or (cat == "Zs" and ch != " "):
            return f"contains the character U+{ord(ch):04X} ({unicodedata.name(ch, cat)})"
    if ".." in name:
        return "contains '..'"
    if name[0] in ".- " or name[-1] == " ":
        return "starts with '.', '-' or a space, or ends with a space"
    return None


def safe_stem(name: object, *, what: str = "name") -> str:
    """``name`` unchanged when it is safe as (part of) a file or folder name, else a
    one-line :class:`UnsafeNameError` saying why (see "Names never become paths" in the
    module doc: 1 to :data:`NAME_MAX_CHARS` characters, no separators, ``..``, glob,
    control or bidirectional characters; refused, never repaired).

    Args:
        name: the user-supplied name (a scene's meta.name, a trial id, ...).
        what: what the name is, for the message ("scene name", "trial id").
    """
    if not isinstance(name, str):
        raise UnsafeNameError(f"{what} {name!r} is not a string; it cannot name a file")
    why = _why_unsafe(name)
    if why is not None:
        shown = repr(name if len(name) <= 40 else name[:40] + "...")  # escapes controls
        raise UnsafeNameError(f"{what} {shown} {why}; it cannot name a file, rename it")
    return name


def inside(folder: str | Path, relative: str | Path) -> Path:
    """``folder / relative``, refused with one :class:`UnsafeNameError` line unless its
    resolved path (symbolic links followed) lies inside the resolved ``folder``."""
    base = Path(folder)
    path = base / relative
    root = base.resolve()
    if not path.resolve().is_relative_to(root) or path.resolve() == root:
        raise UnsafeNameError(f"{path}: resolves outside the output folder {base}; refused")
    return path


def default_run_folder(command: str, name: object, *, what: str = "name") -> Path:
    """The run folder of ``command`` without ``--out``: ``runs/<command>/<name>``, with
    ``name`` checked by :func:`safe_stem` and the folder by :func:`inside`."""
    return inside(Path("runs") / command, safe_stem(name, what=what))


def check_location(out: str | Path) -> Path:
    """Refuse, before any work, an output folder ``out`` that cannot be created or
    written: its nearest existing ancestor is not a folder (``out`` under a regular
    file), is not writable, or refuses a new folder (``/proc``). One line
    (:class:`OutputLocationError`); ``out`` as a Path."""
    p = Path(out)
    if p.exists() and not p.is_dir():
        return p  # a file at out: the callers' own refusal names it
    existing = p.absolute()
    while not existing.is_dir() and existing != existing.parent:
        if existing.exists():
            raise OutputLocationError(
                f"{p}: {existing} is a file, not a folder; cannot write there"
            )
        existing = existing.parent
    try:
        probe = tempfile.mkdtemp(prefix=".parknss-probe-", dir=existing)
    except OSError as exc:
        reason = exc.strerror or exc.__class__.__name__
        raise OutputLocationError(f"{p}: cannot write in {existing} ({reason})") from exc
    os.rmdir(probe)
    return p


def check_file_target(out: str | Path, *, overwrite: bool) -> Path:
    """Refuse, before any work, a single output file ``out`` (``parknss export --out``)
    that cannot be written: a folder, an existing file without ``overwrite``
    (:class:`OutputExistsError`), or a place :func:`check_location` refuses; ``out``."""
    p = Path(out)
    if p.is_dir():
        raise OutputLocationError(f"{p}: is a folder; --out names the file to write")
    if (p.exists() or p.is_symlink()) and not overwrite:
        raise OutputExistsError(f"{p}: already exists (pass --overwrite to replace it)")
    check_location(p.absolute().parent)
    return p


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
    check_location(p)
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
    run finished (the killed run's work, if any, kept by :func:`_set_aside`); delete the
    rest."""
    out = Path(out)
    parent = out.absolute().parent
    if not parent.is_dir():
        return
    for kind in ("replaced", "old", "tmp"):
        for p in sorted(parent.glob(f".{glob.escape(out.name)}.{kind}-*")):
            pid = p.name.rsplit("-", 1)[-1]
            if not pid.isdigit() or _alive(int(pid)):
                continue
            if kind == "replaced" and not (read_manifest(out) or {}).get("finished_utc"):
                kept = _set_aside(out)  # the killed run's folder, if it got that far
                os.replace(p, out)
                if kept is not None:
                    warnings.warn(f"{out}: a killed --overwrite run's work is kept in "
                                  f"{kept} (resume it with --out {kept}); the earlier "
                                  "content is put back", ParknssWarning, stacklevel=2)
            elif kind == "old" and not out.exists() and not out.is_symlink():
                os.replace(p, out)
            else:
                _remove(p)


UNFINISHED = "unfinished"
"""Suffix of the folder an unfinished ``--overwrite`` run's work is kept in
(``<name>.unfinished-<UTC>``) when the earlier content is put back."""


def _set_aside(out: Path) -> Path | None:
    """Clear ``out`` for the earlier content an unfinished ``--overwrite`` run replaced:
    a run that wrote work beyond its manifest (a result cache, training states, partial
    products) is moved to a visible sibling ``<name>.unfinished-<UTC>``, whose manifest
    resumes it with ``--out`` there (its path returned); an empty one is removed."""
    if not out.is_dir() or out.is_symlink():
        _remove(out)
        return None
    if not any(p.name != RUN_MANIFEST for p in out.iterdir()):
        _remove(out)
        return None
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
    kept = out.absolute().parent / f"{out.name}.{UNFINISHED}-{stamp}"
    n = 1
    while kept.exists() or kept.is_symlink():
        n += 1
        kept = out.absolute().parent / f"{out.name}.{UNFINISHED}-{stamp}-{n}"
    os.replace(out, kept)
    return kept


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
    created = _first_missing(parent)
    parent.mkdir(parents=True, exist_ok=True)
    tmp = parent / f".{out.name}.tmp-{os.getpid()}"
    old = parent / f".{out.name}.old-{os.getpid()}"
    _remove(tmp)
    tmp.mkdir()
    try:
        yield tmp
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        _remove_empty(parent, created)
        _note_interrupt(exc, lambda: f"nothing written, {out} is as it was; run the "
                        "same command again")
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


def plain_json(value: Any) -> Any:
    """``value`` as plain JSON (for a manifest or a digest): paths resolved, tuples as
    lists, mappings with str keys."""
    if isinstance(value, Path):
        return str(value.expanduser().resolve())
    if isinstance(value, Mapping):
        return {str(k): plain_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain_json(v) for v in value]
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
    except (OSError, ValueError, RecursionError):
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

    def file(self, name: str) -> Path:
        """The path of the product ``name`` (relative to the folder), refused in one line
        when it resolves outside the folder (:func:`inside`)."""
        return inside(self.path, name)

    def write_text(self, name: str, text: str) -> Path:
        """Write the product ``name`` (relative to the folder) atomically; its path."""
        return write_text_atomic(self.file(name), text)

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
    with contextlib.suppress(FileNotFoundError):
        (out / RUN_MANIFEST).unlink()
    _remove_empty(out.absolute(), created)


def _run_note(out: Path, state: str, kept: Path | None = None) -> str:
    """What an interrupted run keeps in ``out`` and how to resume it, for one line."""
    if state == "replacing" and kept is not None:
        return (f"the earlier content of {out} is put back; this run's work is kept in "
                f"{kept}: run the same command with --out {kept} (without --overwrite) to "
                "resume it")
    if state == "replacing":
        return f"the earlier content of {out} is put back; run the same command again"
    if not (out / RUN_MANIFEST).is_file():
        return f"nothing kept in {out}; run the same command again"
    cache = out / "cache"
    if cache.is_dir() and any(cache.iterdir()):
        n = sum(1 for _ in cache.glob("*.json"))
        return (f"{n} finished job(s) kept in {cache}; run the same command again to "
                "resume from them")
    return f"the partial run is kept in {out}; run the same command again to redo it there"


def _disk_full(exc: BaseException | None) -> bool:
    return isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)


def _drop_partial(out: Path, created: Path | None) -> None:
    """A new run stopped by a full disk: remove its partial products, keeping only a
    result cache (``cache/``, with the manifest, so the same command resumes it); with
    no cache, the folder and the folders the claim created."""
    cache = out / "cache"
    keep = cache.is_dir() and any(cache.iterdir())
    for p in list(out.iterdir()):
        if keep and p.name in ("cache", RUN_MANIFEST):
            continue
        _remove(p)
    if not keep:
        _remove_empty(out.absolute(), created)


def _remove_empty(folder: Path, created: Path | None) -> None:
    """Remove ``folder`` and its parents up to ``created`` (the outermost folder a claim
    created), while they are empty; nothing when ``created`` is None."""
    if created is None:
        return
    for d in (folder, *folder.parents):
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
    out = check_location(out)
    recover_stale(out)
    plain = plain_json(dict(args))
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
    run = RunFolder(out, state, manifest)
    try:
        if state != "resumed":
            write_text_atomic(out / RUN_MANIFEST, json.dumps(manifest, indent=2))
        yield run
    except BaseException as exc:
        kept = None
        if state == "replacing":
            kept = _set_aside(out)
            os.replace(replaced, out)
        elif state == "new" and _disk_full(exc):
            _drop_partial(out, created)
        elif state == "new" and [p.name for p in out.iterdir()] in ([RUN_MANIFEST], []):
            _unclaim(out, created)
        if kept is not None and not isinstance(exc, KeyboardInterrupt):
            warnings.warn(_run_note(out, state, kept), ParknssWarning, stacklevel=2)
        _note_interrupt(exc, lambda: _run_note(out, state, kept))
        raise
    run.manifest["finished_utc"] = _now()
    write_text_atomic(out / RUN_MANIFEST, json.dumps(run.manifest, indent=2, default=str))
    if state == "replacing":
        _remove(replaced)
