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
import math
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import scipy.io
from pydantic import Field, ValidationError

from parknss.config import StrictModel, read_json
from parknss.data.assemble import Assembled, LogRead, assemble
from parknss.data.canlog import CAN_SUFFIXES
from parknss.data.csvlog import read_csv_table
from parknss.data.mapping import (
    GATE_SUFFIX,
    ChannelMapping,
    Column,
    CsvOptions,
    as_mapping,
    iter_gates,
    iter_sources,
    mapping_hint,
    resolve_dbc,
    source_key,
    source_label,
)
from parknss.data.mdf import MDF_SUFFIXES, read_mdf, write_mdf
from parknss.data.meta import META_KEY, parse_meta
from parknss.data.resample import Series
from parknss.data.trial import UNLABELLED, Campaign, Trial
from parknss.data.validate import TrialDataError, load_validation_config, validate_trial
from parknss.data.workflows import campaign_channels
from parknss.errors import DataError, one_line
from parknss.outputs import artefact_folder, safe_stem
from parknss.signals import (
    CHANNEL_BY_NAME,
    REQUIRED_CHANNELS,
    SAMPLE_RATE_HZ,
    SCHEMA_VERSION,
    TRUTH_PREFIX,
    convert_to_schema,
)
from parknss.vehicle import VehicleGeometry

CAMPAIGN_JSON = "campaign.json"
CAMPAIGN_FORMAT = "parknss-campaign"
MANIFEST = "manifest.csv"
CAN_TRACE_SUFFIXES: tuple[str, ...] = tuple(dict.fromkeys((*CAN_SUFFIXES, ".log")))
LOG_SUFFIXES: tuple[str, ...] = (
    ".csv", ".parquet", ".pq", ".mat", *MDF_SUFFIXES, *CAN_TRACE_SUFFIXES
)
LOG_KINDS = (
    ".csv (table or SavvyCAN GVRET), .parquet, .mat, .mf4/.mdf (MDF4, decoded or bus logging) "
    "or .blf/.asc/.trc/.log (CAN)"
)
_NAME_RE = re.compile(r"^(?P<cls>[A-Za-z][A-Za-z0-9_]*?)_r(?P<rep>[0-9]+)$")
_SAFE_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")

Raw = tuple[dict[str, Column], dict]
CSV_DIALECT = "__csv_dialect__"  # meta key: how a CSV was read (moved to the provenance)
TIME_UNITS = (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))
PLAUSIBLE_STEP_S = (1.0e-4, 1.0)  # a log's median time step: 10 kHz ... 1 Hz



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


# ------------------------------------------------------------------- table logs


def parse_numbers(
    col: Column, label: str, source: str, decimal: str = ".", as_nan: frozenset = frozenset()
) -> np.ndarray:
    """Raw values (numbers or text) -> float64; text that is not a number is an error.

    ``nan``/``inf`` text parses (the assembly reports it unless the mapping masks it);
    text listed in ``as_nan`` (the channel's text sentinels, e.g. ``""``) becomes NaN;
    an empty field or other text raises DataError naming the first offending value.
    """
    v = col.values
    if v.dtype.kind in "biuf":
        return v.astype(np.float64, copy=False)
    text = [str(x).strip() for x in v]
    if decimal != ".":
        text = [x.replace(decimal, ".") for x in text]
    out = np.empty(len(text), dtype=np.float64)
    bad = []
    for i, x in enumerate(text):
        if x in as_nan:
            out[i] = np.nan
            continue
        try:
            out[i] = float(x)
        except ValueError:
            bad.append(i)
    if bad:
        i = bad[0]
        what = "empty value" if text[i] == "" else f"non-numeric value {str(v[i]).strip()!r}"
        raise DataError(
            f"{source}: {label}: {what} at {col.locate(i)} ({len(bad)} non-numeric values)"
        )
    return out


