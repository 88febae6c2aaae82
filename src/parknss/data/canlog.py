"""CAN logs (.blf, .asc) with a DBC: python-can reads frames, cantools decodes signals.

The mapping names the DBC (``can.dbc``) and, for every schema channel, the ``message``
and ``signal`` that carry it. Frames are read with python-can's BLFReader/ASCReader
(error and remote frames skipped; ``can.bus_channel`` keeps one bus), time counted from
the log's first frame. Each mapped signal becomes a :class:`~parknss.data.resample.
Series` of its decoded values at the frame times (enumerated signals as their DBC
labels) and goes onto the 100 Hz grid by zero-order hold of the last received value
(:mod:`parknss.data.resample`: the trial starts when every signal has been received
once and ends at the last frame of any mapped signal). Units come from the mapping, else from the
DBC (``can.use_file_units``), converted by the channel mapping. Every problem is a
one-line DataError naming the file and the channel.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from parknss.data.mapping import ChannelMapping
from parknss.data.resample import TIME_KEY, BusLog, Series, to_raw, unique_key
from parknss.errors import DataError
from parknss.signals import CHANNELS

CAN_SUFFIXES: tuple[str, ...] = (".blf", ".asc")
ASC_TAIL_BYTES = 4096  # how much of an .asc file's end is read to find its closing line


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{exc.__class__.__name__}: {text}"[:300]


@dataclass(frozen=True)
class _Source:
    """One mapped schema channel: its DBC message and signal."""

    channel: str
    message: Any  # cantools Message
    signal: Any  # cantools Signal
    label: str

    @property
    def frame_key(self) -> tuple[int, bool]:
        return int(self.message.frame_id), bool(self.message.is_extended_frame)


def _load_dbc(path: Path, m: ChannelMapping) -> Any:
    if m.can.dbc is None:
        raise DataError(f"{path}: a CAN log needs a DBC: set can.dbc in the mapping")
    dbc = Path(m.can.dbc)
    if not dbc.is_file():
        raise DataError(f"{path}: DBC file {dbc} not found (can.dbc in the mapping)")
    try:
        import can  # noqa: F401  (python-can, used by _frames)
        import cantools
    except ImportError as exc:  # pinned dependencies; only a broken install lacks them
        raise DataError(f"{path}: reading CAN logs needs cantools and python-can ({exc})") from exc
    try:
        db = cantools.database.load_file(dbc)
    except Exception as exc:  # cantools raises many types for bad files
        raise DataError(f"{path}: DBC file {dbc}: not readable ({_one_line(exc)})") from exc
    if not hasattr(db, "get_message_by_name"):
        raise DataError(f"{path}: DBC file {dbc}: not a CAN database")
    return db


def _sources(db: Any, m: ChannelMapping, path: Path) -> list[_Source]:
    """Every schema channel's message and signal, checked against the DBC."""
    dbc = Path(str(m.can.dbc)).name
    out = []
    for ch in CHANNELS[1:]:
        src = m.channels.get(ch.name)
        if src is None:
            raise DataError(
                f"{path}: channel {ch.name!r}: not mapped (a CAN log needs "
                f"channels.{ch.name}.message and .signal in the mapping)"
            )
        if src.message is None or src.signal is None:
            raise DataError(
                f"{path}: channel {ch.name!r}: the mapping gives {src.describe()}; a CAN log "
                "needs 'message' and 'signal'"
            )
        label = f"channel {ch.name!r} (message {src.message!r}, signal {src.signal!r})"
        try:
            msg = db.get_message_by_name(src.message)
        except KeyError:
            raise DataError(f"{path}: {label}: message not in the DBC {dbc}") from None
        try:
            sig = msg.get_signal_by_name(src.signal)
        except KeyError:
            raise DataError(
                f"{path}: {label}: signal not in message {src.message!r} of the DBC {dbc}"
            ) from None
        out.append(_Source(ch.name, msg, sig, label))
    return out


def _check_asc_end(path: Path) -> None:
    """An .asc log closes with 'End TriggerBlock'; without it the file was cut off."""
    with open(path, "rb") as f:
        f.seek(max(0, path.stat().st_size - ASC_TAIL_BYTES))
        tail = f.read().decode("latin-1")
    lines = [ln.strip() for ln in tail.splitlines() if ln.strip()]
    if not lines or not lines[-1].lower().startswith("end triggerblock"):
        raise DataError(f"{path}: truncated .asc log (no closing 'End TriggerBlock' line)")


