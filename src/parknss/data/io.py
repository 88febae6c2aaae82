"""Reading and writing trials and campaigns: Parquet (native), CSV, MATLAB .mat, bus logs.

Native campaign = a folder with one Parquet file per trial plus ``campaign.json``
(name, meta, schema version, one entry per trial). Single trials can also be CSV, .mat
or MDF4 in the layouts of docs/data.md, and CAN logs (.blf/.asc with a DBC) are read;
bus logs are resampled onto the 100 Hz grid first (:mod:`parknss.data.resample`). Every
load goes through an optional channel mapping (:mod:`parknss.data.mapping`) and then
:func:`~parknss.data.validate.validate_trial`; every problem is a one-line
:class:`~parknss.errors.DataError` naming the file.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import scipy.io
from pydantic import Field, ValidationError

from parknss.config import StrictModel
from parknss.data.canlog import CAN_SUFFIXES, read_can
from parknss.data.mapping import (
    ChannelMapping,
    Column,
    CsvOptions,
    apply_mapping,
    as_mapping,
    mapping_hint,
)
from parknss.data.mdf import MDF_SUFFIXES, read_mdf, write_mdf
from parknss.data.resample import BusLog
from parknss.data.trial import Campaign, Trial
from parknss.data.validate import TrialDataError, validate_trial
from parknss.errors import DataError
from parknss.signals import REQUIRED_CHANNELS, SAMPLE_RATE_HZ, SCHEMA_VERSION
from parknss.vehicle import VehicleGeometry

CAMPAIGN_JSON = "campaign.json"
CAMPAIGN_FORMAT = "parknss-campaign"
META_KEY = "parknss_trial"  # trial metadata: Parquet schema key, CSV comment, .mat variable
MANIFEST = "manifest.csv"
LOG_SUFFIXES: tuple[str, ...] = (".csv", ".parquet", ".pq", ".mat", *MDF_SUFFIXES, *CAN_SUFFIXES)
LOG_KINDS = ".csv, .parquet, .mat, .mf4/.mdf (MDF4) or .blf/.asc (CAN)"
_NAME_RE = re.compile(r"^(?P<cls>[A-Za-z][A-Za-z0-9_]*?)_r(?P<rep>[0-9]+)$")
_SAFE_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")

Raw = tuple[dict[str, Column], dict]


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{exc.__class__.__name__}: {text}"[:300]


def _rows(i: int) -> str:
    return f"row {i + 1}"


def _nonempty(path: Path) -> None:
    if not path.exists():
        raise DataError(f"{path}: file not found")
    if not path.is_file():
        raise DataError(f"{path}: not a file")
    if path.stat().st_size == 0:
        raise DataError(f"{path}: empty file (0 bytes)")


def _atomic_write(path: Path, write: Callable[[Path], None]) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    write(tmp)
    os.replace(tmp, path)


def _ordered(channels: dict[str, np.ndarray]) -> list[str]:
    """Schema channels in schema order, then truth_* and any others in their own order."""
    rest = [c for c in channels if c not in REQUIRED_CHANNELS]
    return [c for c in REQUIRED_CHANNELS if c in channels] + rest


def _trial_meta(trial: Trial) -> dict:
    return {
        "schema_version": SCHEMA_VERSION,
        "id": trial.id,
        "maneuver": trial.maneuver,
        "repetition": int(trial.repetition),
        "vehicle_id": trial.vehicle_id,
        "sample_rate_hz": float(trial.sample_rate_hz),
        "provenance": trial.provenance,
    }


def _parse_meta(text: str | bytes, source: Path) -> dict:
    try:
        meta = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{source}: trial metadata {META_KEY!r} is not valid JSON") from exc
    if not isinstance(meta, dict):
        raise DataError(f"{source}: trial metadata {META_KEY!r} is not a JSON object")
    version = str(meta.get("schema_version", SCHEMA_VERSION))
    if version != SCHEMA_VERSION:
        raise DataError(
            f"{source}: written with schema version {version!r}, this parknss reads "
            f"{SCHEMA_VERSION!r}"
        )
    return meta


# ----------------------------------------------------------------------------- CSV


def _read_csv(path: Path, opts: CsvOptions) -> Raw:
    """Leading ``#`` comment lines (one may be ``# parknss_trial {json}``), header, rows."""
    _nonempty(path)
    try:
        lines = path.read_bytes().decode("utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not UTF-8 text (binary or corrupt file?)") from exc
    meta: dict = {}
    k = 0
    while k < len(lines) and lines[k].startswith("#"):
        body = lines[k][1:].strip()
        if body.startswith(META_KEY):
            meta = _parse_meta(body[len(META_KEY) :], path)
        k += 1
    numbered = [(n + 1, ln) for n, ln in enumerate(lines) if n >= k and ln.strip()]
    if not numbered:
        raise DataError(f"{path}: no header line (file holds only comments or blank lines)")
    rows = list(csv.reader([ln for _, ln in numbered], delimiter=opts.delimiter))
    header = [h.strip() for h in rows[0]]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup or "" in header:
        what = f"duplicate column {dup[0]!r}" if dup else "an empty column name"
        raise DataError(f"{path}: line {numbered[0][0]}: header has {what}")
    if len(rows) < 2:
        raise DataError(f"{path}: no data rows below the header")
    for (n, _), row in zip(numbered[1:], rows[1:], strict=True):
        if len(row) != len(header):
            last = n == numbered[-1][0]
            raise DataError(
                f"{path}: line {n}{' (the last)' if last else ''}: {len(row)} fields, the "
                f"header has {len(header)} ({'truncated file?' if last else 'malformed row'})"
            )
    linenos = [n for n, _ in numbered[1:]]
    cols = list(zip(*rows[1:], strict=True))

    def locate(i: int) -> str:
        return f"line {linenos[i]}"

    raw = {h: Column(np.array(c, dtype=object), locate) for h, c in zip(header, cols, strict=True)}
    return raw, meta


