"""The resumable state of a fit: ``train_state.json`` naming its tensor file.

Tensors (current weights ``model/*``, best weights ``best/*``, Adam moments and step
counts ``opt/<i>/*``, the torch RNG ``rng/torch``, the weight average ``avg/*`` of a fit
with ``fast.ema``) go into a safetensors file named after
its content, ``train_state.<sha256[:16]>.safetensors``; the step, the history, the
optimizer's hyper-parameters, the wall and CPU time, a fingerprint of the configuration
and data, the tensor file's name and its SHA-256 go into ``train_state.json``. A state is
resumed only by a fit whose fingerprint matches.

Crash consistency: a write is a new *generation*. The tensors go to their new file first
(temporary sibling, fsync, rename); the JSON in place is kept as ``train_state.prev.json``;
then the new JSON replaces ``train_state.json`` by one durable rename, the commit; only
then are tensor files that neither JSON names deleted. So at every instant
``train_state.json`` names a complete tensor file: a kill anywhere (the crash points
``train_state.*`` of :mod:`parknss.durable` hit every window in the tests) leaves the old
or the new state whole. :func:`load` verifies the tensors against the SHA-256 the JSON
records; when the newest generation is unusable all the same (a file damaged on disk) and
the previous one is whole, it resumes from the previous one and says so on stderr; when
neither is, it refuses in one line. States written before generations existed (the tensors
in ``train_state.safetensors``) load as before.
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import torch
from safetensors.torch import load as load_bytes
from safetensors.torch import save as save_bytes

from parknss import durable
from parknss.errors import CheckpointError
from parknss.nss.config import NSSConfig, fit_identity
from parknss.nss.history import History
from parknss.nss.model import NSSModel
from parknss.nss.state_files import (  # noqa: F401 (the layout, re-exported)
    FORMAT,
    META,
    PREV_META,
    TENSORS,
    commit,
    exists,
    tensors_name,
    tensors_path,
)


def fingerprint(
    cfg: NSSConfig, data_hash: str, train_ids: list[str], val_ids: list[str], L: int
) -> str:
    """Hash of everything a resumed fit must share (:func:`fit_identity` of the config, the
    data, the split). A paper-recipe fit's fingerprint is the one it had before the
    recipes existed."""
    doc = fit_identity(cfg)
    blob = json.dumps(
        {"cfg": doc, "data": data_hash, "train": train_ids, "val": val_ids, "L": L},
        sort_keys=True,
    ).encode()
    return hashlib.sha256(blob).hexdigest()


@dataclass
class State:
    epoch: int
    history: History
    best: dict[str, torch.Tensor] | None
    wall_s: float
    cpu_s: float | None  # CPU time of the fit so far; None for a state written without it
    note: str = ""  # non-empty when the newest generation was unusable and the previous used
    avg: dict[str, torch.Tensor] | None = None  # the weight average (fast.ema), if any


def save(
    folder: Path,
    model: NSSModel,
    opt: torch.optim.Optimizer,
    hist: History,
    best: dict[str, torch.Tensor] | None,
    epoch: int,
    wall_s: float,
    fp: str,
    cpu_s: float | None = None,
    avg: dict[str, torch.Tensor] | None = None,
) -> None:
    """Write the state after ``epoch`` (weights are θ_{epoch+1}, i.e. after its step);
    ``avg``: the weight average of a fit with ``fast.ema``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tensors: dict[str, torch.Tensor] = {f"model/{k}": v for k, v in model.state_dict().items()}
    if best is not None:
        tensors.update({f"best/{k}": v for k, v in best.items()})
    if avg is not None:
        tensors.update({f"avg/{k}": v for k, v in avg.items()})
    sd = opt.state_dict()
    for i, st in sd["state"].items():
        for k, v in st.items():
            tensors[f"opt/{i}/{k}"] = v if torch.is_tensor(v) else torch.tensor(v)
    tensors["rng/torch"] = torch.get_rng_state()
    blob = save_bytes({k: v.detach().contiguous() for k, v in tensors.items()})
    sha = hashlib.sha256(blob).hexdigest()
    name = f"train_state.{sha[:16]}.safetensors"
    durable.write_bytes(folder / name, blob, crash="train_state.tensors_tmp")
    durable.crash_point("train_state.tensors")
    meta = {
        "format": FORMAT,
        "epoch": epoch,
        "wall_s": wall_s,
        "cpu_s": cpu_s,
        "fingerprint": fp,
        "has_best": best is not None,
        "param_groups": sd["param_groups"],
        "history": hist.to_json(),
        "tensors": name,
        "sha256": sha,
    }
    commit(folder, json.dumps(meta).encode())


