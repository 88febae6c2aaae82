"""Channel mapping: how a user's log names, units and gear codes map onto the schema.

A mapping YAML (configs/mapping_example.yaml documents every key) says, per schema
channel, which source column holds it and in which unit; values are converted only
through :func:`parknss.signals.convert_to_schema`. For bus logs the same file names the
MDF channel (``column``, found by ``mdf.match``) or the CAN ``message``/``signal`` (with
the DBC in ``can.dbc``), and ``resample`` sets the tolerance of the 100 Hz resampling
(configs/mapping_mdf_example.yaml, configs/mapping_can_example.yaml). Columns named like
the schema and not mentioned are taken as they are (schema units). Gear codes
(``R``/``N``/``P``/``D`` or numbers) map to -1/0/+1 through ``gear_values``. Nothing is
guessed: an unknown unit, a unit of the wrong kind, a missing column or an unmapped gear
code is a one-line error.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import yaml
from pydantic import Field, ValidationError, field_validator, model_validator

from parknss.config import StrictModel
from parknss.errors import ConfigError, DataError
from parknss.signals import (
    CHANNEL_BY_NAME,
    DT,
    TRUTH_PREFIX,
    UNIT_CONVERSIONS,
    convert_to_schema,
)
from parknss.vehicle import VehicleGeometry

Interpolation = Literal["auto", "linear", "hold"]


class ChannelSource(StrictModel):
    """Where one schema channel comes from: a source column, its unit, its sign.

    ``column`` names the column (CSV, Parquet, .mat) or the MDF channel (an exact name or
    a pattern, see :class:`MdfOptions`); a CAN log names ``message`` and ``signal`` of
    the DBC instead. ``group`` picks the MDF data group when a name occurs in several.
    ``interpolation`` says how a bus-log channel goes onto the 100 Hz grid: ``linear``,
    ``hold`` (previous value), or ``auto`` (hold for gear, integer, enumerated/text and
    all CAN signals; linear for other MDF channels).
    """

    column: str | None = Field(None, min_length=1)
    unit: str | None = None  # None: already in the schema unit (or the MDF/DBC unit)
    invert: bool = False  # multiply by -1 after conversion (opposite sign convention)
    message: str | None = Field(None, min_length=1)  # CAN: message name in the DBC
    signal: str | None = Field(None, min_length=1)  # CAN: signal name in that message
    group: int | None = Field(None, ge=0)  # MDF: data group index of the channel
    interpolation: Interpolation = "auto"

    @model_validator(mode="after")
    def _one_source(self) -> ChannelSource:
        can = self.message is not None or self.signal is not None
        if can and (self.message is None or self.signal is None):
            raise ValueError("a CAN source needs both 'message' and 'signal'")
        if can == (self.column is not None):
            raise ValueError(
                "give 'column' (CSV, Parquet, .mat or MDF channel) or 'message' and "
                "'signal' (CAN), not both"
                if can
                else "give 'column' (CSV, Parquet, .mat or MDF channel) or 'message' and "
                "'signal' (CAN)"
            )
        return self

    def describe(self) -> str:
        """The source in words, for messages: ``column 'X'`` or ``message 'M', signal 'S'``."""
        if self.column is not None:
            return f"column {self.column!r}"
        return f"message {self.message!r}, signal {self.signal!r}"


class TimeSource(StrictModel):
    """The time column: name, unit (s or ms), and whether to start the trial at t = 0."""

    column: str = Field("t", min_length=1)
    unit: str = "s"
    start_at_zero: bool = False


class CsvOptions(StrictModel):
    """How CSV logs are written: field delimiter and decimal mark."""

    delimiter: str = Field(",", min_length=1, max_length=1)
    decimal: str = Field(".", min_length=1, max_length=1)


class VehicleInfo(StrictModel):
    """Vehicle the logs come from: its id and (optionally) geometry for describe."""

    id: str = Field("imported", min_length=1)
    geometry: dict[str, float] | None = None

    @field_validator("geometry")
    @classmethod
    def _known_fields(cls, v: dict[str, float] | None) -> dict[str, float] | None:
        if v is not None:
            unknown = sorted(set(v) - set(VehicleGeometry.__dataclass_fields__))
            if unknown:
                raise ValueError(f"unknown geometry field(s) {unknown}")
        return v


class MdfOptions(StrictModel):
    """How MDF4 channels are found (configs/mapping_mdf_example.yaml).

    Attributes:
        match: how ``column`` is compared with the file's channel names: ``exact``, or
            asammdf's channel search (``plain`` substring, ``wildcard`` like ``*VehSpd``,
            ``regex``); the match must be one channel (use ``group`` if it is not).
        case_insensitive: compare names ignoring case (search modes only).
        use_file_units: without a ``unit`` in the mapping, take the channel's MDF unit
            (it must be a unit parknss knows); False: schema units are assumed.
    """

    match: Literal["exact", "plain", "wildcard", "regex"] = "exact"
    case_insensitive: bool = False
    use_file_units: bool = True


class CanOptions(StrictModel):
    """How CAN logs (.blf, .asc) are decoded (configs/mapping_can_example.yaml).

    Attributes:
        dbc: the DBC file; a relative path is relative to the mapping YAML's folder
            (to the working directory for a ChannelMapping built in code).
        bus_channel: only frames of this bus channel (python-can's 0-based number);
            None takes every channel.
        use_file_units: without a ``unit`` in the mapping, take the DBC signal's unit.
    """

    dbc: str | None = Field(None, min_length=1)
    bus_channel: int | None = Field(None, ge=0)
    use_file_units: bool = True


class ResampleOptions(StrictModel):
    """Resampling of bus logs onto the 100 Hz grid.

    Attributes:
        time_tolerance_s: a time stamp within this of a grid time counts as on it, s
            (loggers store times with finite resolution; BLF in ns).
    """

    time_tolerance_s: float = Field(1.0e-6, gt=0.0, lt=DT / 2)


class ChannelMapping(StrictModel):
    """A whole mapping file (see configs/mapping_example.yaml)."""

    time: TimeSource = TimeSource()
    channels: dict[str, ChannelSource] = Field(default_factory=dict)
    gear_values: dict[str, int] | None = None
    csv: CsvOptions = CsvOptions()
    vehicle: VehicleInfo = VehicleInfo()
    mdf: MdfOptions = MdfOptions()
    can: CanOptions = CanOptions()
    resample: ResampleOptions = ResampleOptions()

    @field_validator("gear_values", mode="before")
    @classmethod
    def _keys_as_text(cls, v):
        return {str(k): code for k, code in v.items()} if isinstance(v, dict) else v


@dataclass(frozen=True)
class Column:
    """One raw source column, and how to point at its i-th value in error messages."""

    values: np.ndarray
    locate: Callable[[int], str]


def _check_mapping(m: ChannelMapping, where: str) -> None:
    """Units known and convertible to each channel; gear codes in {-1, 0, 1}."""
    for name, src in m.channels.items():
        if name == "t":
            raise ConfigError(f"{where}: channel 't': map time under 'time:', not 'channels:'")
        if name not in CHANNEL_BY_NAME:
            raise ConfigError(f"{where}: channel {name!r}: not a schema channel")
        if CHANNEL_BY_NAME[name].integer and src.interpolation == "linear":
            raise ConfigError(
                f"{where}: channel {name!r}: an integer channel is never interpolated "
                "(interpolation: hold or auto)"
            )
        if src.unit is None:
            continue
        if src.unit not in UNIT_CONVERSIONS:
            raise ConfigError(
                f"{where}: channel {name!r}: unknown unit {src.unit!r} "
                f"(known: {', '.join(UNIT_CONVERSIONS)})"
            )
        target = CHANNEL_BY_NAME[name].unit
        if UNIT_CONVERSIONS[src.unit][0] != target:
            raise ConfigError(
                f"{where}: channel {name!r}: unit {src.unit!r} cannot be converted to the "
                f"channel's unit {target!r}"
            )
    if UNIT_CONVERSIONS.get(m.time.unit, ("",))[0] != "s":
        raise ConfigError(f"{where}: time: unit {m.time.unit!r} is not a time unit (s or ms)")
    if m.csv.delimiter == m.csv.decimal:
        raise ConfigError(f"{where}: csv: delimiter and decimal mark are both {m.csv.decimal!r}")
    for code, value in (m.gear_values or {}).items():
        if value not in (-1, 0, 1):
            raise ConfigError(f"{where}: gear_values: {code!r} -> {value}, expected -1, 0 or 1")


def load_mapping(path: str | Path) -> ChannelMapping:
    """Read and check a mapping YAML; any problem is a one-line ConfigError."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: mapping file not found")
    try:
        doc = yaml.safe_load(p.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc.__class__.__name__})") from exc
    if not isinstance(doc, dict):
        raise ConfigError(f"{p}: expected a mapping at top level")
    try:
        m = ChannelMapping.model_validate(doc)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        raise ConfigError(f"{p}: field {loc!r}: {err['msg']}") from exc
    _check_mapping(m, str(p))
    if m.can.dbc is not None and not Path(m.can.dbc).is_absolute():
        can = m.can.model_copy(update={"dbc": str(p.parent / m.can.dbc)})
        m = m.model_copy(update={"can": can})
    return m


