"""Channel mapping: how a user's log maps onto the schema, in one documented vocabulary.

A mapping YAML (configs/mapping_example.yaml documents every key; configs/mappings/ holds
mappings for real logs) says, per schema channel, where it comes from and how its values
become schema values. The steps, in this order (docs/data.md, "Channel mapping"):

1. **sources**: one ``column`` (CSV/Parquet/.mat column or MDF channel), or a CAN
   ``message``/``signal`` of the DBC, or several ``sources`` combined by ``combine``
   (``mean`` of four wheel speeds, ``sum`` of a coarse and a fine angle); or the channel
   is ``absent`` from these logs, or a known ``constant``.
2. **values**: an enumeration map (text labels or numeric codes -> numbers), e.g. gear
   ``{P: 0, R: -1, N: 0, D: 1}``; an unlisted code is an error.
3. **invalid samples** (on each source's own values, before any scaling): the values in
   ``invalid`` (start-up sentinels such as 3276.7, ``.nan``, ``""``) and those outside
   ``valid_range``; ``on_invalid: mask`` drops them (the resampler bridges short holes,
   a hole longer than the gap limit is a gap), ``crop`` cuts the trial to the longest
   stretch without them.
4. **time**: every format goes onto the 100 Hz grid (:mod:`parknss.data.assemble`).
5. **combine** the sources, then ``scale``/``offset`` (raw counts -> ``unit``), the unit
   conversion of :func:`parknss.signals.convert_to_schema`, ``invert``,
   ``sign_from_gear`` (unsigned speed: magnitude with the sign of the gear) and ``clip``
   (a documented clamp in schema units; clamped samples are counted in the provenance).

Nothing is guessed: an unknown unit, a unit of the wrong kind, a missing column or an
unmapped code is a one-line error that says what to change in the mapping.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, ValidationError, field_validator, model_validator

from parknss.config import StrictModel, parse_yaml
from parknss.errors import ConfigError
from parknss.signals import (
    CHANNEL_BY_NAME,
    DT,
    UNIT_CONVERSIONS,
    canonical_unit,
    unit_dimension,
)
from parknss.vehicle import VehicleGeometry
from parknss.vehicle_ranges import check_vehicle

Interpolation = Literal["auto", "linear", "hold"]
ABSENT = "absent"  # YAML shorthand: ``torque_cmd: absent``


class SourceRef(StrictModel):
    """One source of a channel: a column / MDF channel, or a CAN message and signal.

    ``group`` picks the MDF data group when a name occurs in several.
    """

    column: str | None = Field(None, min_length=1)
    message: str | None = Field(None, min_length=1)
    signal: str | None = Field(None, min_length=1)
    group: int | None = Field(None, ge=0)

    @model_validator(mode="after")
    def _one_kind(self) -> SourceRef:
        can = self.message is not None or self.signal is not None
        if can and (self.message is None or self.signal is None):
            raise ValueError("a CAN source needs both 'message' and 'signal'")
        if can == (self.column is not None):
            raise ValueError(
                "give 'column' (CSV, Parquet, .mat or MDF channel) or 'message' and "
                "'signal' (CAN)" + (", not both" if can else "")
            )
        return self

    def describe(self) -> str:
        """The source in words, for messages: ``column 'X'`` or ``message 'M', signal 'S'``."""
        if self.column is not None:
            return f"column {self.column!r}"
        return f"message {self.message!r}, signal {self.signal!r}"


class ValidIf(SourceRef):
    """A validity signal that gates a channel: a sample of the channel counts only where
    the gate's last value at or before its time is one of ``equals`` (numbers, or labels
    of a value table / text). Read from the same kind of source as the channel (a column,
    or a CAN message and signal), e.g. CANedge ``SpeedValid``, ``ImuValid``."""

    equals: list[float | str] = Field(default_factory=lambda: [1.0], min_length=1)


class ChannelSource(StrictModel):
    """Where one schema channel comes from and how its values become schema values.

    Exactly one of: a single source (``column``, or ``message`` + ``signal``), several
    ``sources`` with ``combine``, ``absent: true``, or ``constant``. See the module text
    for the order of the steps.

    Attributes:
        unit: the unit of the values after ``scale``/``offset`` (any spelling of
            :func:`parknss.signals.canonical_unit`); None: the file's unit for bus logs
            (``use_file_units``), else the schema unit.
        scale, offset: raw -> unit, ``value * scale + offset`` (raw counts).
        invert: multiply by -1 after the conversion (opposite sign convention).
        sign_from_gear: the speed is unsigned: take its magnitude with the sign of the
            gear (reverse negative; drive, neutral and park positive).
        clip: clamp to [lo, hi] in schema units (documented; counted in the provenance).
        values: enumeration map, source label or code -> number (gear: -1/0/+1).
        invalid: source values that mark a sample invalid (sentinels; ``.nan``; ``""``).
        valid_range: source values outside [lo, hi] are invalid.
        on_invalid: ``mask`` (drop the samples) or ``crop`` (cut the trial to the longest
            stretch without them).
        interpolation: ``linear``, ``hold`` (previous value) or ``auto`` (hold for gear,
            integer, enumerated/text and CAN signals; linear otherwise).
        max_gap_s: longest hole between two samples of this channel that is bridged, s
            (None: ``resample.max_gap_s``).
        valid_if: a validity signal gating the channel (:class:`ValidIf`): samples where
            it is not valid are invalid samples (``on_invalid`` applies).
        event: the channel is logged on change only (its value holds until the next
            sample, however long): no gap limit, and its last value holds to the end.
            None: the reader's default (true for MDF enumerated and integer channels,
            false otherwise).
    """

    column: str | None = Field(None, min_length=1)
    message: str | None = Field(None, min_length=1)
    signal: str | None = Field(None, min_length=1)
    group: int | None = Field(None, ge=0)
    sources: list[SourceRef] | None = Field(None, min_length=1)
    combine: Literal["mean", "sum"] | None = None
    absent: bool = False
    constant: float | None = None
    unit: str | None = None
    scale: float = 1.0
    offset: float = 0.0
    invert: bool = False
    sign_from_gear: bool = False
    clip: tuple[float, float] | None = None
    values: dict[str, float] | None = None
    invalid: list[float | str] = Field(default_factory=list)
    valid_range: tuple[float, float] | None = None
    on_invalid: Literal["mask", "crop"] = "mask"
    interpolation: Interpolation = "auto"
    max_gap_s: float | None = Field(None, gt=0.0)
    event: bool | None = None
    valid_if: ValidIf | None = None

    @model_validator(mode="before")
    @classmethod
    def _shorthand(cls, v):
        if isinstance(v, str) and v.strip().lower() == ABSENT:
            return {"absent": True}
        return v

    @property
    def has_source(self) -> bool:
        """Whether the spec names where the channel comes from (or that it has none)."""
        return (any(x is not None for x in (self.column, self.message, self.signal,
                                            self.sources, self.constant)) or self.absent)

    @field_validator("values", mode="before")
    @classmethod
    def _keys_as_text(cls, v):
        return {str(k): code for k, code in v.items()} if isinstance(v, dict) else v

    @model_validator(mode="after")
    def _one_kind(self) -> ChannelSource:
        single = any(x is not None for x in (self.column, self.message, self.signal))
        kinds = [
            k
            for k, on in (
                ("a single source", single),
                ("'sources'", self.sources is not None),
                ("'absent'", self.absent),
                ("'constant'", self.constant is not None),
            )
            if on
        ]
        if len(kinds) > 1 or (not kinds and self.has_source):
            raise ValueError(
                "give one of: 'column', 'message' and 'signal', 'sources', 'absent: true' or "
                "'constant'" + (f" (got {' and '.join(kinds)})" if kinds else "")
            )
        if single:
            SourceRef(column=self.column, message=self.message, signal=self.signal)
        if self.sources is not None and len(self.sources) > 1 and self.combine is None:
            raise ValueError("several 'sources' need 'combine: mean' or 'combine: sum'")
        if self.constant is not None and not math.isfinite(self.constant):
            raise ValueError("'constant' must be a finite number")
        for name, pair in (("clip", self.clip), ("valid_range", self.valid_range)):
            if pair is not None and not pair[0] <= pair[1]:
                raise ValueError(f"'{name}' needs [lo, hi] with lo <= hi, got {list(pair)}")
        if self.scale == 0.0 or not math.isfinite(self.scale):
            raise ValueError("'scale' must be a finite, non-zero number")
        return self

    @property
    def refs(self) -> list[SourceRef]:
        """The sources (empty for absent and constant channels)."""
        if self.sources is not None:
            return list(self.sources)
        if self.column is None and self.message is None:
            return []
        return [SourceRef(column=self.column, message=self.message, signal=self.signal,
                          group=self.group)]

    def describe(self) -> str:
        """The source in words, for messages (the first source of several)."""
        if self.absent:
            return "absent"
        if self.constant is not None:
            return f"constant {self.constant:g}"
        refs = self.refs
        more = f" (+{len(refs) - 1} more)" if len(refs) > 1 else ""
        return refs[0].describe() + more


class TimeSource(StrictModel):
    """The time base of table logs, and the time window kept of every log.

    Attributes:
        column: the time column of CSV/Parquet/.mat logs (bus logs carry their own).
        unit: its unit: s, ms, us or ns (any spelling of canonical_unit).
        start_at_zero: subtract the first kept time stamp (logs with absolute time).
        crop: keep only [start, end] s, counted from the log's first time stamp (the
            manifest's ``start_s``/``end_s`` columns override it per file).
    """

    column: str = Field("t", min_length=1)
    unit: str = "s"
    start_at_zero: bool = False
    crop: tuple[float, float] | None = None

    @field_validator("crop")
    @classmethod
    def _window(cls, v):
        if v is not None and not (0.0 <= v[0] < v[1]):
            raise ValueError(f"crop needs [start, end] with 0 <= start < end, got {list(v)}")
        return v


class CsvOptions(StrictModel):
    """How CSV logs are written: field delimiter and decimal mark (sniffed from the file
    when not given), and whether a units row follows the header (None: detected)."""

    delimiter: str = Field(",", min_length=1, max_length=1)
    decimal: str = Field(".", min_length=1, max_length=1)
    units_row: bool | None = None


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
            try:
                check_vehicle(v, "vehicle.geometry")
            except ConfigError as exc:
                raise ValueError(str(exc)) from exc
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
        strict_dbc: load the DBC in cantools' strict mode (overlapping signals, missing
            sections are errors); by default it is loaded leniently and what was ignored
            is reported as a warning.
        duplicate_buses: a message seen on several bus channels (frames forwarded by a
            gateway): ``first`` keeps one bus per message (the one with most frames of it,
            ties to the lowest number) and records the choice; ``keep`` keeps all frames.
    """

    dbc: str | None = Field(None, min_length=1)
    bus_channel: int | None = Field(None, ge=0)
    use_file_units: bool = True
    strict_dbc: bool = False
    duplicate_buses: Literal["first", "keep"] = "first"


