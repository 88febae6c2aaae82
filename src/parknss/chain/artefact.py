"""The chain artefact: one folder, safetensors weights + JSON, never pickle.

Layout::

    chain.json              format, schema version, envelope, per-channel candidate
                            (spec, scaling, structure config), weights SHA-256 and shapes,
                            the NSS's SHA-256, and the build's metadata (selection,
                            co-tuning, data hash, timings)
    actuators.safetensors   the three submodels' weights ("drive.k", "brake.net.0.weight")
    nss/                    the frozen NSS in its own format (parknss.nss.checkpoint),
                            with its own SHA256SUMS
    SHA256SUMS              the SHA-256 of every other file, nss/ included
                            (parknss.durable), written last

:func:`read_chain` refuses, with one-line :class:`~parknss.errors.CheckpointError`s, a
missing folder or file, a file that differs from the manifest (an edited chain.json or
nss/model.json, swapped weights), malformed JSON, another format or schema version, a
missing channel, a candidate whose sizes exceed the limits (:data:`MAX_LAGS`,
:data:`~parknss.nss.checkpoint.MAX_UNITS`, :data:`~parknss.nss.checkpoint.MAX_LAYERS`),
a hash mismatch (corrupt or truncated weights, or an NSS swapped underneath), weights
whose dtypes, names or shapes (read from the safetensors header before any tensor is
loaded) do not fit the recorded candidates, and weights that are not finite.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from pydantic import ValidationError
from safetensors.torch import load_file

from parknss.actuators.candidates import build_candidate
from parknss.actuators.config import ArchConfig
from parknss.actuators.envelopes import Envelope
from parknss.actuators.models import ActuatorModel, Scaling
from parknss.actuators.spec import CHANNELS, CandidateSpec
from parknss.chain.model import Chain, NSSProvenance
from parknss.durable import MANIFEST, verify_manifest, write_manifest
from parknss.errors import CheckpointError, ConfigError
from parknss.nss.checkpoint import (
    MAX_LAYERS,
    MAX_UNITS,
    atomic_save_tensors,
    atomic_write_text,
    check_finite,
    check_float_dtypes,
    check_size,
    git_revision,
    load_model,
    safetensors_header,
    save_model,
    sha256_file,
)
from parknss.nss.config import NSSConfig
from parknss.outputs import artefact_folder
from parknss.signals import DT, SCHEMA_VERSION

FORMAT = "parknss-chain"
FORMAT_VERSION = 1
META = "chain.json"
WEIGHTS = "actuators.safetensors"
NSS_DIR = "nss"
MAX_LAGS = 1000
"""The most lagged command samples a loaded NARX candidate may have (10 s; the paper's 5)."""
MEMBERS = (META, WEIGHTS, f"{NSS_DIR}/model.json", f"{NSS_DIR}/model.safetensors",
           f"{NSS_DIR}/{MANIFEST}")
"""The files a chain is made of, each listed in its manifest."""


def write_chain(folder: str | Path, chain: Chain, meta: dict) -> Path:
    """Write ``chain`` (all three submodels, and its NSS's provenance) as the folder
    ``folder``, whose earlier content it replaces atomically
    (:func:`~parknss.outputs.artefact_folder`); ``meta`` is the build's metadata (recorded
    under ``build``)."""
    out = Path(folder)
    missing = [c for c in CHANNELS if chain.model(c) is None]
    if missing:
        raise CheckpointError(f"{out}: a deployed chain needs all submodels; {missing} measured")
    cfg = chain.provenance.config
    if cfg is None:
        raise CheckpointError(f"{out}: the chain carries no NSS config (chain.provenance)")
    with artefact_folder(out, overwrite=True, kind="chain") as tmp:
        _write_chain(tmp, chain, cfg, meta)
    return out


def _write_chain(out: Path, chain: Chain, cfg: NSSConfig, meta: dict) -> None:
    save_model(out / NSS_DIR, chain.nss, cfg, chain.provenance.training)
    tensors, channels = {}, {}
    for ch in CHANNELS:
        m = chain.model(ch)
        for k, v in m.state_dict().items():
            tensors[f"{ch}.{k}"] = v.detach().to(torch.float64)
        channels[ch] = {
            "spec": m.spec.name,
            "scaling": m.scaling.to_json(),
            "arch": m.cfg.artefact_json(m.spec.arch),
        }
    atomic_save_tensors(tensors, out / WEIGHTS)
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "schema_version": SCHEMA_VERSION,
        "envelope": chain.envelope.to_json(),
        "channels": channels,
        "weights": {
            "file": WEIGHTS,
            "sha256": sha256_file(out / WEIGHTS),
            "shapes": {k: list(v.shape) for k, v in tensors.items()},
        },
        "nss": {"folder": NSS_DIR, "sha256": sha256_file(out / NSS_DIR / "model.safetensors")},
        "build": {"git_revision": git_revision(), **meta},
    }
    atomic_write_text(out / META, json.dumps(doc, indent=2))
    write_manifest(out)