def _check_table_time(t: np.ndarray, col: Column, source: str) -> None:
    """The time column: finite, never repeated, never going backwards (one line each)."""
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise DataError(
            f"{source}: channel 't': {len(bad)} non-finite time stamps (first at "
            f"{col.locate(int(bad[0]))})"
        )
    dt = np.diff(t)
    dup = np.flatnonzero(dt == 0.0)
    if len(dup):
        raise DataError(
            f"{source}: channel 't': {len(dup)} duplicate timestamps (first at "
            f"t={t[int(dup[0])]:.2f} s)"
        )
    back = np.flatnonzero(dt < 0.0)
    if len(back):
        k = int(back[0])
        raise DataError(
            f"{source}: channel 't': time goes backwards at {len(back)} steps (first from "
            f"t={t[k]:.2f} s to t={t[k + 1]:.2f} s); sort the log by time"
        )


def find_column(raw: dict[str, Column], name: str) -> str | None:
    """The column called ``name``: exactly, else the one whose name differs only in case."""
    if name in raw:
        return name
    found = [c for c in raw if c.casefold() == name.casefold()]
    return found[0] if len(found) == 1 else None


def _time_unit(t: np.ndarray, m: ChannelMapping, col: Column, source: str) -> tuple[str, str]:
    """(unit of the time column, how it was decided): the mapping's, the file's, or guessed
    from the median step (the unit that makes it a rate of 1 Hz ... 10 kHz)."""
    if "unit" in m.time.model_fields_set:
        return m.time.unit, "mapping"
    if col.unit:
        return col.unit, "file"
    steps = np.diff(t[: 100_001])
    steps = steps[steps > 0]
    if not len(steps):
        return m.time.unit, "default"
    med = float(np.median(steps))
    for unit, factor in TIME_UNITS:
        if PLAUSIBLE_STEP_S[0] <= med * factor <= PLAUSIBLE_STEP_S[1]:
            return unit, f"guessed from the median step {med:g}"
    raise DataError(
        f"{source}: channel 't': median time step {med:g} is not a sampling rate of 1 Hz "
        "to 10 kHz in s, ms, us or ns; state the unit with time.unit in the mapping"
    )