class ResampleOptions(StrictModel):
    """How every log goes onto the 100 Hz grid (docs/data.md, "Time").

    Attributes:
        time_tolerance_s: a time stamp within this of a grid time counts as on it, s
            (loggers store times with finite resolution; BLF in ns).
        max_gap_s: the longest hole between two samples of a channel that is bridged
            (interpolated or held), s; a channel's own ``max_gap_s`` overrides it.
        on_gap: a longer hole inside the log: ``refuse`` (one-line error naming the
            channel and the time), or ``split`` (each stretch between gaps becomes a
            trial of its own, ids ``<id>_s1``, ``<id>_s2``, ...).
        min_segment_s: with ``split``, stretches shorter than this are dropped (s).
    """

    time_tolerance_s: float = Field(1.0e-6, gt=0.0, lt=DT / 2)
    max_gap_s: float = Field(0.5, gt=0.0)
    on_gap: Literal["refuse", "split"] = "refuse"
    min_segment_s: float = Field(5.0, ge=0.0)


class ChannelMapping(StrictModel):
    """A whole mapping file (see configs/mapping_example.yaml).

    ``gear_values`` is the older spelling of ``channels.gear.values`` (give one of them).
    """

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

    def source(self, name: str) -> ChannelSource:
        """The channel's source: as mapped, else a column/MDF channel of its own name.

        The gear's enumeration map is folded in from ``gear_values``.
        """
        src = self.channels.get(name)
        if src is None:
            src = ChannelSource(column=name)
        elif not src.has_source:  # only how to read it: from a column of its own name
            src = src.model_copy(update={"column": name})
        if name == "gear" and self.gear_values is not None and src.values is None:
            src = src.model_copy(update={"values": {k: float(v) for k, v in
                                                   self.gear_values.items()}})
        return src

    def absent(self) -> list[str]:
        """Schema channels the mapping declares absent, in schema order."""
        return [c for c in CHANNEL_BY_NAME if c != "t" and self.source(c).absent]

    def present(self) -> list[str]:
        """Schema channels a log read with this mapping must have (t first)."""
        return [c for c in CHANNEL_BY_NAME if c == "t" or not self.source(c).absent]

    def is_mapped(self, name: str) -> bool:
        """Whether the mapping names the channel (rather than defaulting to its own name)."""
        return name in self.channels or (name == "gear" and self.gear_values is not None)


