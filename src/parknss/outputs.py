"""Artefact folders written atomically, never over another artefact without ``--overwrite``.

Every command that writes an artefact folder (a campaign, a model, a chain, a run) writes
it through :func:`artefact_folder`::

    with artefact_folder(out, overwrite=overwrite, kind="campaign") as tmp:
        write_campaign(campaign, tmp)          # everything goes into tmp

The writer fills a fresh temporary sibling ``.<name>.tmp-<pid>``; only when it returns
normally is that folder renamed into place as ``out``. A writer that fails (or is
interrupted) leaves ``out`` as it was and the temporary folder deleted; one that is killed
leaves ``out`` as it was and a stale temporary folder, which the next writer of ``out``
removes. An ``out`` that already holds something is refused with a one-line
:class:`OutputExistsError` unless ``overwrite=True``; then the old folder is renamed away
(``.<name>.old-<pid>``), the new one renamed in and only then the old one deleted, so a
crash at any point leaves either the old or the new artefact whole (a crash between the
two renames leaves the old one under its ``.old`` name; the next writer of ``out`` puts it
back before it looks at ``out``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

from parknss.errors import ParknssError

MARKERS: tuple[tuple[str, str], ...] = (
    ("campaign.json", "campaign"),
    ("model.json", "model"),
    ("chain.json", "chain"),
)
"""(file, what) pairs that identify an artefact folder, checked in this order."""


class OutputExistsError(ParknssError):
    """The output folder holds something already and ``--overwrite`` was not given."""


def describe_contents(out: str | Path) -> str | None:
    """What the existing path ``out`` holds, for a message (``"a campaign (campaign.json)"``,
    ``"a run (3 entries)"``, ``"a file"``), or None when it is absent or an empty folder."""
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
    renamed away (``.<name>.old-<pid>``) when ``out`` is missing, delete the rest."""
    out = Path(out)
    parent = out.absolute().parent
    if not parent.is_dir():
        return
    for kind in ("old", "tmp"):
        for p in sorted(parent.glob(f".{out.name}.{kind}-*")):
            pid = p.name.rsplit("-", 1)[-1]
            if not pid.isdigit() or _alive(int(pid)):
                continue
            if kind == "old" and not out.exists() and not out.is_symlink():
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
        check_writable(out, overwrite=overwrite, kind=kind)
        if describe_contents(out) is None:
            _remove(out)  # absent, or an empty folder: nothing to keep
            os.replace(tmp, out)
            return
        _remove(old)
        os.replace(out, old)
        try:
            os.replace(tmp, out)
        except BaseException:
            os.replace(old, out)
            raise
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
