"""Bus logs made by parknss: encode signals into frames and write them as real loggers do.

For tests and benchmarks: :func:`encode_message` packs physical signal values into
payloads (the inverse of :func:`parknss.data.dbc.decode_signal`, vectorised),
:func:`frames_from_signals` builds a :class:`~parknss.data.canframes.FrameTable` from
per-message signal time series, and the writers put a table into a .blf or .asc
(python-can), a candump .log, a SavvyCAN GVRET .csv, or an MDF4 bus-logging file
(a ``CAN_DataFrame`` channel group as the CANedge writes it, which asammdf's
``extract_bus_logging`` decodes). :func:`on_buses` copies frames onto more buses, as a
gateway forwarding them would.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from parknss.data.canframes import FrameTable
from parknss.data.dbc import encode_signal, to_raw_numbers

SignalSeries = Mapping[str, tuple[np.ndarray, np.ndarray]]  # signal: (t (N,), values (N,))


def _active(message: Any, signal: Any, values: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """(N,) bool: frames in which the signal's multiplexers select it."""
    if not signal.multiplexer_ids or not signal.multiplexer_signal:
        return np.ones(n, dtype=bool)
    mux = message.get_signal_by_name(signal.multiplexer_signal)
    if mux.name not in values:
        raise ValueError(
            f"message {message.name!r}: signal {signal.name!r} is multiplexed by "
            f"{mux.name!r}; give values for {mux.name!r} too"
        )
    number = to_raw_numbers(mux, np.asarray(values[mux.name]))
    here = np.isin(number, list(signal.multiplexer_ids))
    return here & _active(message, mux, values, n)


def encode_message(
    message: Any, values: Mapping[str, np.ndarray], n: int | None = None
) -> np.ndarray:
    """Payloads of N frames of ``message`` carrying the given physical values.

    Args:
        message: a cantools Message.
        values: {signal name: (N,) values}: numbers in the DBC unit, or value-table
            labels (str). Signals not given are 0 (raw); a multiplexed signal is
            written only in frames whose multiplexer value selects it.
        n: number of frames (needed when ``values`` is empty).

    Returns:
        (N, message.length) uint8. Values are quantised as cantools does
        (``round((v - offset) / scale)``, half to even) and clipped to what the bits
        hold.
    """
    arrays = {k: np.asarray(v) for k, v in values.items()}
    sizes = {len(v) for v in arrays.values()}
    if n is None:
        if len(sizes) != 1:
            raise ValueError(f"message {message.name!r}: give n or values of one length")
        n = sizes.pop()
    elif sizes - {n}:
        raise ValueError(f"message {message.name!r}: values must all have {n} samples")
    unknown = set(arrays) - {s.name for s in message.signals}
    if unknown:
        raise ValueError(f"message {message.name!r} has no signal(s) {sorted(unknown)}")
    out = np.zeros((n, message.length), dtype=np.uint8)
    for signal in message.signals:
        if signal.name not in arrays:
            continue
        rows = np.flatnonzero(_active(message, signal, arrays, n))
        raw = to_raw_numbers(signal, arrays[signal.name][rows])
        part = np.zeros((len(rows), message.length), dtype=np.uint8)
        encode_signal(signal, raw, part)
        out[rows] |= part
    return out


def _table(
    t: np.ndarray, ids: np.ndarray, ext: np.ndarray, bus: np.ndarray, data: np.ndarray
) -> FrameTable:
    width = 8 if data.shape[1] <= 8 else 64
    padded = np.zeros((len(t), width), dtype=np.uint8)
    padded[:, : data.shape[1]] = data
    return FrameTable(
        t=np.asarray(t, dtype=np.float64),
        id=np.asarray(ids, dtype=np.uint32),
        extended=np.asarray(ext, dtype=bool),
        bus=np.asarray(bus, dtype=np.int16),
        dlc=np.full(len(t), data.shape[1], dtype=np.uint8),
        data=padded,
        t_first=float(t[0]) if len(t) else float("nan"),
        n_frames=len(t),
        kind="generated",
    )


def message_frames(
    message: Any, t: np.ndarray, values: Mapping[str, np.ndarray], bus: int = 0
) -> FrameTable:
    """Frames of one message at times ``t`` (s, (N,)) with the given signal values."""
    t = np.asarray(t, dtype=np.float64)
    data = encode_message(message, values, len(t))
    n = len(t)
    return _table(
        t,
        np.full(n, message.frame_id),
        np.full(n, bool(message.is_extended_frame)),
        np.full(n, bus),
        data,
    )


