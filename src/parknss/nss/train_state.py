"""The resumable state of a fit: ``train_state.safetensors`` + ``train_state.json``.

Tensors (current weights ``model/*``, best weights ``best/*``, Adam moments and step
counts ``opt/<i>/*``, the torch RNG ``rng/torch``) go into safetensors; the step, the
history, the optimizer's hyper-parameters, the wall and CPU time and a fingerprint of the
configuration and data go into the JSON, with the SHA-256 of the tensor file so that a
torn pair is detected. A state is resumed only by a fit whose fingerprint matches.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import torch
from safetensors.torch import load_file

from parknss.errors import CheckpointError
from parknss.nss.checkpoint import atomic_save_tensors, atomic_write_text, sha256_file
from parknss.nss.config import NSSConfig, fit_identity
from parknss.nss.history import History
from parknss.nss.model import NSSModel

FORMAT = "parknss-nss-train-state/1"
TENSORS = "train_state.safetensors"
META = "train_state.json"


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


def exists(folder: Path) -> bool:
    return (Path(folder) / META).is_file()


@dataclass
class State:
    epoch: int
    history: History
    best: dict[str, torch.Tensor] | None
    wall_s: float
    cpu_s: float | None  # CPU time of the fit so far; None for a state written without it


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
) -> None:
    """Write the state after ``epoch`` (weights are θ_{epoch+1}, i.e. after its step)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tensors: dict[str, torch.Tensor] = {f"model/{k}": v for k, v in model.state_dict().items()}
    if best is not None:
        tensors.update({f"best/{k}": v for k, v in best.items()})
    sd = opt.state_dict()
    for i, st in sd["state"].items():
        for k, v in st.items():
            tensors[f"opt/{i}/{k}"] = v if torch.is_tensor(v) else torch.tensor(v)
    tensors["rng/torch"] = torch.get_rng_state()
    atomic_save_tensors(tensors, folder / TENSORS)
    meta = {
        "format": FORMAT,
        "epoch": epoch,
        "wall_s": wall_s,
        "cpu_s": cpu_s,
        "fingerprint": fp,
        "has_best": best is not None,
        "param_groups": sd["param_groups"],
        "history": hist.to_json(),
        "sha256": sha256_file(folder / TENSORS),
    }
    atomic_write_text(folder / META, json.dumps(meta))


def load(folder: Path, model: NSSModel, opt: torch.optim.Optimizer, fp: str) -> State:
    """Restore model and optimizer in place; return the epoch, history and best weights."""
    folder = Path(folder)
    src = folder / META
    try:
        meta = json.loads(src.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{src}: unreadable training state ({exc})") from exc
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"{src}: not a parknss training state")
    if meta.get("fingerprint") != fp:
        raise CheckpointError(
            f"{src}: training state belongs to another config, data or split; "
            "remove it or train without --resume"
        )
    tpath = folder / TENSORS
    if not tpath.is_file() or sha256_file(tpath) != meta.get("sha256"):
        raise CheckpointError(f"{tpath}: training state is corrupt or truncated")
    try:
        t = load_file(str(tpath))
    except Exception as exc:  # safetensors raises its own error types
        raise CheckpointError(f"{tpath}: unreadable safetensors file ({exc})") from exc
    model.load_state_dict({k[6:]: v for k, v in t.items() if k.startswith("model/")})
    best = {k[5:]: v for k, v in t.items() if k.startswith("best/")} if meta["has_best"] else None
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
    )