def as_mapping(mapping: ChannelMapping | str | Path | None) -> ChannelMapping:
    """A ChannelMapping from an object, a YAML path, or None (identity mapping)."""
    if mapping is None:
        return ChannelMapping()
    if isinstance(mapping, ChannelMapping):
        _check_mapping(mapping, "mapping")
        return mapping
    return load_mapping(mapping)


def parse_numbers(col: Column, label: str, source: str, decimal: str = ".") -> np.ndarray:
    """Raw values (numbers or text) -> float64; text that is not a number is an error.

    ``nan``/``inf`` text parses (validation then reports it); an empty field or other
    text raises DataError naming ``label`` and the first offending value's location.
    """
    v = col.values
    if v.dtype.kind in "biuf":
        return v.astype(np.float64)
    text = [str(x).strip() for x in v]
    if decimal != ".":
        text = [s.replace(decimal, ".") for s in text]
    try:
        return np.array([float(s) for s in text], dtype=np.float64)
    except ValueError:
        pass
    bad = []
    for i, s in enumerate(text):
        try:
            float(s)
        except ValueError:
            bad.append(i)
    i = bad[0]
    what = "empty value" if text[i] == "" else f"non-numeric value {str(v[i]).strip()!r}"
    raise DataError(f"{source}: {label}: {what} at {col.locate(i)} ({len(bad)} non-numeric values)")