def write_trial_csv(trial: Trial, path: str | Path) -> Path:
    """One trial as CSV: a ``# parknss_trial {json}`` line, header, rows in full precision."""
    p = Path(path)
    names = _ordered(trial.channels)
    cols = [np.asarray(trial.channels[c], dtype=np.float64).tolist() for c in names]
    lines = [f"# {META_KEY} {json.dumps(_trial_meta(trial), sort_keys=True)}", ",".join(names)]
    lines += [",".join(map(repr, row)) for row in zip(*cols, strict=True)]
    _atomic_write(p, lambda tmp: tmp.write_text("\n".join(lines) + "\n"))
    return p


# ------------------------------------------------------------------------- Parquet


def _read_parquet(path: Path) -> Raw:
    _nonempty(path)
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DataError(
            f"{path}: not a readable Parquet file, corrupt or truncated ({_one_line(exc)})"
        ) from exc
    meta_b = (table.schema.metadata or {}).get(META_KEY.encode())
    meta = _parse_meta(meta_b, path) if meta_b is not None else {}
    raw: dict[str, Column] = {}
    for name in table.column_names:
        try:
            values = table.column(name).to_numpy()
        except (pa.ArrowException, ValueError, TypeError) as exc:
            raise DataError(
                f"{path}: column {name!r}: unsupported type {table.schema.field(name).type}"
            ) from exc
        raw[name] = Column(np.asarray(values), _rows)
    return raw, meta


def write_trial_parquet(trial: Trial, path: str | Path) -> Path:
    """One trial as Parquet: float64 columns, metadata JSON under schema key parknss_trial."""
    p = Path(path)
    names = _ordered(trial.channels)
    table = pa.table({c: np.asarray(trial.channels[c], dtype=np.float64) for c in names})
    table = table.replace_schema_metadata({META_KEY: json.dumps(_trial_meta(trial))})
    _atomic_write(p, lambda tmp: pq.write_table(table, tmp))
    return p


# ----------------------------------------------------------------------------- MAT


def _mat_column(name: str, v, path: Path) -> Column:
    arr = np.atleast_1d(np.asarray(v, dtype=object if isinstance(v, list) else None))
    if arr.ndim != 1:
        raise DataError(f"{path}: variable {name!r}: expected a vector, got shape {arr.shape}")
    return Column(arr, _rows)