@dataclass(frozen=True)
class Column:
    """One raw source column, and how to point at its i-th value in error messages."""

    values: np.ndarray
    locate: Callable[[int], str]
    unit: str = ""  # the file's own unit for it (CSV bracket or units row), if any


def _check_unit(where: str, name: str, unit: str | None) -> None:
    if unit is None:
        return
    if canonical_unit(unit) is None:
        raise ConfigError(
            f"{where}: channel {name!r}: unknown unit {unit!r} "
            f"(known: {', '.join(UNIT_CONVERSIONS)}, in any case, and common aliases)"
        )
    target = CHANNEL_BY_NAME[name].unit
    if unit_dimension(unit) != target:
        raise ConfigError(
            f"{where}: channel {name!r}: unit {unit!r} cannot be converted to the "
            f"channel's unit {target!r}"
        )


def _check_mapping(m: ChannelMapping, where: str) -> None:
    """Names, units and codes that can work: every problem one line naming the key."""
    for name, src in m.channels.items():
        if name == "t":
            raise ConfigError(f"{where}: channel 't': map time under 'time:', not 'channels:'")
        if name not in CHANNEL_BY_NAME:
            raise ConfigError(f"{where}: channel {name!r}: not a schema channel")
        integer = CHANNEL_BY_NAME[name].integer
        if integer and src.interpolation == "linear":
            raise ConfigError(
                f"{where}: channel {name!r}: an integer channel is never interpolated "
                "(interpolation: hold or auto)"
            )
        if integer and (src.unit not in (None, "-") or src.scale != 1.0 or src.offset != 0.0):
            raise ConfigError(
                f"{where}: channel {name!r}: gear takes no unit, scale or offset; map its "
                "codes with 'values'"
            )
        _check_unit(where, name, src.unit)
        if src.sign_from_gear and name in ("gear", "t"):
            raise ConfigError(f"{where}: channel {name!r}: sign_from_gear is for speeds")
        if src.sign_from_gear and m.source("gear").absent:
            raise ConfigError(
                f"{where}: channel {name!r}: sign_from_gear needs the gear channel, which "
                "the mapping declares absent (give gear a constant, e.g. 1 for a drive "
                "without reversing, or map it)"
            )
        if name == "gear" and src.values is not None and m.gear_values is not None:
            raise ConfigError(
                f"{where}: channel 'gear': give its codes in channels.gear.values or in "
                "gear_values, not both"
            )
    gear = m.source("gear")
    for code, value in (gear.values or {}).items():
        if value not in (-1, 0, 1):
            raise ConfigError(
                f"{where}: gear_values: {code!r} -> {value:g}, expected -1, 0 or 1"
            )
    if gear.constant is not None and gear.constant not in (-1, 0, 1):
        raise ConfigError(f"{where}: channel 'gear': constant {gear.constant:g} is not -1, 0 or 1")
    if unit_dimension(m.time.unit) != "s":
        raise ConfigError(
            f"{where}: time: unit {m.time.unit!r} is not a time unit (s, ms, us or ns)"
        )
    if m.csv.delimiter == m.csv.decimal:
        raise ConfigError(f"{where}: csv: delimiter and decimal mark are both {m.csv.decimal!r}")
    if all(m.source(c).absent for c in CHANNEL_BY_NAME if c != "t"):
        raise ConfigError(f"{where}: every channel is declared absent; nothing to read")


