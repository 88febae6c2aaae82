"""The NSS model artefact: ``model.safetensors`` + ``model.json`` + ``SHA256SUMS`` in one
folder.

The safetensors file holds the weights and nothing else; the JSON beside it holds the
configuration, the normalizer statistics, the vehicle geometry, the channel-schema
version, the weights' SHA-256 and shapes, and the training metadata (epochs, best epoch,
wall time, seed, data hash, git revision); ``SHA256SUMS`` (:mod:`parknss.durable`) holds
the SHA-256 of both, so an edited normaliser scale is caught like swapped weights.
Nothing is ever pickled. :func:`save_model` writes the folder into a temporary sibling,
flushes it and renames it into place (:func:`parknss.outputs.artefact_folder`): a kill
leaves the old folder or the new one, whole.

:func:`load_model` refuses, with one-line :class:`~parknss.errors.CheckpointError`s, and
before it allocates the model: a folder without the files or the manifest, a file that
differs from the manifest, malformed JSON, another format or schema version, a config or
normalizer that is invalid or does not belong together, a config whose sizes exceed
:data:`MAX_LAYERS` / :data:`MAX_UNITS`, a weights file whose hash does not match (corrupt
or truncated), a safetensors header that is malformed, holds other dtypes than float32 /
float64 (:data:`FLOAT_DTYPES`) or names or shapes that do not fit the model the config
describes (read from the header, without loading the tensors); and, once loaded, weights
that are not finite (NaN or infinity).
"""

from __future__ import annotations

import json
import struct
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import torch
from pydantic import ValidationError
from safetensors.torch import load_file
from safetensors.torch import save as save_bytes

from parknss import durable
from parknss.config import REPO_ROOT
from parknss.data.normalize import Normalizer
from parknss.errors import CheckpointError
from parknss.nss.config import NSSConfig
from parknss.nss.model import NORMALIZED, NSSModel
from parknss.outputs import artefact_folder
from parknss.signals import SCHEMA_VERSION
from parknss.vehicle import VehicleGeometry

FORMAT = "parknss-nss"
FORMAT_VERSION = 1
WEIGHTS = "model.safetensors"
META = "model.json"

MAX_LAYERS = 16
"""The most hidden layers a loaded network (state or output net, an actuator MLP) may have
(the paper's state net has 6); a config asking more is refused before anything is built."""
MAX_UNITS = 1024
"""The most units a hidden layer of a loaded network may have (the paper's: 128)."""
MAX_HEADER_BYTES = 16 << 20
"""The largest safetensors header (JSON) read; a model's is a few kB."""
FLOAT_DTYPES: dict[str, torch.dtype] = {"F32": torch.float32, "F64": torch.float64}
"""The safetensors dtypes of loadable weights."""

sha256_file = durable.sha256_file