def table_read(raw: dict[str, Column], meta: dict, m: ChannelMapping, path: Path, fmt: str):
    """Columns of a CSV/Parquet/.mat log -> the series of every mapped source.

    Column names match exactly, else ignoring case; a column's own unit (a CSV bracket
    or units row) is used when the mapping gives none. Without ``time.unit`` in the
    mapping or the file, the time unit is guessed from the median step and stated in
    the provenance (and a warning line).
    """
    source = str(path)
    tsrc = m.time
    meta = dict(meta)
    prov: dict = {}
    dialect = meta.pop(CSV_DIALECT, None)
    if dialect is not None:
        prov["csv"] = dialect
    tname = find_column(raw, tsrc.column)
    if tname is None:
        like = [c for c in raw if "time" in c.casefold() or c.casefold() in ("t", "ts")]
        fix = f"; set time.column in the mapping (e.g. time.column: {like[0]!r})" if like else (
            "; set time.column in the mapping")
        raise DataError(
            f"{source}: channel 't': time column {tsrc.column!r} not found "
            f"(columns: {', '.join(raw)}){fix}"
        )
    tlabel = "channel 't'" + (f" (column {tname!r})" if tname != "t" else "")
    t = parse_numbers(raw[tname], tlabel, source, m.csv.decimal)
    unit, how = _time_unit(t, m, raw[tname], source)
    if how.startswith("guessed") and unit != m.time.unit:
        import warnings

        from parknss.errors import ParknssWarning

        warnings.warn(
            f"{source}: time unit {unit!r} {how} (set time.unit in the mapping to state it)",
            ParknssWarning,
            stacklevel=2,
        )
    if how != "mapping":
        prov["time_unit"] = {"unit": unit, "from": how}
    t = convert_to_schema(t, unit, "t")
    _check_table_time(t, raw[tname], source)
    file_units = False
    series: list[Series] = []
    for name, k, ref, spec in iter_sources(m):
        if ref.column is None:
            raise DataError(
                f"{source}: channel {name!r}: the mapping gives a CAN {ref.describe()}; "
                "this log needs a 'column'"
            )
        cname = find_column(raw, ref.column)
        if cname is None:
            if not m.is_mapped(name):
                continue  # reported as missing after the assembly
            raise DataError(
                f"{source}: channel {name!r}: mapped column {ref.column!r} not found "
                f"(columns: {', '.join(raw)})"
            )
        col = raw[cname]
        file_units = file_units or bool(col.unit)
        label = source_label(name, ref)
        text_kept = spec.values is not None
        if text_kept:
            values = col.values
        else:
            as_nan = frozenset(str(x).strip() for x in spec.invalid if isinstance(x, str))
            values = parse_numbers(col, label, source, m.csv.decimal, as_nan)
        hold = spec.interpolation == "hold" or (
            spec.interpolation == "auto" and (CHANNEL_BY_NAME[name].integer or text_kept)
        )
        series.append(
            Series(name, source_key(name, k), label, t, values, hold, col.unit or None,
                   col.locate)
        )
    for name, gate in iter_gates(m):
        cname = None if gate.column is None else find_column(raw, gate.column)
        if cname is None:
            raise DataError(
                f"{source}: channel {name!r}: valid_if {gate.describe()} not found "
                f"(columns: {', '.join(raw)})"
            )
        col = raw[cname]
        series.append(Series(name + GATE_SUFFIX, name + GATE_SUFFIX,
                             f"channel {name!r} (valid_if column {cname!r})", t, col.values,
                             True, None, col.locate))
    for name, col in raw.items():
        if name.startswith(TRUTH_PREFIX):
            values = parse_numbers(col, f"channel {name!r}", source, m.csv.decimal)
            series.append(Series(name, name, f"channel {name!r}", t, values, False, None,
                                 col.locate))
    return LogRead(series, fmt, use_file_units=file_units, table=True, meta=meta,
                   provenance=prov)


# ----------------------------------------------------------------------------- CSV


def _read_csv(path: Path, opts: CsvOptions) -> Raw:
    """A table CSV (:mod:`parknss.data.csvlog`): its columns (with the file's units) and
    metadata; the dialect found goes to the provenance under ``csv``."""
    table = read_csv_table(path, opts)
    raw = {
        n: Column(c.values, c.locate, table.units.get(n, "")) for n, c in table.raw.items()
    }
    return raw, {**table.meta, CSV_DIALECT: table.dialect}


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
            f"{path}: not a readable Parquet file, corrupt or truncated ({one_line(exc)})"
        ) from exc
    meta_b = (table.schema.metadata or {}).get(META_KEY.encode())
    meta = parse_meta(meta_b, path) if meta_b is not None else {}
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
            f"{path}: not a readable MATLAB file, corrupt or truncated ({one_line(exc)})"
        ) from exc
    variables = {k: v for k, v in mat.items() if not k.startswith("__")}
    meta_text = variables.pop(META_KEY, None)
    meta = parse_meta(meta_text, path) if isinstance(meta_text, str) else {}
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


