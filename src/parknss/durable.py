"""Durable writes, test crash points and the SHA-256 manifest of an artefact folder.

Three small mechanisms the writers of states and artefacts share:

* **Durable replacement** (:func:`write_bytes`, :func:`replace`, :func:`fsync_tree`,
  :func:`exchange`): a file is written to a temporary sibling, flushed to disk
  (``fsync``), renamed over its target and the rename made durable by an ``fsync`` of the
  folder. At every instant the target is the old complete file or the new complete one,
  after a kill or a power loss. A folder replaces another by an atomic exchange of the
  two names where Linux offers it.
* **Crash points** (:func:`crash_point`): named places inside the writers where a test
  kills the process deterministically. ``PARKNSS_CRASH_AT=NAME[:N]`` in the environment
  makes the process SIGKILL itself the N-th time (default 1) it reaches the point NAME;
  unset (always, outside tests) the call is a dictionary look-up. The points are listed in
  :data:`CRASH_POINTS`.
* **Manifests** (:func:`write_manifest`, :func:`verify_manifest`): an artefact folder (an
  NSS model, a chain) carries ``SHA256SUMS`` (:data:`MANIFEST`), the SHA-256 of every file
  it is made of in the format of coreutils ``sha256sum`` (``sha256sum -c SHA256SUMS``
  checks it from a shell). The manifest cannot hash itself: it lists every other file of
  the folder, those of sub-folders included (a chain's ``nss/SHA256SUMS`` too). A loader
  verifies it before it reads anything and refuses the folder in one line when a file
  differs, is missing, or the manifest is absent or malformed. It protects against edits
  and swapped files, not against someone who rewrites the manifest as well.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import signal
from collections.abc import Iterable
from pathlib import Path

from parknss.errors import CheckpointError

CRASH_ENV = "PARKNSS_CRASH_AT"
"""The environment variable naming the crash point a test wants hit (``NAME[:N]``)."""

CRASH_POINTS: tuple[str, ...] = (
    "train_state.tensors_tmp",  # the new tensors written to their temporary file
    "train_state.tensors",  # the new tensors renamed into place, the JSON not yet
    "train_state.prev",  # the previous JSON kept as train_state.prev.json
    "train_state.meta_tmp",  # the new JSON written to its temporary file
    "train_state.meta",  # the new JSON renamed into place (the commit), not yet tidied
    "artefact.tmp",  # an artefact folder written and flushed, not yet renamed into place
    "identify.stage",  # an identify stage's product written, its done record not yet
)
"""The named crash points of the writers (see :func:`crash_point`)."""

_hits: dict[str, int] = {}


def crash_point(name: str) -> None:
    """SIGKILL this process if ``PARKNSS_CRASH_AT`` names ``name`` and this is the N-th
    time it is reached (a test hook; a no-op when the variable is unset)."""
    want = os.environ.get(CRASH_ENV)
    if not want:
        return
    point, _, count = want.partition(":")
    if point != name:
        return
    _hits[name] = _hits.get(name, 0) + 1
    if _hits[name] == (int(count) if count else 1):
        os.kill(os.getpid(), signal.SIGKILL)


# ------------------------------------------------------------------------- durable writes


def fsync_dir(folder: str | Path) -> None:
    """Make the entries of ``folder`` (a rename into it) durable."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:  # some filesystems refuse fsync on a folder; nothing more to do
        pass
    finally:
        os.close(fd)


