"""CAN bus logs with a DBC: frames read column-wise, signals decoded vectorised.

The mapping names the DBC (``can.dbc``) and, per schema channel, the ``message`` and
``signal`` that carry it. :func:`read_can_series` reads the frames of those messages
(:mod:`parknss.data.canframes`: .blf, .asc, candump .log, SavvyCAN GVRET .csv, MDF4 bus
logging; error and remote frames skipped), keeps one bus (``can.bus_channel``) or one
bus per message (``can.duplicate_buses: first``: frames a gateway forwards onto several
buses are kept once), decodes each requested signal for all its frames at once
(:func:`parknss.data.dbc.decode_signal`: value tables as labels, multiplexed signals
only from the frames that carry them, frames too short for a signal skipped and
counted) and returns one :class:`~parknss.data.resample.Series` per request, with time
counted from the log's first frame (any bus, any id). Every problem is a one-line
DataError naming the file and the channel.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from parknss.data.canframes import (
    KINDS,
    FrameTable,
    buses_by_key,
    drop_duplicate_buses,
    frame_key,
    keep_bus,
    read_frames,
)
from parknss.data.dbc import LoadedDbc, bytes_needed, decode_signal, load_dbc, similar_hint
from parknss.data.mapping import CanOptions
from parknss.data.resample import Series
from parknss.errors import DataError

# CAN by suffix alone (also: .log, see canframes)
CAN_SUFFIXES: tuple[str, ...] = (".blf", ".asc", ".trc")


@dataclass(frozen=True)
class CanRequest:
    """One signal to decode for a schema channel.

    Attributes:
        key: unique raw key of the series, e.g. ``vx#0``.
        channel: the schema channel it feeds.
        message: message name in the DBC.
        signal: signal name in that message.
        label: how messages name it, e.g. ``channel 'vx' (message 'ESP', signal 'VehSpd')``.
    """

    key: str
    channel: str
    message: str
    signal: str
    label: str


@dataclass(frozen=True)
class _Resolved:
    request: CanRequest
    message: Any  # cantools Message
    signal: Any  # cantools Signal

    @property
    def frame_key(self) -> int:
        return frame_key(self.message.frame_id, self.message.is_extended_frame)


def _dbc(path: Path, can: CanOptions) -> LoadedDbc:
    if can.dbc is None:
        raise DataError(f"{path}: a CAN log needs a DBC: set can.dbc in the mapping")
    dbc = Path(can.dbc)
    if not dbc.is_file():
        raise DataError(f"{path}: DBC file {dbc} not found (can.dbc in the mapping)")
    try:
        return load_dbc(dbc, strict=can.strict_dbc)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from None


def _resolve(dbc: LoadedDbc, r: CanRequest, path: Path) -> _Resolved:
    """The request's message and signal in the DBC; DataError with close names if absent."""
    name = dbc.path.name
    try:
        msg = dbc.message(r.message)
    except KeyError:
        hint = similar_hint(r.message, dbc.message_names())
        raise DataError(f"{path}: {r.label}: message not in the DBC {name}{hint}") from None
    try:
        sig = msg.get_signal_by_name(r.signal)
    except KeyError:
        hint = similar_hint(r.signal, [s.name for s in msg.signals])
        raise DataError(
            f"{path}: {r.label}: signal not in message {r.message!r} of the DBC {name}{hint}"
        ) from None
    return _Resolved(r, msg, sig)


def _select_buses(
    frames: FrameTable, resolved: list[_Resolved], can: CanOptions, path: Path
) -> tuple[FrameTable, dict]:
    """Apply can.bus_channel and can.duplicate_buses; (frames kept, provenance entries)."""
    seen = buses_by_key(frames)
    names = {r.frame_key: r.message.name for r in resolved}
    for r in resolved:
        if r.frame_key not in seen:
            raise DataError(
                f"{path}: {r.request.label}: no frames of the message "
                f"(id 0x{r.message.frame_id:X}) in the log"
            )
        if can.bus_channel is not None and can.bus_channel not in seen[r.frame_key]:
            on = ", ".join(str(b) for b in sorted(seen[r.frame_key]))
            raise DataError(
                f"{path}: {r.request.label}: no frames of the message "
                f"(id 0x{r.message.frame_id:X}) on bus {can.bus_channel} (can.bus_channel); "
                f"the log has it on bus {on}"
            )
    prov: dict[str, Any] = {}
    if can.bus_channel is not None:
        frames = keep_bus(frames, can.bus_channel)
        dropped = {names[k]: sum(c.values()) - c.get(can.bus_channel, 0) for k, c in seen.items()}
        prov["frames_of_other_buses_dropped"] = {k: n for k, n in dropped.items() if n}
        kept = {names[k]: can.bus_channel for k in seen}
    elif can.duplicate_buses == "first":
        frames, choices = drop_duplicate_buses(frames)
        kept = {names[k]: next(iter(c)) for k, c in seen.items()}
        kept |= {names[c.key]: c.kept for c in choices}
        prov["duplicates_dropped"] = {names[c.key]: c.dropped for c in choices}
    else:
        kept = {names[k]: sorted(c) if len(c) > 1 else next(iter(c)) for k, c in seen.items()}
    prov["bus_kept"] = kept
    return frames, prov