def _read_can(path: Path, m: ChannelMapping) -> LogRead:
    """A CAN trace (.blf/.asc/.log/GVRET .csv/bus-logging MDF4) decoded with the DBC."""
    from parknss.data.canlog import CanRequest, read_can_series

    requests = []
    for name, k, ref, _spec in iter_sources(m):
        if ref.message is None:
            if not m.is_mapped(name):
                raise DataError(
                    f"{path}: channel {name!r}: not mapped (a CAN log needs "
                    f"channels.{name}.message and .signal in the mapping, or "
                    f"'{name}: absent')"
                )
            raise DataError(
                f"{path}: channel {name!r}: the mapping gives {ref.describe()}; a CAN log "
                "needs 'message' and 'signal'"
            )
        requests.append(
            CanRequest(source_key(name, k), name, ref.message, str(ref.signal),
                       source_label(name, ref))
        )
    for name, gate in iter_gates(m):
        if gate.message is None:
            raise DataError(f"{path}: channel {name!r}: valid_if needs 'message' and "
                            "'signal' in a CAN log")
        requests.append(CanRequest(name + GATE_SUFFIX, name + GATE_SUFFIX, gate.message,
                                   str(gate.signal), f"channel {name!r} (valid_if message "
                                   f"{gate.message!r}, signal {gate.signal!r})"))
    if m.can.dbc is None:
        raise DataError(f"{path}: a CAN log needs a DBC: set can.dbc in the mapping")
    m = resolve_dbc(m, path)
    series, prov = read_can_series(path, requests, m.can)
    fmt = prov.pop("format", path.suffix.lower().lstrip("."))
    return LogRead(series, fmt, use_file_units=m.can.use_file_units, provenance=prov,
                   unit_required=m.can.use_file_units)


def _is_can(path: Path) -> bool:
    """A CAN trace: by suffix, a GVRET CSV by its header, an MDF4 by its bus-logging group."""
    suf = path.suffix.lower()
    if suf in CAN_TRACE_SUFFIXES:
        return True
    from parknss.data import canframes

    if suf == ".csv":
        return canframes.is_gvret_csv(path)
    if suf in MDF_SUFFIXES:
        return canframes.is_bus_logging_mdf(path)
    return False


def _read_log(path: Path, m: ChannelMapping) -> LogRead:
    """Any supported log as series, ready for the assembly."""
    _nonempty(path)
    suf = path.suffix.lower()
    if _is_can(path):
        return _read_can(path, m)
    if suf in MDF_SUFFIXES:
        return read_mdf(path, m)
    raw, meta = _READERS[suf](path, m.csv)
    return table_read(raw, meta, m, path, suf.lstrip("."))


# ------------------------------------------------------------------------ dispatch

_READERS: dict[str, Callable[..., Raw]] = {
    ".csv": _read_csv,
    ".parquet": lambda p, _o: _read_parquet(p),
    ".pq": lambda p, _o: _read_parquet(p),
    ".mat": lambda p, _o: _read_mat(p),
}
_BUS_SUFFIXES: tuple[str, ...] = (*MDF_SUFFIXES, *CAN_TRACE_SUFFIXES)
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


def identity_from_name(path: str | Path) -> tuple[str, int] | None:
    """(class, repetition) from a file name like ``park_in_left_r1.csv``, else None."""
    p = Path(path)
    match = _NAME_RE.match(p.stem)
    if match is None or int(match["rep"]) < 1:
        return None
    return match["cls"], int(match["rep"])


def infer_identity(path: str | Path) -> tuple[str, int]:
    """(class, repetition) from a file name like ``park_in_left_r1.csv``, else DataError."""
    found = identity_from_name(path)
    if found is None:
        p = Path(path)
        raise DataError(
            f"{p}: cannot infer class and repetition from the file name (expected "
            f"<class>_r<N>, e.g. park_in_left_r1{p.suffix})"
        )
    return found


def _safe_id(stem: str) -> str:
    """A trial id from a file stem: letters, digits, '_', '.', '-' (others become '_')."""
    out = re.sub(r"[^A-Za-z0-9_.-]", "_", stem)
    return out if out and out[0].isalnum() else f"t{out}"


def _vehicle_id(m: ChannelMapping, meta: dict) -> str:
    """The mapping's vehicle id when it sets one, else the file's, else 'imported'."""
    if "id" in m.vehicle.model_fields_set:
        return m.vehicle.id
    return str(meta.get("vehicle_id", m.vehicle.id))