def _gear(col: Column, m: ChannelMapping, label: str, source: str) -> np.ndarray:
    """Gear codes -> -1/0/+1 via gear_values (text or numeric codes), else numeric as is."""
    if m.gear_values is None:
        return parse_numbers(col, label, source, m.csv.decimal)
    by_text = dict(m.gear_values)
    by_num: dict[float, int] = {}
    for k, code in m.gear_values.items():
        with contextlib.suppress(ValueError):
            by_num[float(k)] = code
    out = np.empty(len(col.values), dtype=np.float64)
    for i, raw in enumerate(col.values):
        s = str(raw).strip()
        code = by_text.get(s)
        if code is None:
            try:
                code = by_num.get(float(s))
            except ValueError:
                code = None
        if code is None:
            known = ", ".join(m.gear_values)
            raise DataError(
                f"{source}: {label}: value {s!r} at {col.locate(i)} is not in gear_values ({known})"
            )
        out[i] = code
    return out


def _label(name: str, column: str) -> str:
    return f"channel {name!r}" + (f" (column {column!r})" if column != name else "")


def apply_mapping(raw: dict[str, Column], m: ChannelMapping, source: str) -> dict[str, np.ndarray]:
    """Raw columns -> schema channels (float64, schema units) plus ``truth_*`` columns.

    Channels not in the mapping are read from a column of their own name, if any (a
    missing required one is then reported by validation). Other columns are ignored.
    """
    out: dict[str, np.ndarray] = {}
    tsrc = m.time
    if tsrc.column not in raw:
        raise DataError(
            f"{source}: channel 't': time column {tsrc.column!r} not found "
            f"(columns: {', '.join(raw)})"
        )
    t = parse_numbers(raw[tsrc.column], _label("t", tsrc.column), source, m.csv.decimal)
    t = convert_to_schema(t, tsrc.unit, "t")
    if tsrc.start_at_zero and len(t):
        t = t - t[0]
    out["t"] = t
    for name in CHANNEL_BY_NAME:
        if name == "t":
            continue
        src = m.channels.get(name)
        if src is None:
            if name in raw:
                col = raw[name]
                out[name] = (
                    _gear(col, m, _label(name, name), source)
                    if name == "gear"
                    else parse_numbers(col, _label(name, name), source, m.csv.decimal)
                )
            continue
        if src.column is None:
            raise DataError(
                f"{source}: channel {name!r}: the mapping gives a CAN {src.describe()}; "
                "this log needs a 'column'"
            )
        if src.column not in raw:
            raise DataError(
                f"{source}: channel {name!r}: mapped column {src.column!r} not found "
                f"(columns: {', '.join(raw)})"
            )
        label = _label(name, src.column)
        if name == "gear":
            vals = _gear(raw[src.column], m, label, source)
        else:
            vals = parse_numbers(raw[src.column], label, source, m.csv.decimal)
            if src.unit is not None:
                vals = convert_to_schema(vals, src.unit, name)
        out[name] = -vals if src.invert else vals
    for col_name, col in raw.items():
        if col_name.startswith(TRUTH_PREFIX):
            out[col_name] = parse_numbers(col, _label(col_name, col_name), source, m.csv.decimal)
    return out


def mapping_hint(m: ChannelMapping, channel: str | None) -> str:
    """' (mapped from column X in unit U; check the mapping)' for a mapped channel, else ''."""
    if channel == "t" and (m.time.column != "t" or m.time.unit != "s"):
        return f" (mapped from column {m.time.column!r} in {m.time.unit!r}; check the mapping)"
    src = m.channels.get(channel or "")
    if src is None:
        return ""
    unit = src.unit or CHANNEL_BY_NAME[channel].unit
    return f" (mapped from {src.describe()} in {unit!r}; check the mapping's unit)"