def _frames(path: Path, wanted: set[tuple[int, bool]], bus: int | None):
    """(time of the first frame, {frame key: [(timestamp, data), ...]}) in file order."""
    import can

    kind = path.suffix.lower()
    if kind == ".asc":
        _check_asc_end(path)
    reader = None
    try:
        reader = can.BLFReader(str(path)) if kind == ".blf" else can.ASCReader(str(path))
        if kind == ".blf" and reader.file_size > path.stat().st_size:
            raise DataError(
                f"{path}: truncated .blf log (header says {reader.file_size} bytes, the file "
                f"has {path.stat().st_size})"
            )
        t0 = None
        frames: dict[tuple[int, bool], list] = defaultdict(list)
        for msg in reader:
            if t0 is None:
                t0 = float(msg.timestamp)
            if msg.is_error_frame or msg.is_remote_frame:
                continue
            if bus is not None and msg.channel != bus:
                continue
            key = (int(msg.arbitration_id), bool(msg.is_extended_id))
            if key in wanted:
                frames[key].append((float(msg.timestamp), bytes(msg.data)))
    except DataError:
        raise
    except Exception as exc:  # python-can raises struct.error, BLFParseError, ValueError...
        raise DataError(
            f"{path}: not a readable {kind} log, corrupt or truncated ({_one_line(exc)})"
        ) from exc
    finally:
        if reader is not None:
            reader.stop()
    if t0 is None:
        raise DataError(f"{path}: no CAN frames in the log")
    return t0, frames


def _decode_all(src: _Source, frames: list, t0: float, path: Path) -> list[tuple[float, dict]]:
    """Every frame of the source's message decoded: (s from the first frame, signals)."""
    if not frames:
        raise DataError(
            f"{path}: {src.label}: no frames of the message (id 0x{src.frame_key[0]:X}) in the log"
        )
    out = []
    for ts, data in frames:
        try:
            out.append((ts - t0, src.message.decode(data, decode_choices=True, scaling=True)))
        except Exception as exc:  # cantools DecodeError, struct errors on short frames
            raise DataError(
                f"{path}: {src.label}: frame at t={ts - t0:.6f} s cannot be decoded "
                f"({_one_line(exc)})"
            ) from exc
    return out


def _decoded(src: _Source, decoded: list[tuple[float, dict]], path: Path) -> Series:
    """The signal's values at its message's frame times (s from the first frame)."""
    name = src.signal.name
    # multiplexed signals are absent from the frames of other multiplexer values
    times = [t for t, sigs in decoded if name in sigs]
    values = [sigs[name] for _, sigs in decoded if name in sigs]
    if not values:
        raise DataError(f"{path}: {src.label}: no frame carries the signal")
    if all(isinstance(v, int | float) for v in values):
        arr = np.asarray(values, dtype=np.float64)
    else:  # enumerated: labels where the DBC has one, numbers as text otherwise
        arr = np.array([str(getattr(v, "name", v)) for v in values], dtype=object)
    return Series(
        src.channel,
        f"{src.message.name}.{src.signal.name}",
        src.label,
        np.asarray(times, dtype=np.float64),
        arr,
        hold=True,
        unit=src.signal.unit or "",
    )


def read_can(path: Path, m: ChannelMapping) -> BusLog:
    """Read one CAN log: mapped signals decoded and held onto the 100 Hz grid.

    Args:
        path: an existing, non-empty .blf or .asc file.
        m: the channel mapping (``can``, ``channels`` with message/signal, ``resample``,
            ``time.start_at_zero``).

    Returns:
        A BusLog: raw columns (grid time in s from the first frame, signal values (T,) in
        DBC units), the mapping that converts them, provenance.
    """
    db = _load_dbc(path, m)
    sources = _sources(db, m, path)
    t0, frames = _frames(path, {s.frame_key for s in sources}, m.can.bus_channel)
    taken: set[str] = {TIME_KEY}
    series = []
    by_message: dict[tuple[int, bool], list[tuple[float, dict]]] = {}
    for src in sources:
        if src.frame_key not in by_message:  # decode each message's frames once
            by_message[src.frame_key] = _decode_all(src, frames.get(src.frame_key, []), t0, path)
        s = _decoded(src, by_message[src.frame_key], path)
        mode = m.channels[src.channel].interpolation
        hold = mode != "linear"  # CAN signals are event-based: held unless asked
        key = unique_key(s.key, s.channel, taken)
        series.append(Series(s.channel, key, s.label, s.t, s.values, hold, s.unit))
    log = to_raw(series, m, str(path), path.suffix.lower()[1:], m.can.use_file_units)
    log.provenance["dbc"] = str(m.can.dbc)
    return log