def _missing(channels: dict, m: ChannelMapping, source: str) -> None:
    """Every channel the mapping does not declare absent must be in the log."""
    missing = [c for c in m.present() if c not in channels]
    if missing:
        more = f" ({len(missing)} channels missing: {', '.join(missing)})" * (len(missing) > 1)
        raise DataError(
            f"{source}: channel {missing[0]!r}: missing{more}; map it to the log's column, "
            f"or declare it '{missing[0]}: absent' in the mapping"
        )


def read_trials(
    path: str | Path,
    mapping: ChannelMapping | str | Path | None = None,
    maneuver: str | None = None,
    repetition: int | None = None,
    window: tuple[float, float] | None = None,
) -> list[Trial]:
    """Read and validate one log file: one trial, or several when its gaps split it.

    Args:
        path: a .csv, .parquet/.pq, .mat, .mf4/.mdf, .blf, .asc or candump .log file
            (layouts in docs/data.md; a GVRET CSV and a bus-logging MDF4 are recognised
            by their content and decoded with the mapping's DBC).
        mapping: a ChannelMapping or mapping-YAML path (required for CAN logs).
        maneuver, repetition: the trial's class and repetition; by default taken from
            the file's parknss_trial metadata, else from a name like park_in_left_r1,
            else class ``unlabelled``, repetition 1 and the file stem as id.
        window: keep [start, end] s from the log's first time stamp (overrides the
            mapping's time.crop).

    Returns:
        Validated Trials (float64 channels in schema units); with ``resample.on_gap:
        split`` one per stretch between gaps, ids ``<id>_s1``, ``<id>_s2``, ...
        Raises DataError/ConfigError.
    """
    p = Path(path)
    m = as_mapping(mapping)
    _suffix(p)
    read = _read_log(p, m)
    cfg = load_validation_config()
    win = window if window is not None else m.time.crop
    parts: list[Assembled] = assemble(read, m, str(p), win)
    meta = read.meta
    if maneuver is None and repetition is None and {"id", "maneuver", "repetition"} <= set(meta):
        tid, cls, rep = meta["id"], meta["maneuver"], meta["repetition"]
    else:
        named = identity_from_name(p)
        cls_i, rep_i = named if named is not None else (UNLABELLED, 1)
        cls = maneuver if maneuver is not None else cls_i
        rep = repetition if repetition is not None else rep_i
        tid = f"{cls}_r{rep}" if named is not None or maneuver is not None else _safe_id(p.stem)
    required = tuple(m.present())
    trials = []
    for k, part in enumerate(parts):
        _missing(part.channels, m, str(p))
        # a file parknss wrote carries its own history; any other log gets the assembly's
        provenance = str(meta.get("provenance") or json.dumps(part.provenance, sort_keys=True))
        trial = Trial(
            id=tid if len(parts) == 1 else f"{tid}_s{k + 1}",
            maneuver=cls,
            repetition=rep,
            channels=part.channels,
            vehicle_id=_vehicle_id(m, meta),
            sample_rate_hz=meta.get("sample_rate_hz", SAMPLE_RATE_HZ),
            provenance=provenance,
        )
        try:
            trials.append(validate_trial(trial, str(p), cfg, required=required))
        except TrialDataError as exc:
            raise DataError(f"{exc}{mapping_hint(m, exc.channel)}") from exc
    return trials


def read_trial(
    path: str | Path,
    mapping: ChannelMapping | str | Path | None = None,
    maneuver: str | None = None,
    repetition: int | None = None,
    window: tuple[float, float] | None = None,
) -> Trial:
    """Read and validate one trial file (see :func:`read_trials`); a log that splits
    into several trials at its gaps is an error here (use read_trials or import)."""
    trials = read_trials(path, mapping, maneuver, repetition, window)
    if len(trials) > 1:
        raise DataError(
            f"{path}: the log splits into {len(trials)} trials at its gaps "
            "(resample.on_gap: split); read it with read_trials or campaign import"
        )
    return trials[0]


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