def merge_frames(tables: list[FrameTable]) -> FrameTable:
    """All frames of several tables in time order (ties keep the order of ``tables``)."""
    tables = [tb for tb in tables if len(tb)]
    if not tables:
        raise ValueError("no frames to merge")
    width = max(tb.data.shape[1] for tb in tables)
    data = np.zeros((sum(len(tb) for tb in tables), width), dtype=np.uint8)
    row = 0
    for tb in tables:
        data[row : row + len(tb), : tb.data.shape[1]] = tb.data
        row += len(tb)
    t = np.concatenate([tb.t for tb in tables])
    order = np.argsort(t, kind="stable")
    merged = FrameTable(
        t=t[order],
        id=np.concatenate([tb.id for tb in tables])[order],
        extended=np.concatenate([tb.extended for tb in tables])[order],
        bus=np.concatenate([tb.bus for tb in tables])[order],
        dlc=np.concatenate([tb.dlc for tb in tables])[order],
        data=data[order],
        kind="generated",
    )
    return replace(merged, t_first=float(merged.t[0]), n_frames=len(merged))


def frames_from_signals(db: Any, schedule: Mapping[str, SignalSeries], bus: int = 0) -> FrameTable:
    """A frame table from signal time series, message by message.

    Args:
        db: a cantools Database.
        schedule: {message name: {signal name: (t (N,), values (N,))}}; the signals of
            one message must share their time stamps (one frame per time stamp).
        bus: the bus of every frame.

    Returns:
        All frames, sorted by time (stable).
    """
    tables = []
    for name, signals in schedule.items():
        message = db.get_message_by_name(name)
        times = [np.asarray(t, dtype=np.float64) for t, _ in signals.values()]
        if any(len(t) != len(times[0]) or not np.array_equal(t, times[0]) for t in times):
            raise ValueError(f"message {name!r}: its signals must share their time stamps")
        values = {s: v for s, (_, v) in signals.items()}
        tables.append(message_frames(message, times[0], values, bus))
    return merge_frames(tables)


def on_buses(frames: FrameTable, buses: tuple[int, ...] = (0, 1), delay_s: float = 0.0):
    """Every frame once per bus (the k-th copy ``k * delay_s`` later), time sorted."""
    copies = [
        replace(frames, bus=np.full(len(frames), b, dtype=np.int16), t=frames.t + k * delay_s)
        for k, b in enumerate(buses)
    ]
    return merge_frames(copies)


# --------------------------------------------------------------------------- writers


def _can_messages(frames: FrameTable):
    import can

    for i in range(len(frames)):
        n = int(frames.dlc[i])
        yield can.Message(
            timestamp=float(frames.t[i]),
            arbitration_id=int(frames.id[i]),
            is_extended_id=bool(frames.extended[i]),
            data=frames.data[i, :n].tobytes(),
            is_fd=n > 8,
            channel=int(frames.bus[i]),
        )


def _write_python_can(path: str | Path, frames: FrameTable, writer_name: str) -> Path:
    """Frames through one of python-can's file writers (``BLFWriter``, ``ASCWriter``)."""
    import can

    p = Path(path)
    _feed(getattr(can, writer_name)(str(p)), frames)
    return p


def _feed(writer, frames: FrameTable) -> None:
    """Every frame into an open python-can writer, which is stopped (file closed) after."""
    try:
        for msg in _can_messages(frames):
            writer.on_message_received(msg)
    finally:
        writer.stop()


def write_blf(path: str | Path, frames: FrameTable) -> Path:
    """A Vector .blf (python-can's BLFWriter; bus b is BLF channel b + 1)."""
    return _write_python_can(path, frames, "BLFWriter")


def write_asc(path: str | Path, frames: FrameTable) -> Path:
    """A Vector .asc (python-can's ASCWriter; bus b is channel b + 1)."""
    return _write_python_can(path, frames, "ASCWriter")


def write_trc(path: str | Path, frames: FrameTable, version: str = "2.1") -> Path:
    """A PCAN .trc (python-can's TRCWriter, version 2.1 or 1.0; bus b is bus b + 1).

    Version 2.1 keeps time offsets to 1 µs, 1.0 to 1 ms (and no start time).
    """
    import can
    from can.io.trc import TRCFileVersion

    versions = {"2.1": TRCFileVersion.V2_1, "1.0": TRCFileVersion.V1_0}
    if version not in versions:
        raise ValueError(f"python-can writes .trc versions {', '.join(versions)}, not {version}")
    p = Path(path)
    writer = can.TRCWriter(str(p))
    writer.file_version = versions[version]
    _feed(writer, frames)
    return p


def _hex_rows(data: np.ndarray, dlc: np.ndarray, sep: str) -> list[str]:
    digits = np.char.upper(np.char.mod("%02x", data))  # (N, W) of 2-character str
    return [sep.join(row[:n]) for row, n in zip(digits.tolist(), dlc.tolist(), strict=True)]