def _read_mat(path: Path) -> Raw:
    """Top-level vectors (one per channel) plus a parknss_trial JSON string; or one struct."""
    _nonempty(path)
    try:
        mat = scipy.io.loadmat(path, simplify_cells=True)
    except NotImplementedError as exc:
        raise DataError(
            f"{path}: MATLAB v7.3 (HDF5) files are not supported; save with -v7"
        ) from exc
    except Exception as exc:  # scipy raises many types for corrupt files
        raise DataError(
            f"{path}: not a readable MATLAB file, corrupt or truncated ({_one_line(exc)})"
        ) from exc
    variables = {k: v for k, v in mat.items() if not k.startswith("__")}
    meta_text = variables.pop(META_KEY, None)
    meta = _parse_meta(meta_text, path) if isinstance(meta_text, str) else {}
    structs = [k for k, v in variables.items() if isinstance(v, dict)]
    if len(structs) == 1 and len(variables) == 1:
        variables = dict(variables[structs[0]])
    elif structs:
        raise DataError(
            f"{path}: variable {structs[0]!r}: a struct beside other variables; use one "
            "variable per channel, or a single struct whose fields are the channels"
        )
    raw = {k: _mat_column(k, v, path) for k, v in variables.items() if not isinstance(v, str)}
    return raw, meta


def write_trial_mat(trial: Trial, path: str | Path) -> Path:
    """One trial as .mat (v5): one T x 1 double per channel, metadata JSON in parknss_trial."""
    p = Path(path)
    data: dict[str, object] = {
        c: np.asarray(trial.channels[c], dtype=np.float64).reshape(-1, 1)
        for c in _ordered(trial.channels)
    }
    data[META_KEY] = json.dumps(_trial_meta(trial), sort_keys=True)

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            scipy.io.savemat(f, data, do_compression=True, oned_as="column")

    _atomic_write(p, write)
    return p


# ------------------------------------------------------------------------ MDF4


def write_trial_mdf(trial: Trial, path: str | Path) -> Path:
    """One trial as MDF4: master t (s), schema units, gear int8, metadata in the header."""
    p = Path(path)
    comment = f"{META_KEY} {json.dumps(_trial_meta(trial), sort_keys=True)}"
    return write_mdf(trial.channels, _ordered(trial.channels), comment, p)


def _read_bus(path: Path, m: ChannelMapping) -> tuple[Raw, ChannelMapping]:
    """A bus log resampled onto the grid, its metadata, and the mapping to apply."""
    _nonempty(path)
    log: BusLog = read_mdf(path, m) if path.suffix.lower() in MDF_SUFFIXES else read_can(path, m)
    meta: dict = {"provenance": json.dumps(log.provenance, sort_keys=True)}
    text = log.header_text or ""
    if text.startswith(META_KEY):
        meta = _parse_meta(text[len(META_KEY) :], path)
    return (log.raw, meta), log.applied


# ------------------------------------------------------------------------ dispatch

_READERS: dict[str, Callable[..., Raw]] = {
    ".csv": _read_csv,
    ".parquet": lambda p, _o: _read_parquet(p),
    ".pq": lambda p, _o: _read_parquet(p),
    ".mat": lambda p, _o: _read_mat(p),
}
_BUS_SUFFIXES: tuple[str, ...] = (*MDF_SUFFIXES, *CAN_SUFFIXES)
_WRITERS: dict[str, Callable[[Trial, Path], Path]] = {
    ".csv": write_trial_csv,
    ".parquet": write_trial_parquet,
    ".pq": write_trial_parquet,
    ".mat": write_trial_mat,
    ".mf4": write_trial_mdf,
    ".mdf": write_trial_mdf,
}


def _suffix(path: Path) -> str:
    suf = path.suffix.lower()
    if suf not in _READERS and suf not in _BUS_SUFFIXES:
        raise DataError(f"{path}: unsupported file type {suf or '(none)'!r} (expected {LOG_KINDS})")
    return suf


