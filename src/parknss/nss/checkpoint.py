"""The NSS model artefact: ``model.safetensors`` + ``model.json`` in one folder.

The safetensors file holds the weights and nothing else; the JSON beside it holds the
configuration, the normalizer statistics, the vehicle geometry, the channel-schema
version, the weights' SHA-256 and shapes, and the training metadata (epochs, best epoch,
wall time, seed, data hash, git revision). Nothing is ever pickled.

:func:`load_model` refuses, with one-line :class:`~parknss.errors.CheckpointError`s, a
folder without the files, malformed JSON, another format or schema version, a config or
normalizer that is invalid or does not belong together, a weights file whose hash does
not match (corrupt or truncated), and weights whose names or shapes do not fit the model
the config describes.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import torch
from pydantic import ValidationError
from safetensors.torch import load_file, save_file

from parknss.config import REPO_ROOT
from parknss.data.normalize import Normalizer
from parknss.errors import CheckpointError
from parknss.nss.config import NSSConfig
from parknss.nss.model import NORMALIZED, NSSModel
from parknss.signals import SCHEMA_VERSION
from parknss.vehicle import VehicleGeometry

FORMAT = "parknss-nss"
FORMAT_VERSION = 1
WEIGHTS = "model.safetensors"
META = "model.json"


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def git_revision() -> str:
    """HEAD of the source checkout, or 'unknown' outside a git checkout."""
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def atomic_save_tensors(tensors: dict[str, torch.Tensor], path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    save_file({k: v.detach().contiguous() for k, v in tensors.items()}, str(tmp))
    os.replace(tmp, path)


@dataclass
class LoadedModel:
    """A model ready for inference with everything its JSON said."""

    model: NSSModel
    config: NSSConfig
    normalizer: Normalizer
    geometry: VehicleGeometry
    training: dict = field(default_factory=dict)
    path: Path | None = None


def save_model(
    folder: str | Path,
    model: NSSModel,
    config: NSSConfig,
    training: dict | None = None,
) -> Path:
    """Write model.safetensors and model.json into ``folder``; return the folder."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    state = {k: v for k, v in model.state_dict().items()}
    atomic_save_tensors(state, out / WEIGHTS)
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "schema_version": SCHEMA_VERSION,
        "config": config.model_dump(mode="json"),
        "normalizer": model.normalizer.to_json(),
        "geometry": model.geometry.to_dict(),
        "weights": {
            "file": WEIGHTS,
            "sha256": sha256_file(out / WEIGHTS),
            "dtype": str(model.dtype).removeprefix("torch."),
            "shapes": {k: list(v.shape) for k, v in state.items()},
        },
        "training": {"git_revision": git_revision(), **(training or {})},
    }
    atomic_write_text(out / META, json.dumps(meta, indent=2))
    return out


def _meta_path(path: str | Path) -> Path:
    p = Path(path)
    if p.is_dir():
        p = p / META
    if not p.is_file():
        raise CheckpointError(f"{p}: model file not found")
    return p


def _check_header(meta: dict, src: Path) -> None:
    fmt = meta.get("format") if isinstance(meta, dict) else None
    if fmt != FORMAT:
        raise CheckpointError(f"{src}: not a parknss NSS model (format {fmt!r})")
    if meta.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"{src}: model format version {meta.get('format_version')!r}, "
            f"this parknss reads {FORMAT_VERSION}"
        )
    if meta.get("schema_version") != SCHEMA_VERSION:
        raise CheckpointError(
            f"{src}: channel schema version {meta.get('schema_version')!r} does not match "
            f"this parknss ({SCHEMA_VERSION!r}); retrain the model"
        )


def _check_normalizer(norm: Normalizer, cfg: NSSConfig, src: Path) -> None:
    missing = [c for c in NORMALIZED if c not in norm.channels]
    if missing:
        raise CheckpointError(f"{src}: normalizer lacks channel(s) {', '.join(missing)}")
    if norm.kind != cfg.data.normalizer:
        raise CheckpointError(
            f"{src}: normalizer kind {norm.kind!r} does not match the config's "
            f"{cfg.data.normalizer!r}"
        )
    if norm.kind == "clipped" and tuple(norm.percentiles) != tuple(cfg.data.clip_percentiles):
        raise CheckpointError(
            f"{src}: normalizer percentiles {list(norm.percentiles)} do not match the "
            f"config's {list(cfg.data.clip_percentiles)}"
        )


def _load_weights(meta: dict, src: Path) -> dict[str, torch.Tensor]:
    w = meta.get("weights")
    if not isinstance(w, dict) or "sha256" not in w:
        raise CheckpointError(f"{src}: no weights entry")
    wpath = src.parent / str(w.get("file", WEIGHTS))
    if not wpath.is_file():
        raise CheckpointError(f"{wpath}: weights file not found")
    if sha256_file(wpath) != w["sha256"]:
        raise CheckpointError(f"{wpath}: weights are corrupt or truncated (SHA-256 mismatch)")
    try:
        return load_file(str(wpath))
    except Exception as exc:  # safetensors raises its own error types
        raise CheckpointError(f"{wpath}: unreadable safetensors file ({exc})") from exc


def _check_shapes(model: NSSModel, tensors: dict[str, torch.Tensor], src: Path) -> None:
    want = {k: tuple(v.shape) for k, v in model.state_dict().items()}
    have = {k: tuple(v.shape) for k, v in tensors.items()}
    for k in sorted(set(want) | set(have)):
        if k not in have:
            raise CheckpointError(f"{src}: weights lack {k!r} (shape {want[k]})")
        if k not in want:
            raise CheckpointError(f"{src}: unexpected weight {k!r} for this configuration")
        if want[k] != have[k]:
            raise CheckpointError(
                f"{src}: weight {k!r} has shape {have[k]}, the config needs {want[k]}"
            )


def load_model(path: str | Path) -> LoadedModel:
    """Load a model folder (or its model.json) for inference (eval mode, no gradients)."""
    src = _meta_path(path)
    try:
        meta = json.loads(src.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{src}: malformed JSON ({exc.__class__.__name__})") from exc
    _check_header(meta, src)
    try:
        cfg = NSSConfig.model_validate(meta.get("config"))
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        raise CheckpointError(f"{src}: invalid config field {loc!r}: {err['msg']}") from exc
    try:
        norm = Normalizer.from_json(meta.get("normalizer") or {})
    except CheckpointError as exc:
        raise CheckpointError(f"{src}: {exc}") from exc
    _check_normalizer(norm, cfg, src)
    try:
        geom = VehicleGeometry.from_dict(meta.get("geometry") or {})
    except (TypeError, ValueError, AttributeError) as exc:  # AttributeError: not an object
        raise CheckpointError(f"{src}: invalid vehicle geometry ({exc})") from exc
    tensors = _load_weights(meta, src)
    model = NSSModel(cfg.model, norm, geom)
    dtype = next(iter(tensors.values())).dtype if tensors else torch.float32
    model.to(dtype)
    _check_shapes(model, tensors, src)
    model.load_state_dict(tensors)
    model.eval()
    model.requires_grad_(False)
    return LoadedModel(model, cfg, norm, geom, dict(meta.get("training") or {}), src.parent)