def write_candump(path: str | Path, frames: FrameTable, iface: str = "can") -> Path:
    """A can-utils ``candump -L`` log: ``(s.us) can<bus> ID#DATA`` (FD: ``ID##0DATA``)."""
    p = Path(path)
    data = _hex_rows(frames.data, frames.dlc, "")
    with open(p, "w", encoding="ascii", newline="\n") as f:
        for t, i, e, b, n, d in zip(
            frames.t.tolist(),
            frames.id.tolist(),
            frames.extended.tolist(),
            frames.bus.tolist(),
            frames.dlc.tolist(),
            data,
            strict=True,
        ):
            ident = f"{i:08X}" if e else f"{i:03X}"
            sep = "##0" if n > 8 else "#"
            f.write(f"({t:.6f}) {iface}{b} {ident}{sep}{d}\n")
    return p


def write_gvret_csv(path: str | Path, frames: FrameTable) -> Path:
    """A SavvyCAN GVRET CSV: µs time stamps, hex ids and bytes, LEN fields per row."""
    p = Path(path)
    width = int(frames.dlc.max()) if len(frames) else 8
    head = ",".join(f"D{k}" for k in range(1, max(width, 8) + 1))
    data = _hex_rows(frames.data, frames.dlc, ",")
    with open(p, "w", encoding="ascii", newline="\n") as f:
        f.write(f"Time Stamp,ID,Extended,Bus,LEN,{head}\n")
        for t, i, e, b, n, d in zip(
            np.rint(frames.t * 1e6).astype(np.int64).tolist(),
            frames.id.tolist(),
            frames.extended.tolist(),
            frames.bus.tolist(),
            frames.dlc.tolist(),
            data,
            strict=True,
        ):
            tail = f",{d}" if n else ""
            f.write(f"{t},{i:08X},{'true' if e else 'false'},{b},{n}{tail}\n")
    return p


LEN_TO_DLC = {n: k for k, n in enumerate((0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64))}


def write_mdf_bus_logging(path: str | Path, frames: FrameTable) -> Path:
    """An MDF4 bus-logging file: one ``CAN_DataFrame`` group as the CANedge writes it.

    Channels ``CAN_DataFrame.BusChannel`` (bus + 1), ``.ID``, ``.IDE``, ``.DLC``,
    ``.DataLength``, ``.DataBytes``, ``.Dir``, ``.EDL``, ``.BRS``, ``.ESI`` in one
    structure, master ``Timestamp`` = the frame times (s), CAN bus-event source.
    """
    from asammdf import MDF, Signal
    from asammdf.blocks.source_utils import Source

    p = Path(path)
    n, width = len(frames), frames.data.shape[1]
    dtype = np.dtype(
        [
            ("CAN_DataFrame.BusChannel", "u1"),
            ("CAN_DataFrame.ID", "<u4"),
            ("CAN_DataFrame.IDE", "u1"),
            ("CAN_DataFrame.DLC", "u1"),
            ("CAN_DataFrame.DataLength", "u1"),
            ("CAN_DataFrame.DataBytes", "u1", (width,)),
            ("CAN_DataFrame.Dir", "u1"),
            ("CAN_DataFrame.EDL", "u1"),
            ("CAN_DataFrame.BRS", "u1"),
            ("CAN_DataFrame.ESI", "u1"),
        ]
    )
    rec = np.zeros(n, dtype=dtype)
    rec["CAN_DataFrame.BusChannel"] = frames.bus + 1
    rec["CAN_DataFrame.ID"] = frames.id
    rec["CAN_DataFrame.IDE"] = frames.extended
    lookup = np.array([LEN_TO_DLC.get(k, 15) for k in range(65)], dtype=np.uint8)
    rec["CAN_DataFrame.DLC"] = lookup[frames.dlc]
    rec["CAN_DataFrame.DataLength"] = frames.dlc
    rec["CAN_DataFrame.DataBytes"] = frames.data
    rec["CAN_DataFrame.EDL"] = frames.dlc > 8
    source = Source(
        name="CAN",
        path="CAN",
        comment="",
        source_type=Source.SOURCE_BUS,
        bus_type=Source.BUS_TYPE_CAN,
    )
    signal = Signal(
        samples=rec,
        timestamps=np.asarray(frames.t, dtype=np.float64),
        name="CAN_DataFrame",
        source=source,
    )
    mdf = MDF(version="4.11")
    try:
        mdf.append([signal], acq_name="CAN_DataFrame", acq_source=source, common_timebase=True)
        mdf.save(p, overwrite=True)
    finally:
        mdf.close()
    return p


WRITERS: dict[str, Callable[[str | Path, FrameTable], Path]] = {
    ".blf": write_blf,
    ".asc": write_asc,
    ".trc": write_trc,
    ".log": write_candump,
    ".csv": write_gvret_csv,
    ".mf4": write_mdf_bus_logging,
    ".mdf": write_mdf_bus_logging,
}


def write_frames(path: str | Path, frames: FrameTable) -> Path:
    """Write a frame table; the format follows the suffix (.blf .asc .log .csv .mf4)."""
    suffix = Path(path).suffix.lower()
    if suffix not in WRITERS:
        raise ValueError(f"{path}: no bus-log writer for {suffix!r} (known: {', '.join(WRITERS)})")
    return WRITERS[suffix](path, frames)