def _check_time(s: Series, name: str, buses: dict[int, int], path: Path) -> None:
    """Time stamps never go backwards; naming the fix when several buses are mixed."""
    dt = np.diff(s.t)
    back = np.flatnonzero(dt < 0.0)
    if not len(back):
        return
    k = int(back[0])
    hint = ""
    if len(buses) > 1:
        hint = (
            f"; message {name!r} arrives on buses {' and '.join(map(str, sorted(buses)))}: "
            "set can.bus_channel or can.duplicate_buses: first"
        )
    raise DataError(
        f"{path}: {s.label}: non-monotonic time stamps, {len(back)} steps backwards (first "
        f"from t={s.t[k]:.6f} s to t={s.t[k + 1]:.6f} s){hint}"
    )


def _series(r: _Resolved, frames: FrameTable, t0: float, path: Path) -> tuple[Series, int]:
    """The request's signal from its message's frames: (Series, frames too short)."""
    dec = decode_signal(r.message, r.signal, frames.data, frames.dlc)
    if not dec.mask.any():
        why = (
            f"{dec.n_short} of {len(frames)} frames are shorter than the "
            f"{bytes_needed(r.signal)} bytes it needs"
            if dec.n_short
            else f"the multiplexer {r.signal.multiplexer_signal!r} never selects it in "
            f"{len(frames)} frames"
        )
        raise DataError(f"{path}: {r.request.label}: no frame carries the signal ({why})")
    rows = np.flatnonzero(dec.mask)
    return (
        Series(
            r.request.channel,
            r.request.key,
            r.request.label,
            frames.t[rows] - t0,
            dec.values[rows],
            hold=True,
            unit=r.signal.unit or "",
            event=bool(r.signal.choices),  # enumerations are often sent on change only
        ),
        dec.n_short,
    )


def read_can_series(
    path: Path, requests: list[CanRequest], can: CanOptions
) -> tuple[list[Series], dict]:
    """Decode the requested signals of one CAN bus log.

    Args:
        path: a .blf, .asc, candump .log, GVRET .csv or MDF4 bus-logging file.
        requests: the signals to decode (unique keys).
        can: the mapping's CAN options (dbc, bus_channel, strict_dbc, duplicate_buses).

    Returns:
        (one Series per request, in order: t in s from the log's first frame (float64
        (N,)), values in the DBC unit (float64, or str labels for value-table signals),
        hold=True, unit = the DBC unit or '', event = the signal has a value table;
        provenance: format, dbc, dbc_warnings, log_t0_s (the first frame's time stamp on
        the logger's clock),
        frames_read, frames_skipped (error/remote), frames_mapped, bus_kept per message,
        duplicates_dropped (or frames_of_other_buses_dropped), short_frames per key).

    Raises:
        DataError: one line naming the file and the channel (or the DBC).
    """
    keys = [r.key for r in requests]
    if len(set(keys)) != len(keys):
        raise ValueError(f"request keys must be unique: {keys}")
    dbc = _dbc(path, can)
    resolved = [_resolve(dbc, r, path) for r in requests]
    wanted = {(int(r.message.frame_id), bool(r.message.is_extended_frame)) for r in resolved}
    frames = read_frames(path, wanted)  # the reader by content, else by suffix
    t0 = frames.t_first
    frames, bus_prov = _select_buses(frames, resolved, can, path)
    seen = buses_by_key(frames)
    keys_of = frames.keys()
    order = np.argsort(keys_of, kind="stable")  # rows of each message, in file order
    uniq, first = np.unique(keys_of[order], return_index=True)
    bounds = dict(
        zip(uniq.tolist(), zip(first, [*first[1:], len(order)], strict=True), strict=True)
    )
    by_message: dict[int, FrameTable] = {}
    series, short = [], {}
    for r in resolved:
        if r.frame_key not in by_message:
            lo, hi = bounds[r.frame_key]
            by_message[r.frame_key] = frames.take(order[lo:hi])
        s, n_short = _series(r, by_message[r.frame_key], t0, path)
        _check_time(s, r.message.name, seen[r.frame_key], path)
        series.append(s)
        if n_short:
            short[r.request.key] = n_short
    provenance = {
        "format": frames.kind,
        "format_name": KINDS[frames.kind],
        "dbc": str(dbc.path),
        "dbc_warnings": list(dbc.warnings),
        "log_t0_s": t0,
        "frames_read": frames.n_frames,
        "frames_skipped": frames.n_skipped,
        "frames_mapped": int(sum(len(f) for f in by_message.values())),
        **bus_prov,
        "short_frames": short,
    }
    return series, provenance