def load_mapping(path: str | Path) -> ChannelMapping:
    """Read and check a mapping YAML; any problem is a one-line ConfigError."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: mapping file not found")
    try:
        doc = parse_yaml(p.read_text(), str(p))  # depth-limited
    except UnicodeDecodeError as exc:
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
        beside = p.parent / m.can.dbc
        if beside.is_file():  # else it is looked for beside each log (resolve_dbc)
            can = m.can.model_copy(update={"dbc": str(beside)})
            m = m.model_copy(update={"can": can})
    return m


def resolve_dbc(m: ChannelMapping, log: Path) -> ChannelMapping:
    """The mapping with ``can.dbc`` found: as given (absolute, beside the mapping file or
    the working directory), else beside the log; ConfigError naming the places tried."""
    if m.can.dbc is None:
        return m
    dbc = Path(m.can.dbc)
    if dbc.is_file():
        return m
    beside = log.parent / dbc
    if not dbc.is_absolute() and beside.is_file():
        return m.model_copy(update={"can": m.can.model_copy(update={"dbc": str(beside)})})
    where = f"{dbc}" + ("" if dbc.is_absolute() else f" nor {beside}")
    raise ConfigError(
        f"{log}: DBC file {m.can.dbc} not found (can.dbc in the mapping; looked for {where})"
    )


def as_mapping(mapping: ChannelMapping | str | Path | None) -> ChannelMapping:
    """A ChannelMapping from an object, a YAML path, or None (identity mapping)."""
    if mapping is None:
        return ChannelMapping()
    if isinstance(mapping, ChannelMapping):
        _check_mapping(mapping, "mapping")
        return mapping
    return load_mapping(mapping)


def iter_sources(m: ChannelMapping) -> Iterator[tuple[str, int, SourceRef, ChannelSource]]:
    """(schema channel, source index, source, channel spec) of every source to read."""
    for name in CHANNEL_BY_NAME:
        if name == "t":
            continue
        src = m.source(name)
        for k, ref in enumerate(src.refs):
            yield name, k, ref, src


GATE_SUFFIX = "#valid"  # the series of a channel's valid_if signal: '<channel>#valid'


def iter_gates(m: ChannelMapping) -> Iterator[tuple[str, ValidIf]]:
    """(schema channel, its validity signal) of every gated channel."""
    for name in CHANNEL_BY_NAME:
        if name != "t":
            src = m.source(name)
            if src.valid_if is not None and not src.absent and src.constant is None:
                yield name, src.valid_if


def source_key(channel: str, k: int) -> str:
    """The raw key of a channel's k-th source (unique within one log)."""
    return f"{channel}#{k}"


def source_label(channel: str, ref: SourceRef, kind: str = "column") -> str:
    """How messages name a source: ``channel 'vx' (column 'VehSpd')``."""
    if ref.message is not None:
        return f"channel {channel!r} (message {ref.message!r}, signal {ref.signal!r})"
    if ref.column == channel:
        return f"channel {channel!r}"
    return f"channel {channel!r} ({kind} {ref.column!r})"


def mapping_hint(m: ChannelMapping, channel: str | None) -> str:
    """' (mapped from column X in unit U; check the mapping)' for a mapped channel, else ''."""
    if channel == "t" and (m.time.column != "t" or m.time.unit != "s"):
        return f" (mapped from column {m.time.column!r} in {m.time.unit!r}; check the mapping)"
    if channel not in CHANNEL_BY_NAME or not m.is_mapped(channel):
        return ""
    src = m.source(channel)
    if src.absent or src.constant is not None:
        return ""
    unit = src.unit or CHANNEL_BY_NAME[channel].unit
    return f" (mapped from {src.describe()} in {unit!r}; check the mapping's unit)"
