"""The file layout of a fit's resumable state, without torch: the names, the generation
JSON's format, which tensor file a JSON names, and the commit that makes a new generation
the newest (:mod:`parknss.nss.train_state` writes and reads the tensors; the result store's
parked states, :mod:`parknss.experiments.parked`, copy and check states with this module
alone, so that ``parknss results list`` starts without torch)."""

from __future__ import annotations

import json
import os
from pathlib import Path

from parknss import durable
from parknss.errors import CheckpointError

FORMAT = "parknss-nss-train-state/1"
TENSORS = "train_state.safetensors"
"""The tensor file of a state written before generations (a JSON without ``tensors``)."""
META = "train_state.json"
PREV_META = "train_state.prev.json"
"""The JSON of the generation before the newest, kept until the next commit."""


def exists(folder: Path) -> bool:
    return (Path(folder) / META).is_file() or (Path(folder) / PREV_META).is_file()


def tensors_name(meta: dict) -> str:
    """The tensor file a state JSON names (:data:`TENSORS` for a state written before
    generations); a :class:`CheckpointError` for a name that is not a plain file name."""
    name = meta.get("tensors", TENSORS)
    plain = isinstance(name, str) and "/" not in name and "\\" not in name
    if not (plain and name.startswith("train_state.") and name.endswith(".safetensors")):
        raise CheckpointError(f"training state names an invalid tensor file {name!r}")
    return name


def tensors_path(folder: Path) -> Path | None:
    """The tensor file of the newest state in ``folder`` (None: no readable JSON)."""
    try:
        return Path(folder) / tensors_name(json.loads((Path(folder) / META).read_text()))
    except (OSError, ValueError, CheckpointError, AttributeError):
        return None


def commit(folder: Path, meta: bytes, keep_previous: bool = True) -> None:
    """Make ``meta`` (a state JSON whose tensor file is already in ``folder``, durably) the
    newest generation: keep the JSON in place as :data:`PREV_META`, rename the new one over
    :data:`META`, then delete the tensor files neither names (see the module doc).
    ``keep_previous=False`` (a parked copy, committed to git): drop the previous
    generation once the new one is in place."""
    folder = Path(folder)
    cur = folder / META
    if cur.is_file():
        durable.write_bytes(folder / PREV_META, cur.read_bytes())
        durable.crash_point("train_state.prev")
    durable.write_bytes(cur, meta, crash="train_state.meta_tmp")
    durable.crash_point("train_state.meta")
    if not keep_previous:
        (folder / PREV_META).unlink(missing_ok=True)
    keep = set()
    for name in (META, PREV_META):
        try:
            keep.add(tensors_name(json.loads((folder / name).read_text())))
        except (OSError, ValueError, CheckpointError, AttributeError):
            continue
    for p in folder.glob("train_state*.safetensors"):
        if p.name not in keep:
            p.unlink(missing_ok=True)
    for p in folder.glob(".train_state*.tmp-*"):  # a killed writer's temporary file
        if not p.name.endswith(f".tmp-{os.getpid()}"):
            p.unlink(missing_ok=True)