def _read(folder: Path, src: Path, fp: str) -> tuple[dict, dict[str, torch.Tensor]]:
    """The JSON and the verified tensors of the generation ``src`` names."""
    try:
        meta = json.loads(src.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{src}: unreadable training state ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"{src}: not a parknss training state")
    if meta.get("fingerprint") != fp:
        raise _ForeignError(
            f"{src}: training state belongs to another config, data or split; "
            "remove it or train without --resume"
        )
    try:
        tpath = folder / tensors_name(meta)
    except CheckpointError as exc:
        raise CheckpointError(f"{src}: {exc}") from exc
    try:
        blob = tpath.read_bytes()
    except OSError:
        blob = b""
    if hashlib.sha256(blob).hexdigest() != meta.get("sha256"):
        raise CheckpointError(f"{tpath}: training state is corrupt or truncated")
    try:
        return meta, load_bytes(blob)
    except Exception as exc:  # safetensors raises its own error types
        raise CheckpointError(f"{tpath}: unreadable safetensors file ({exc})") from exc


class _ForeignError(CheckpointError):
    """A state of another fit (never replaced by an older generation)."""


def load(folder: Path, model: NSSModel, opt: torch.optim.Optimizer, fp: str) -> State:
    """Restore model and optimizer in place; return the epoch, history and best weights.

    The newest generation (:data:`META`) is used when it is whole; else the previous one
    (:data:`PREV_META`), with a one-line note on stderr (and in :attr:`State.note`); else a
    one-line :class:`CheckpointError` naming what is wrong with the newest."""
    folder = Path(folder)
    first: CheckpointError | None = None
    for src in (folder / META, folder / PREV_META):
        if not src.is_file() and src.name == PREV_META:
            break
        try:
            meta, t = _read(folder, src, fp)
        except _ForeignError:
            raise
        except CheckpointError as exc:
            first = first or exc
            continue
        note = ""
        if first is not None:
            note = (f"{folder}: the newest training state is unusable ({first}); resuming "
                    f"from the previous one, step {meta.get('epoch')}")
            print(f"parknss: note: {note}", file=sys.stderr)
        return _restore(meta, t, model, opt, note)
    assert first is not None
    raise first


def _restore(meta: dict, t: dict[str, torch.Tensor], model: NSSModel,
             opt: torch.optim.Optimizer, note: str) -> State:
    model.load_state_dict({k[6:]: v for k, v in t.items() if k.startswith("model/")})
    best = {k[5:]: v for k, v in t.items() if k.startswith("best/")} if meta["has_best"] else None
    avg = {k[4:]: v for k, v in t.items() if k.startswith("avg/")} or None
    state: dict[int, dict] = {}
    for k, v in t.items():
        if k.startswith("opt/"):
            _, i, name = k.split("/", 2)
            state.setdefault(int(i), {})[name] = v
    opt.load_state_dict({"state": state, "param_groups": meta["param_groups"]})
    torch.set_rng_state(t["rng/torch"])
    cpu = meta.get("cpu_s")
    return State(
        int(meta["epoch"]),
        History.from_json(meta["history"]),
        best,
        float(meta["wall_s"]),
        None if cpu is None else float(cpu),
        note,
        avg,
    )