def write_trial(trial: Trial, path: str | Path) -> Path:
    """Write one trial; the format follows the extension (.csv, .parquet/.pq, .mat, .mf4)."""
    p = Path(path)
    suf = _suffix(p)
    if suf not in _WRITERS:
        raise DataError(f"{p}: parknss reads {suf} logs but does not write them")
    return _WRITERS[suf](trial, p)


def infer_identity(path: str | Path) -> tuple[str, int]:
    """(class, repetition) from a file name like ``park_in_left_r1.csv``, else DataError."""
    p = Path(path)
    match = _NAME_RE.match(p.stem)
    if match is None or int(match["rep"]) < 1:
        raise DataError(
            f"{p}: cannot infer class and repetition from the file name (expected "
            f"<class>_r<N>, e.g. park_in_left_r1{p.suffix}), and no manifest.csv gives them"
        )
    return match["cls"], int(match["rep"])


def _vehicle_id(m: ChannelMapping, meta: dict) -> str:
    """The mapping's vehicle id when it sets one, else the file's, else 'imported'."""
    if "id" in m.vehicle.model_fields_set:
        return m.vehicle.id
    return str(meta.get("vehicle_id", m.vehicle.id))


def read_trial(
    path: str | Path,
    mapping: ChannelMapping | str | Path | None = None,
    maneuver: str | None = None,
    repetition: int | None = None,
) -> Trial:
    """Read and validate one trial file; the format follows the extension.

    Args:
        path: a .csv, .parquet/.pq, .mat, .mf4/.mdf, .blf or .asc file (layouts in
            docs/data.md; bus logs are resampled onto the 100 Hz grid first).
        mapping: a ChannelMapping or mapping-YAML path for non-schema names/units
            (required for CAN logs: the DBC and each channel's message and signal).
        maneuver, repetition: the trial's class and repetition; by default taken from
            the file's parknss_trial metadata, else from a name like park_in_left_r1.

    Returns:
        A validated Trial (float64 channels in schema units). Raises DataError/ConfigError.
    """
    p = Path(path)
    m = as_mapping(mapping)
    suf = _suffix(p)
    if suf in _BUS_SUFFIXES:
        (raw, meta), applied = _read_bus(p, m)
    else:
        (raw, meta), applied = _READERS[suf](p, m.csv), m
    channels = apply_mapping(raw, applied, str(p))
    if maneuver is None and repetition is None and {"id", "maneuver", "repetition"} <= set(meta):
        tid, cls, rep = meta["id"], meta["maneuver"], meta["repetition"]
    else:
        if maneuver is None or repetition is None:
            cls_i, rep_i = infer_identity(p)
        cls = maneuver if maneuver is not None else cls_i
        rep = repetition if repetition is not None else rep_i
        tid = f"{cls}_r{rep}"
    trial = Trial(
        id=tid,
        maneuver=cls,
        repetition=rep,
        channels=channels,
        vehicle_id=_vehicle_id(m, meta),
        sample_rate_hz=meta.get("sample_rate_hz", SAMPLE_RATE_HZ),
        provenance=str(meta.get("provenance") or json.dumps({"source_file": str(p)})),
    )
    try:
        return validate_trial(trial, str(p))
    except TrialDataError as exc:
        raise DataError(f"{exc}{mapping_hint(applied, exc.channel)}") from exc


# ------------------------------------------------------------------------ campaign


class TrialEntry(StrictModel):
    """One trial of campaign.json."""

    id: str = Field(min_length=1)
    maneuver: str = Field(min_length=1)
    repetition: int = Field(ge=1)
    vehicle_id: str
    sample_rate_hz: float
    provenance: str
    file: str = Field(min_length=1)
    n_samples: int = Field(ge=0)


class CampaignIndex(StrictModel):
    """The whole campaign.json."""

    format: str
    schema_version: str
    name: str
    meta: dict
    trials: list[TrialEntry]