def write_campaign(campaign: Campaign, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """Validate every trial, then write ``<id>.parquet`` per trial and campaign.json.

    The folder is written atomically (:func:`parknss.outputs.artefact_folder`): a failure
    leaves an earlier ``out_dir`` whole, and an ``out_dir`` that holds anything already is
    refused unless ``overwrite`` (then it is replaced as a whole, never merged into).

    Returns the folder. Raises DataError for invalid trials, duplicate or unsafe ids, or
    metadata that is not JSON; OutputExistsError for an existing ``out_dir`` without
    ``overwrite``.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a folder")
    seen: set[str] = set()
    for tr in campaign:
        if not _SAFE_ID.match(str(tr.id)) or tr.id in seen:
            why = "duplicate" if tr.id in seen else "unsafe as a file name"
            raise DataError(f"{out}: trial id {tr.id!r} is {why}")
        safe_stem(tr.id, what=f"{out}: trial id")  # bounded length
        seen.add(tr.id)
    present = campaign_channels(campaign) if len(campaign) else REQUIRED_CHANNELS
    if "t" not in present:
        raise DataError(f"{out}: the trials have no time channel 't'")
    trials = [
        validate_trial(tr, f"{out / (tr.id + '.parquet')}", required=present) for tr in campaign
    ]
    meta = dict(campaign.meta)
    absent = [c for c in REQUIRED_CHANNELS if c not in present]
    if absent:
        meta["absent_channels"] = absent
    else:
        meta.pop("absent_channels", None)
    try:
        meta_json = json.loads(json.dumps(meta))
    except (TypeError, ValueError) as exc:
        raise DataError(
            f"{out}: campaign meta is not JSON-serializable ({one_line(exc)})"
        ) from exc
    with artefact_folder(out, overwrite=overwrite, kind="campaign") as tmp:
        entries = []
        for tr in trials:
            write_trial_parquet(tr, tmp / f"{tr.id}.parquet")
            entries.append({**_trial_meta(tr), "file": f"{tr.id}.parquet", "n_samples": tr.n})
            del entries[-1]["schema_version"]
        index = {
            "format": CAMPAIGN_FORMAT,
            "schema_version": SCHEMA_VERSION,
            "name": campaign.name,
            "meta": meta_json,
            "trials": entries,
        }
        (tmp / CAMPAIGN_JSON).write_text(json.dumps(index, indent=2))
    return out


def _read_index(folder: Path) -> CampaignIndex:
    jpath = folder / CAMPAIGN_JSON
    if not jpath.is_file():
        raise DataError(
            f"{folder}: no {CAMPAIGN_JSON}, not a parknss campaign folder "
            "(bring raw logs in with `parknss campaign import`)"
        )
    _nonempty(jpath)
    doc = read_json(jpath, DataError)  # depth-limited, unreadable: one line
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
    absent = index.meta.get("absent_channels", [])
    if not isinstance(absent, list) or not set(absent) <= set(REQUIRED_CHANNELS) - {"t"}:
        raise DataError(f"{folder / CAMPAIGN_JSON}: meta.absent_channels {absent!r} is not a "
                        "list of schema channels")
    required = tuple(c for c in REQUIRED_CHANNELS if c not in absent)
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
        channels = {
            name: parse_numbers(col, f"channel {name!r}", str(f)) for name, col in raw.items()
        }
        if "t" not in channels:
            raise DataError(f"{f}: channel 't': missing")
        n = len(channels["t"])
        if n != e.n_samples:
            raise DataError(
                f"{f}: channel 't': {n} samples, {CAMPAIGN_JSON} says {e.n_samples} "
                "(truncated or replaced file?)"
            )
        tr = Trial(
            e.id, e.maneuver, e.repetition, channels, e.vehicle_id, e.sample_rate_hz, e.provenance
        )
        trials.append(validate_trial(tr, str(f), required=required))
    return Campaign(trials, name=index.name, meta=dict(index.meta))


# -------------------------------------------------------------------------- import


@dataclass(frozen=True)
class _Job:
    """One log to import: its file, class and repetition (None: unlabelled), window."""

    path: Path
    cls: str | None
    rep: int | None
    window: tuple[float, float] | None = None


def _float_or_none(text: str, what: str, where: str) -> float | None:
    if not text.strip():
        return None
    try:
        x = float(text)
    except ValueError:
        raise DataError(f"{where}: {what} {text.strip()!r} is not a number (s)") from None
    if not math.isfinite(x) or x < 0:
        raise DataError(f"{where}: {what} {text.strip()!r} must be a time >= 0 s")
    return x


def _manifest_window(r: list[str], idx: dict[str, int], where: str):
    """The row's (start_s, end_s) crop window, s from the log's first time stamp, or None."""
    if "start_s" not in idx and "end_s" not in idx:
        return None
    a = _float_or_none(r[idx["start_s"]], "start_s", where) if "start_s" in idx else None
    b = _float_or_none(r[idx["end_s"]], "end_s", where) if "end_s" in idx else None
    if a is None and b is None:
        return None
    a, b = a or 0.0, b if b is not None else math.inf
    if not a < b:
        raise DataError(f"{where}: start_s {a:g} is not before end_s {b:g}")
    return a, b


def _read_manifest(src: Path, logs: list[Path]) -> list[_Job]:
    """manifest.csv rows: ``file`` and optional ``class``, ``repetition``, ``start_s``,
    ``end_s`` (a crop window); every log listed exactly once."""
    mpath = src / MANIFEST
    _nonempty(mpath)
    try:
        rows = list(csv.reader(mpath.read_text(encoding="utf-8-sig").splitlines()))
    except UnicodeDecodeError as exc:
        raise DataError(f"{mpath}: not UTF-8 text") from exc
    rows = [(n + 1, r) for n, r in enumerate(rows) if any(x.strip() for x in r)]
    header = [h.strip() for h in rows[0][1]] if rows else []
    if "file" not in header:
        raise DataError(
            f"{mpath}: line 1: column 'file' missing (columns: file, and optionally class, "
            "repetition, start_s, end_s)"
        )
    if ("class" in header) != ("repetition" in header):
        have, lack = ("class", "repetition") if "class" in header else ("repetition", "class")
        raise DataError(f"{mpath}: line 1: column {lack!r} missing (given with {have!r})")
    known = ("file", "class", "repetition", "start_s", "end_s")
    idx = {c: header.index(c) for c in known if c in header}
    out: list[_Job] = []
    listed: set[str] = set()
    for n, r in rows[1:]:
        where = f"{mpath}: line {n}"
        if len(r) != len(header):
            raise DataError(f"{where}: {len(r)} fields, the header has {len(header)}")
        name = r[idx["file"]].strip()
        cls = r[idx["class"]].strip() if "class" in idx else ""
        rep_s = r[idx["repetition"]].strip() if "repetition" in idx else ""
        f = src / name
        if name in listed:
            raise DataError(f"{where}: file {name!r} listed twice")
        if not f.is_file() or f.suffix.lower() not in LOG_SUFFIXES:
            raise DataError(f"{where}: file {name!r} not found as a log ({LOG_KINDS}) in {src}")
        if cls and not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", cls):
            raise DataError(f"{where}: class {cls!r} is not a name (letters, digits, _)")
        if bool(cls) != bool(rep_s):
            raise DataError(f"{where}: give both class and repetition, or leave both empty")
        if rep_s and (not rep_s.isdigit() or int(rep_s) < 1):
            raise DataError(f"{where}: repetition {rep_s!r} is not an integer >= 1")
        listed.add(name)
        window = _manifest_window(r, idx, where)
        out.append(_Job(f, cls or None, int(rep_s) if rep_s else None, window))
    if not out:
        raise DataError(f"{mpath}: no trials listed")
    for f in logs:
        if f.name not in listed:
            raise DataError(f"{f}: not listed in {mpath.name} (list it, or move it out of {src})")
    return out


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _list_logs(folder: Path) -> tuple[list[Path], list[dict[str, str]]]:
    """The logs of a folder (sorted), and every other entry with why it is skipped
    (hidden files are skipped without a word, and so is the manifest)."""
    logs, skipped = [], []
    for f in sorted(folder.iterdir()):
        if f.name.startswith(".") or f.name == MANIFEST:
            continue
        why = None
        if f.is_symlink() and not f.exists():
            why = "dangling symbolic link"
        elif f.is_dir():
            why = "a folder (sub-folders are not read)"
        elif not f.is_file():
            why = "not a regular file"
        elif f.suffix.lower() not in LOG_SUFFIXES:
            why = f"{f.suffix or 'no suffix'}: not a log type parknss reads"
        if why is None:
            logs.append(f)
        else:
            skipped.append({"file": f.name, "why": why})
    return logs, skipped


def skipped_summary(campaign: Campaign) -> str | None:
    """'skipped N files: a (why), b (why)' from an imported campaign's meta, or None."""
    skipped = campaign.meta.get("skipped_files") or []
    if not skipped:
        return None
    items = ", ".join(f"{s['file']} ({s['why']})" for s in skipped)
    return f"skipped {len(skipped)} file{'s' * (len(skipped) > 1)}: {items}"


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
    logs, skipped = _list_logs(folder)
    if (folder / MANIFEST).exists():
        jobs = _read_manifest(folder, logs)
    else:
        jobs = [_Job(f, *(identity_from_name(f) or (None, None))) for f in logs]
    if not jobs:
        raise DataError(f"{folder}: no logs found ({LOG_KINDS})")
    trials: list[Trial] = []
    origin: dict[str, Path] = {}
    unlabelled = 0
    for job in jobs:
        f = job.path
        if job.cls is None:
            unlabelled += 1
        cls = job.cls if job.cls is not None else UNLABELLED
        rep = job.rep if job.rep is not None else unlabelled
        parts = read_trials(f, m, cls, rep, job.window)
        for tr in parts:
            if job.cls is None:  # ids of unlabelled trials: the file stem (and stretch)
                suffix = tr.id[len(f"{cls}_r{rep}"):]
                tr.id = _safe_id(f.stem) + suffix
            if tr.id in origin:
                raise DataError(
                    f"{f}: trial {tr.id!r} again (already from {origin[tr.id].name})"
                )
            origin[tr.id] = f
            tr.provenance = json.dumps(
                {
                    "imported_from": str(f),
                    "sha256": _sha256(f),
                    "mapping": None
                    if mapping is None or isinstance(mapping, ChannelMapping)
                    else str(mapping),
                    "window_s": list(job.window) if job.window is not None else None,
                    "file_provenance": tr.provenance,
                },
                sort_keys=True,
            )
            trials.append(tr)
    meta: dict = {"synthetic": False, "imported_from": str(folder), "vehicle_id": m.vehicle.id}
    if m.absent():
        meta["absent_channels"] = m.absent()
    if unlabelled:
        meta["unlabelled_trials"] = unlabelled
    if skipped:
        meta["skipped_files"] = skipped
    if m.vehicle.geometry is not None:
        meta["vehicle_geometry"] = VehicleGeometry.from_dict(m.vehicle.geometry).to_dict()
    return Campaign(trials, name=folder.name, meta=meta)


__all__ = [
    "CAMPAIGN_JSON",
    "import_folder",
    "infer_identity",
    "read_campaign",
    "read_trial",
    "read_trials",
    "skipped_summary",
    "write_campaign",
    "write_trial",
    "write_trial_csv",
    "write_trial_mat",
    "write_trial_mdf",
    "write_trial_parquet",
]