def _read_meta(folder: Path) -> dict:
    if not folder.is_dir():
        raise CheckpointError(f"{folder}: chain folder not found")
    src = folder / META
    if not src.is_file():
        raise CheckpointError(f"{src}: chain file not found")
    try:
        doc = json.loads(src.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{src}: malformed JSON ({exc.__class__.__name__})") from exc
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise CheckpointError(f"{src}: not a parknss chain (format {doc.get('format')!r})")
    if doc.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(f"{src}: chain format version {doc.get('format_version')!r}, "
                              f"this parknss reads {FORMAT_VERSION}")
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise CheckpointError(f"{src}: channel schema version {doc.get('schema_version')!r} "
                              f"does not match this parknss ({SCHEMA_VERSION!r})")
    return doc


def _build_models(doc: dict, src: Path) -> dict[str, ActuatorModel]:
    chans = doc.get("channels")
    if not isinstance(chans, dict):
        raise CheckpointError(f"{src}: no channels entry")
    models = {}
    for ch in CHANNELS:
        d = chans.get(ch)
        if not isinstance(d, dict):
            raise CheckpointError(f"{src}: channel {ch!r} missing")
        try:
            spec = CandidateSpec.parse(str(d["spec"]))
            arch = ArchConfig.model_validate(d["arch"])
            scaling = Scaling.from_json(d["scaling"])
        except (KeyError, TypeError, ValueError, ValidationError, ConfigError) as exc:
            raise CheckpointError(f"{src}: channel {ch!r}: invalid entry ({exc})") from exc
        if spec.channel != ch:
            raise CheckpointError(f"{src}: channel {ch!r} holds a {spec.channel} candidate")
        _check_sizes(arch, f"{src}: channel {ch!r}")
        torch.manual_seed(0)
        models[ch] = build_candidate(spec, scaling, arch)
    return models


def _check_sizes(arch: ArchConfig, where: str) -> None:
    """Refuse, before a candidate is built, structure sizes beyond the documented limits."""
    src = Path(where)
    for name in ("hammerstein_hidden", "narx_hidden"):
        hidden = getattr(arch, name)
        check_size(f"arch.{name} layers", len(hidden), MAX_LAYERS, src)
        check_size(f"arch.{name} units", max(hidden, default=0), MAX_UNITS, src)
    for name in ("gru_hidden", "lstm_hidden"):
        check_size(f"arch.{name}", getattr(arch, name), MAX_UNITS, src)
    for name in ("narx_lags", "narx_long_lags"):
        check_size(f"arch.{name}", getattr(arch, name), MAX_LAGS, src)
    check_size("arch.monolag_knots", arch.monolag_knots, MAX_UNITS, src)
    check_size("arch.monolag_max_delay_s samples", round(arch.monolag_max_delay_s / DT),
               MAX_LAGS, src)


def _load_weights(doc: dict, folder: Path, models: dict[str, ActuatorModel]) -> None:
    w = doc.get("weights")
    if not isinstance(w, dict) or "sha256" not in w:
        raise CheckpointError(f"{folder / META}: no weights entry")
    if str(w.get("file", WEIGHTS)) != WEIGHTS:
        raise CheckpointError(f"{folder / META}: weights file {w.get('file')!r}, a chain's is "
                              f"{WEIGHTS!r}")
    wpath = folder / WEIGHTS
    if not wpath.is_file():
        raise CheckpointError(f"{wpath}: weights file not found")
    if sha256_file(wpath) != w["sha256"]:
        raise CheckpointError(f"{wpath}: weights are corrupt or truncated (SHA-256 mismatch)")
    header = safetensors_header(wpath)
    check_float_dtypes(header, wpath)
    for ch, m in models.items():
        want = {k: tuple(v.shape) for k, v in m.state_dict().items()}
        have = {k[len(ch) + 1 :]: s for k, (_, s) in header.items() if k.startswith(ch + ".")}
        for k in sorted(set(want) | set(have)):
            if k not in have:
                raise CheckpointError(f"{wpath}: weights lack {ch}.{k} (shape {want[k]})")
            if k not in want:
                raise CheckpointError(f"{wpath}: unexpected weight {ch}.{k}")
            if have[k] != want[k]:
                raise CheckpointError(f"{wpath}: weight {ch}.{k} has shape "
                                      f"{have[k]}, the candidate needs {want[k]}")
    try:
        tensors = load_file(str(wpath))
    except Exception as exc:  # safetensors raises its own error types
        raise CheckpointError(f"{wpath}: unreadable safetensors file ({exc})") from exc
    check_finite(tensors, wpath)
    for ch, m in models.items():
        m.load_state_dict({k[len(ch) + 1 :]: v for k, v in tensors.items()
                           if k.startswith(ch + ".")})
        m.eval()
        m.requires_grad_(False)


def read_chain(path: str | Path) -> tuple[Chain, dict, Path]:
    """(Chain, build metadata, folder) from an artefact folder."""
    folder = Path(path)
    if not folder.is_dir():
        raise CheckpointError(f"{folder}: chain folder not found")
    verify_manifest(folder, required=MEMBERS)
    doc = _read_meta(folder)
    src = folder / META
    nss_dir = folder / NSS_DIR
    nss_w = nss_dir / "model.safetensors"
    if not nss_w.is_file():
        raise CheckpointError(f"{nss_w}: NSS weights file not found")
    if sha256_file(nss_w) != (doc.get("nss") or {}).get("sha256"):
        raise CheckpointError(f"{nss_w}: NSS weights do not match the chain (SHA-256 mismatch)")
    loaded = load_model(nss_dir)
    env = Envelope.from_json(doc.get("envelope") or {})
    models = _build_models(doc, src)
    _load_weights(doc, folder, models)
    chain = Chain(loaded.model, models, env, NSSProvenance(loaded.config, loaded.training))
    return chain, dict(doc.get("build") or {}), folder