def write_campaign(campaign: Campaign, out_dir: str | Path) -> Path:
    """Validate every trial, then write ``<id>.parquet`` per trial and campaign.json.

    Returns the folder. Raises DataError for invalid trials, duplicate or unsafe ids, or
    metadata that is not JSON.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a folder")
    seen: set[str] = set()
    for tr in campaign:
        if not _SAFE_ID.match(str(tr.id)) or tr.id in seen:
            why = "duplicate" if tr.id in seen else "unsafe as a file name"
            raise DataError(f"{out}: trial id {tr.id!r} is {why}")
        seen.add(tr.id)
    trials = [validate_trial(tr, f"{out / (tr.id + '.parquet')}") for tr in campaign]
    try:
        meta_json = json.loads(json.dumps(campaign.meta))
    except (TypeError, ValueError) as exc:
        raise DataError(
            f"{out}: campaign meta is not JSON-serializable ({_one_line(exc)})"
        ) from exc
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for tr in trials:
        write_trial_parquet(tr, out / f"{tr.id}.parquet")
        entries.append({**_trial_meta(tr), "file": f"{tr.id}.parquet", "n_samples": tr.n})
        del entries[-1]["schema_version"]
    index = {
        "format": CAMPAIGN_FORMAT,
        "schema_version": SCHEMA_VERSION,
        "name": campaign.name,
        "meta": meta_json,
        "trials": entries,
    }
    _atomic_write(out / CAMPAIGN_JSON, lambda tmp: tmp.write_text(json.dumps(index, indent=2)))
    return out


def _read_index(folder: Path) -> CampaignIndex:
    jpath = folder / CAMPAIGN_JSON
    if not jpath.is_file():
        raise DataError(
            f"{folder}: no {CAMPAIGN_JSON}, not a parknss campaign folder "
            "(bring raw logs in with `parknss campaign import`)"
        )
    _nonempty(jpath)
    try:
        doc = json.loads(jpath.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{jpath}: not valid JSON ({_one_line(exc)})") from exc
    try:
        index = CampaignIndex.model_validate(doc)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        raise DataError(f"{jpath}: field {loc!r}: {err['msg']}") from exc
    if index.format != CAMPAIGN_FORMAT:
        raise DataError(f"{jpath}: format {index.format!r}, expected {CAMPAIGN_FORMAT!r}")
    if index.schema_version != SCHEMA_VERSION:
        raise DataError(
            f"{jpath}: schema version {index.schema_version!r}, this parknss reads "
            f"{SCHEMA_VERSION!r}"
        )
    return index


def read_campaign(path: str | Path) -> Campaign:
    """Read a native campaign folder (or its campaign.json) and validate every trial."""
    p = Path(path)
    folder = p.parent if p.is_file() and p.name == CAMPAIGN_JSON else p
    if not folder.exists():
        raise DataError(f"{folder}: campaign folder not found")
    if not folder.is_dir():
        raise DataError(f"{folder}: not a campaign folder (give the folder with {CAMPAIGN_JSON})")
    index = _read_index(folder)
    trials: list[Trial] = []
    seen: set[str] = set()
    for e in index.trials:
        f = folder / e.file
        if Path(e.file).is_absolute() or ".." in Path(e.file).parts:
            raise DataError(
                f"{folder / CAMPAIGN_JSON}: trial {e.id!r}: file {e.file!r} outside the folder"
            )
        if e.id in seen:
            raise DataError(f"{folder / CAMPAIGN_JSON}: duplicate trial id {e.id!r}")
        seen.add(e.id)
        raw, _ = _read_parquet(f)
        channels = apply_mapping(raw, ChannelMapping(), str(f))
        n = len(channels["t"])
        if n != e.n_samples:
            raise DataError(
                f"{f}: channel 't': {n} samples, {CAMPAIGN_JSON} says {e.n_samples} "
                "(truncated or replaced file?)"
            )
        tr = Trial(
            e.id, e.maneuver, e.repetition, channels, e.vehicle_id, e.sample_rate_hz, e.provenance
        )
        trials.append(validate_trial(tr, str(f)))
    return Campaign(trials, name=index.name, meta=dict(index.meta))


# -------------------------------------------------------------------------- import


def _read_manifest(src: Path, logs: list[Path]) -> list[tuple[Path, str, int]]:
    """manifest.csv rows (file, class, repetition); every log listed exactly once."""
    mpath = src / MANIFEST
    _nonempty(mpath)
    try:
        rows = list(csv.reader(mpath.read_text(encoding="utf-8-sig").splitlines()))
    except UnicodeDecodeError as exc:
        raise DataError(f"{mpath}: not UTF-8 text") from exc
    rows = [(n + 1, r) for n, r in enumerate(rows) if any(x.strip() for x in r)]
    header = [h.strip() for h in rows[0][1]] if rows else []
    need = ("file", "class", "repetition")
    missing = [c for c in need if c not in header]
    if missing:
        raise DataError(
            f"{mpath}: line 1: column {missing[0]!r} missing (need file, class, repetition)"
        )
    idx = {c: header.index(c) for c in need}
    out: list[tuple[Path, str, int]] = []
    listed: set[str] = set()
    for n, r in rows[1:]:
        if len(r) != len(header):
            raise DataError(f"{mpath}: line {n}: {len(r)} fields, the header has {len(header)}")
        name, cls, rep_s = (r[idx[c]].strip() for c in need)
        f = src / name
        if name in listed:
            raise DataError(f"{mpath}: line {n}: file {name!r} listed twice")
        if not f.is_file() or f.suffix.lower() not in LOG_SUFFIXES:
            raise DataError(
                f"{mpath}: line {n}: file {name!r} not found as a log ({LOG_KINDS}) in {src}"
            )
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", cls):
            raise DataError(f"{mpath}: line {n}: class {cls!r} is not a name (letters, digits, _)")
        if not rep_s.isdigit() or int(rep_s) < 1:
            raise DataError(f"{mpath}: line {n}: repetition {rep_s!r} is not an integer >= 1")
        listed.add(name)
        out.append((f, cls, int(rep_s)))
    if not out:
        raise DataError(f"{mpath}: no trials listed")
    for f in logs:
        if f.name not in listed:
            raise DataError(f"{f}: not listed in {mpath.name} (list it, or move it out of {src})")
    return out


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def import_folder(src: str | Path, mapping: ChannelMapping | str | Path | None = None) -> Campaign:
    """A validated Campaign from a folder of logs, one file per trial.

    Class and repetition come from ``manifest.csv`` (columns file, class, repetition)
    when present, else from file names like ``park_in_left_r1.csv``. ``mapping``: a
    ChannelMapping or mapping-YAML path applied to every file.
    """
    folder = Path(src)
    if not folder.is_dir():
        raise DataError(
            f"{folder}: log folder not found" if not folder.exists() else f"{folder}: not a folder"
        )
    m = as_mapping(mapping)
    logs = sorted(
        f
        for f in folder.iterdir()
        if f.is_file()
        and f.suffix.lower() in LOG_SUFFIXES
        and f.name != MANIFEST
        and not f.name.startswith(".")
    )
    if (folder / MANIFEST).exists():
        jobs = _read_manifest(folder, logs)
    else:
        jobs = [(f, *infer_identity(f)) for f in logs]
    if not jobs:
        raise DataError(f"{folder}: no logs found ({LOG_KINDS})")
    trials: list[Trial] = []
    origin: dict[str, Path] = {}
    for f, cls, rep in jobs:
        tr = read_trial(f, m, cls, rep)
        if tr.id in origin:
            raise DataError(f"{f}: trial {tr.id!r} again (already from {origin[tr.id].name})")
        origin[tr.id] = f
        tr.provenance = json.dumps(
            {
                "imported_from": str(f),
                "sha256": _sha256(f),
                "mapping": None
                if mapping is None or isinstance(mapping, ChannelMapping)
                else str(mapping),
                "file_provenance": tr.provenance,
            },
            sort_keys=True,
        )
        trials.append(tr)
    meta: dict = {"synthetic": False, "imported_from": str(folder), "vehicle_id": m.vehicle.id}
    if m.vehicle.geometry is not None:
        meta["vehicle_geometry"] = VehicleGeometry.from_dict(m.vehicle.geometry).to_dict()
    return Campaign(trials, name=folder.name, meta=meta)


__all__ = [
    "CAMPAIGN_JSON",
    "import_folder",
    "infer_identity",
    "read_campaign",
    "read_trial",
    "write_campaign",
    "write_trial",
    "write_trial_csv",
    "write_trial_mat",
    "write_trial_mdf",
    "write_trial_parquet",
]