def git_revision() -> str:
    """HEAD of the source checkout, or 'unknown' outside a git checkout."""
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` durably (:func:`parknss.durable.write_bytes`)."""
    durable.write_bytes(path, text.encode())


def atomic_save_tensors(tensors: dict[str, torch.Tensor], path: Path) -> None:
    """Write ``tensors`` as safetensors to ``path`` durably."""
    durable.write_bytes(path, save_bytes({k: v.detach().contiguous() for k, v in tensors.items()}))


def safetensors_header(path: Path) -> dict[str, tuple[str, tuple[int, ...]]]:
    """``{name: (dtype, shape)}`` of the safetensors file ``path``, read from its header
    (an 8-byte little-endian length, then JSON) without loading a tensor; a one-line
    :class:`CheckpointError` for a header that is malformed or does not fit the file."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(8)
            n = struct.unpack("<Q", head)[0] if len(head) == 8 else -1
            if n < 2 or n > min(size - 8, MAX_HEADER_BYTES):
                raise ValueError(f"header length {n} for a {size}-byte file")
            doc = json.loads(f.read(n))
        if not isinstance(doc, dict):
            raise ValueError("header is not a JSON object")
        out, body = {}, size - 8 - n
        for name, t in doc.items():
            if name == "__metadata__":
                continue
            dtype, shape, (a, b) = t["dtype"], t["shape"], t["data_offsets"]
            if not (isinstance(dtype, str) and isinstance(shape, list)
                    and all(isinstance(d, int) and d >= 0 for d in shape)
                    and isinstance(a, int) and isinstance(b, int) and 0 <= a <= b <= body):
                raise ValueError(f"entry {name!r}")
            out[str(name)] = (dtype, tuple(shape))
    except OSError as exc:
        raise CheckpointError(f"{path}: unreadable ({exc.__class__.__name__})") from exc
    except (ValueError, KeyError, TypeError, struct.error, RecursionError) as exc:
        raise CheckpointError(f"{path}: malformed safetensors header ({exc})") from exc
    return out


def check_float_dtypes(header: dict[str, tuple[str, tuple[int, ...]]], path: Path) -> torch.dtype:
    """The one float dtype of every tensor in ``header``; a one-line :class:`CheckpointError`
    for another dtype (int32, float16, ...) or a mix."""
    kinds = sorted({d for d, _ in header.values()})
    bad = [d for d in kinds if d not in FLOAT_DTYPES]
    if bad:
        name = next(k for k, (d, _) in header.items() if d == bad[0])
        raise CheckpointError(f"{path}: weight {name!r} is stored as {bad[0]}; parknss weights "
                              f"are {' or '.join(FLOAT_DTYPES)}")
    if len(kinds) > 1:
        raise CheckpointError(f"{path}: weights mix dtypes {', '.join(kinds)}")
    return FLOAT_DTYPES[kinds[0]] if kinds else torch.float32


def check_finite(tensors: dict[str, torch.Tensor], path: Path) -> None:
    """A one-line :class:`CheckpointError` naming the first weight holding NaN or inf."""
    for k in sorted(tensors):
        v = tensors[k]
        if v.is_floating_point() and not bool(torch.isfinite(v).all()):
            raise CheckpointError(f"{path}: weight {k!r} holds NaN or infinite values")


def check_size(what: str, value: int, limit: int, src: Path) -> None:
    """A one-line :class:`CheckpointError` when the config size ``what`` exceeds ``limit``."""
    if value > limit:
        raise CheckpointError(f"{src}: {what} = {value} exceeds the limit {limit}; refusing to "
                              "build the model")


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
    """Write model.safetensors, model.json and SHA256SUMS as the folder ``folder`` (whose
    earlier content it replaces, atomically); return the folder."""
    with artefact_folder(folder, overwrite=True, kind="model") as tmp:
        _write_model(tmp, model, config, training)
    return Path(folder)


def _write_model(out: Path, model: NSSModel, config: NSSConfig, training: dict | None) -> None:
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
    durable.write_manifest(out)


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


def _weights_path(meta: dict, src: Path) -> Path:
    w = meta.get("weights")
    if not isinstance(w, dict) or "sha256" not in w:
        raise CheckpointError(f"{src}: no weights entry")
    name = str(w.get("file", WEIGHTS))
    if name != WEIGHTS:
        raise CheckpointError(f"{src}: weights file {name!r}, a model's is {WEIGHTS!r}")
    wpath = src.parent / name
    if not wpath.is_file():
        raise CheckpointError(f"{wpath}: weights file not found")
    if sha256_file(wpath) != w["sha256"]:
        raise CheckpointError(f"{wpath}: weights are corrupt or truncated (SHA-256 mismatch)")
    return wpath


def _load_weights(wpath: Path) -> dict[str, torch.Tensor]:
    try:
        tensors = load_file(str(wpath))
    except Exception as exc:  # safetensors raises its own error types
        raise CheckpointError(f"{wpath}: unreadable safetensors file ({exc})") from exc
    check_finite(tensors, wpath)
    return tensors


def _check_sizes(cfg: NSSConfig, src: Path) -> None:
    m = cfg.model
    for net in ("state", "output"):
        check_size(f"model.{net}_layers", getattr(m, f"{net}_layers"), MAX_LAYERS, src)
        check_size(f"model.{net}_units", getattr(m, f"{net}_units"), MAX_UNITS, src)


def _check_shapes(model: NSSModel, header: dict[str, tuple[str, tuple[int, ...]]],
                  src: Path) -> None:
    want = {k: tuple(v.shape) for k, v in model.state_dict().items()}
    have = {k: shape for k, (_, shape) in header.items()}
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
    durable.verify_manifest(src.parent, required=(src.name, WEIGHTS))
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
    _check_sizes(cfg, src)
    try:
        norm = Normalizer.from_json(meta.get("normalizer") or {})
    except CheckpointError as exc:
        raise CheckpointError(f"{src}: {exc}") from exc
    _check_normalizer(norm, cfg, src)
    try:
        geom = VehicleGeometry.from_dict(meta.get("geometry") or {})
    except (TypeError, ValueError, AttributeError) as exc:  # AttributeError: not an object
        raise CheckpointError(f"{src}: invalid vehicle geometry ({exc})") from exc
    wpath = _weights_path(meta, src)
    header = safetensors_header(wpath)
    dtype = check_float_dtypes(header, wpath)
    model = NSSModel(cfg.model, norm, geom)
    model.to(dtype)
    _check_shapes(model, header, src)
    model.load_state_dict(_load_weights(wpath))
    model.eval()
    model.requires_grad_(False)
    return LoadedModel(model, cfg, norm, geom, dict(meta.get("training") or {}), src.parent)