def fsync_file(path: str | Path) -> None:
    """Flush the contents of the file ``path`` to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def replace(tmp: str | Path, path: str | Path) -> None:
    """Flush the finished file ``tmp``, rename it over ``path`` and flush the folder."""
    fsync_file(tmp)
    os.replace(tmp, path)
    fsync_dir(Path(path).parent)


def write_bytes(path: str | Path, data: bytes, crash: str | None = None) -> None:
    """Write ``data`` to ``path`` durably (temporary sibling, fsync, rename, fsync of the
    folder); ``crash`` names the crash point between the write and the rename."""
    p = Path(path)
    tmp = p.with_name(f".{p.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        if crash:
            crash_point(crash)
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    fsync_dir(p.parent)


def exchange(a: str | Path, b: str | Path) -> bool:
    """Swap the existing paths ``a`` and ``b`` in one atomic step (Linux ``renameat2`` with
    ``RENAME_EXCHANGE``), so that neither name is ever missing; False (nothing done) where
    the system or the filesystem cannot, and the caller renames in two steps."""
    fn = _renameat2()
    if fn is None:
        return False
    at_fdcwd, rename_exchange = -100, 2
    return fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0


_RENAMEAT2: list = []


def _renameat2():
    if not _RENAMEAT2:
        fn = None
        with contextlib.suppress(OSError, AttributeError):
            import ctypes

            fn = ctypes.CDLL(None, use_errno=True).renameat2
            fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                           ctypes.c_uint]
            fn.restype = ctypes.c_int
        _RENAMEAT2.append(fn)
    return _RENAMEAT2[0]


def fsync_tree(folder: str | Path) -> None:
    """Flush every file and folder under ``folder`` (before it is renamed into place)."""
    root = Path(folder)
    for dirpath, _dirs, files in os.walk(root):
        for name in files:
            p = Path(dirpath) / name
            if not p.is_symlink():
                fsync_file(p)
        fsync_dir(dirpath)


# ------------------------------------------------------------------------------ manifests

MANIFEST = "SHA256SUMS"
"""The manifest of an artefact folder: ``<sha256>  <relative path>`` per file."""

_LINE = re.compile(r"^([0-9a-f]{64})  (\S(?:.*\S)?)$")


def sha256_file(path: str | Path) -> str:
    """The SHA-256 (hex) of the file ``path``, read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _members(folder: Path) -> list[str]:
    """Every regular file under ``folder`` except its own manifest and hidden temporary
    files, as sorted POSIX paths relative to ``folder``."""
    out = []
    for p in folder.rglob("*"):
        rel = p.relative_to(folder).as_posix()
        if rel == MANIFEST or any(part.startswith(".") for part in p.relative_to(folder).parts):
            continue
        if p.is_file() and not p.is_symlink():
            out.append(rel)
    return sorted(out)


def write_manifest(folder: str | Path) -> Path:
    """Write ``folder/SHA256SUMS`` over every other file under ``folder`` (durably); its
    path. Write it last, when every file of the artefact is in place."""
    root = Path(folder)
    lines = [f"{sha256_file(root / rel)}  {rel}\n" for rel in _members(root)]
    path = root / MANIFEST
    write_bytes(path, "".join(lines).encode())
    return path


def read_manifest(folder: str | Path) -> dict[str, str]:
    """``{relative path: sha256}`` of ``folder/SHA256SUMS``; a one-line
    :class:`CheckpointError` when it is absent or malformed (a line that is not
    ``<64 hex>  <path>``, or a path that leaves the folder)."""
    root = Path(folder)
    path = root / MANIFEST
    if not path.is_file():
        raise CheckpointError(
            f"{root}: no {MANIFEST} (the SHA-256 of its files); the artefact was written by "
            f"an older parknss or its manifest was removed: if you trust its files, write one "
            f"with `cd {root} && sha256sum $(find . -type f ! -name {MANIFEST} "
            f"! -name '.*' | sort) > {MANIFEST}`"
        )
    out: dict[str, str] = {}
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: unreadable manifest ({exc.__class__.__name__})") from exc
    for n, line in enumerate(text.splitlines(), 1):
        m = _LINE.match(line)
        rel = m.group(2).removeprefix("./") if m else ""
        parts = Path(rel).parts
        if not m or Path(rel).is_absolute() or ".." in parts or rel in out:
            raise CheckpointError(f"{path}: malformed line {n} (want '<sha256>  <file>')")
        out[rel] = m.group(1)
    return out


def verify_manifest(folder: str | Path, required: Iterable[str] = ()) -> dict[str, str]:
    """Check every file ``folder/SHA256SUMS`` lists against its SHA-256; the manifest.

    Args:
        folder: the artefact folder.
        required: files (relative POSIX paths) the loader will read; each must be listed.

    Raises:
        CheckpointError: one line naming the first file that is missing, unlisted or
            differs (edited, truncated or swapped), or what is wrong with the manifest.
    """
    root = Path(folder)
    sums = read_manifest(root)
    for rel in required:
        if rel not in sums:
            raise CheckpointError(f"{root / MANIFEST}: does not list {rel}; refusing the artefact")
    for rel, want in sums.items():
        p = root / rel
        if not p.is_file():
            raise CheckpointError(f"{p}: listed in {MANIFEST} but missing")
        if sha256_file(p) != want:
            raise CheckpointError(
                f"{p}: differs from the SHA-256 its {MANIFEST} records (edited, truncated or "
                "swapped); refusing the artefact"
            )
    return sums
