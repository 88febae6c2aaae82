"""Benchmark: import one hour of a 2000 frames/s CAN bus log (.blf and MDF4 bus logging).

    python benchmarks/bench_import.py [--minutes 60] [--workdir /tmp/parknss_bench_import]
                                      [--formats blf,mf4] [--paths series,trial] [--json]

Generates (once; cached under ``--workdir``) a bus log of ``--minutes`` at 2000
frames/s: 12 DBC messages carrying the parknss channels at 10-100 Hz (860 frames/s,
Intel and Motorola, signed, a value table, an extended id, a multiplexed message) and
38 filler ids at 30 Hz that no mapping asks for (1140 frames/s, random payloads), then
writes it as .blf (python-can) and as an MDF4 bus-logging file (CAN_DataFrame, as the
CANedge writes it); ``--formats`` may add asc, log (candump) and csv (GVRET), whose
writers are slow (about 100 k frames/s). Each import runs in a fresh subprocess, which
reports its wall time and peak memory (VmHWM, including the interpreter and libraries):

* ``series``: :func:`parknss.data.canlog.read_can_series` (frames read, buses
  de-duplicated, the 11 mapped signals decoded);
* ``trial``: :func:`parknss.data.io.read_trial` end to end (decode, 100 Hz grid, units,
  validation); reported as failed (with its one-line error) if it fails.

Prints per format and path: frames in the file, wall s, frames/s, peak MB. Target: an
hour of each format in under 2 minutes with peak memory under 2 GB.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

FRAMES_PER_S = 2000
FILLER_IDS = 38
FILLER_HZ = 30
EPOCH = 1_700_000_000.0  # loggers stamp absolute time
CACHE_VERSION = 1


def _db():
    """The benchmark DBC: 12 messages (860 frames/s), units the mapping converts."""
    from cantools.database.can import Database, Message
    from cantools.database.can import Signal as CanSignal
    from cantools.database.conversion import BaseConversion

    def sig(name, start, scale, unit="", signed=True, length=16, big=False, **kw):
        conv = BaseConversion.factory(scale=scale, offset=0, choices=kw.pop("choices", None))
        order = "big_endian" if big else "little_endian"
        return CanSignal(
            name,
            start,
            length,
            byte_order=order,
            is_signed=signed,
            conversion=conv,
            unit=unit,
            **kw,
        )

    gear = {0: "P", 1: "R", 2: "N", 3: "D"}
    messages = [
        Message(
            0x0A0,
            "WHL",
            8,
            [
                sig(f"WhlSpd{k}", 16 * i, 0.01, "km/h", signed=False)
                for i, k in enumerate(("FL", "FR", "RL", "RR"))
            ],
        ),
        Message(0x100, "ESP", 8, [sig("VehSpd", 0, 0.01, "km/h")]),
        Message(0x101, "YAW", 8, [sig("YawRate", 7, 0.01, "deg/s", big=True)]),
        Message(0x120, "IMU_X", 8, [sig("AccX", 0, 0.001, "m/s^2")]),
        Message(0x121, "IMU_Y", 8, [sig("AccY", 7, 0.001, "m/s^2", big=True)]),
        Message(0x130, "BRK", 8, [sig("BrkPrs", 0, 0.001, "MPa", signed=False)]),
        Message(0x131, "ACC", 8, [sig("DecelReq", 16, 0.001, "m/s^2")]),
        Message(0x18FF0140, "MOT", 8, [sig("MotTrq", 0, 0.1, "Nm")], is_extended_frame=True),
        Message(0x141, "MOT_CMD", 8, [sig("MotTrqReq", 23, 0.1, "Nm", big=True)]),
        Message(0x150, "STR", 8, [sig("StrWhlAng", 7, 0.1, "deg", big=True)]),
        Message(0x151, "STR_CMD", 8, [sig("StrWhlAngReq", 0, 0.1, "deg")]),
        Message(
            0x160,
            "GEAR",
            8,
            [
                sig("Page", 0, 1, signed=False, length=8, is_multiplexer=True),
                sig(
                    "GearPos",
                    8,
                    1,
                    signed=False,
                    length=8,
                    choices=gear,
                    multiplexer_ids=[0],
                    multiplexer_signal="Page",
                ),
                sig(
                    "Odometer",
                    8,
                    1,
                    "km",
                    signed=False,
                    length=32,
                    multiplexer_ids=[1],
                    multiplexer_signal="Page",
                ),
            ],
        ),
    ]
    return Database(messages=messages)


# message: (rate Hz, {signal: f(t) in DBC units})
def _signals() -> dict:
    def gear(t):
        phase = (t // 20).astype(np.int64) % 4
        return np.array(["P", "D", "R", "D"], dtype=object)[phase]

    return {
        "WHL": (
            100,
            {
                f"WhlSpd{k}": (lambda t: 7.2 * np.abs(np.sin(2 * np.pi * t / 120)))
                for k in ("FL", "FR", "RL", "RR")
            },
        ),
        "ESP": (50, {"VehSpd": lambda t: 7.2 * np.sin(2 * np.pi * t / 120)}),
        "YAW": (100, {"YawRate": lambda t: 17.0 * np.sin(2 * np.pi * t / 40)}),
        "IMU_X": (100, {"AccX": lambda t: np.sin(2 * np.pi * t / 30)}),
        "IMU_Y": (100, {"AccY": lambda t: 0.8 * np.cos(2 * np.pi * t / 25)}),
        "BRK": (50, {"BrkPrs": lambda t: 2.0 + 1.5 * np.sin(2 * np.pi * t / 17)}),
        "ACC": (50, {"DecelReq": lambda t: -1.0 - 0.5 * np.sin(2 * np.pi * t / 13)}),
        "MOT": (100, {"MotTrq": lambda t: 100 + 80 * np.sin(2 * np.pi * t / 11)}),
        "MOT_CMD": (50, {"MotTrqReq": lambda t: 100 + 80 * np.sin(2 * np.pi * t / 11 + 0.1)}),
        "STR": (100, {"StrWhlAng": lambda t: 300 * np.sin(2 * np.pi * t / 23)}),
        "STR_CMD": (50, {"StrWhlAngReq": lambda t: 300 * np.sin(2 * np.pi * t / 23 + 0.05)}),
        "GEAR": (
            10,
            {
                "Page": lambda t: (np.arange(len(t)) % 8 == 7).astype(float),
                "GearPos": gear,
                "Odometer": lambda t: 1234 + t / 3600,
            },
        ),
    }


MAPPING = {
    "vx": ("ESP", "VehSpd", "km/h"),
    "yaw_rate": ("YAW", "YawRate", None),
    "ax": ("IMU_X", "AccX", None),
    "ay": ("IMU_Y", "AccY", None),
    "brake_pressure": ("BRK", "BrkPrs", None),
    "decel_cmd": ("ACC", "DecelReq", None),
    "torque": ("MOT", "MotTrq", None),
    "torque_cmd": ("MOT_CMD", "MotTrqReq", None),
    "steer": ("STR", "StrWhlAng", None),
    "steer_cmd": ("STR_CMD", "StrWhlAngReq", None),
    "gear": ("GEAR", "GearPos", None),
}


SUFFIX = {"blf": ".blf", "mf4": ".mf4", "asc": ".asc", "log": ".log", "csv": ".csv"}


def _frames(db, minutes: float):
    """The whole log as one FrameTable, time sorted, absolute time stamps."""
    from dataclasses import replace

    from parknss.data.canframes import FrameTable
    from parknss.data.canwrite import merge_frames, message_frames

    duration = minutes * 60.0
    rng = np.random.default_rng(7)
    tables = []
    for name, (rate, fns) in _signals().items():
        t = np.arange(0.0, duration, 1.0 / rate) + rng.uniform(0, 1.0 / rate)
        values = {s: f(t) for s, f in fns.items()}
        tables.append(message_frames(db.get_message_by_name(name), t, values))
    for k in range(FILLER_IDS):
        t = np.arange(0.0, duration, 1.0 / FILLER_HZ) + rng.uniform(0, 1.0 / FILLER_HZ)
        n = len(t)
        tables.append(
            FrameTable(
                t=t,
                id=np.full(n, 0x300 + k, np.uint32),
                extended=np.zeros(n, bool),
                bus=np.zeros(n, np.int16),
                dlc=np.full(n, 8, np.uint8),
                data=rng.integers(0, 256, (n, 8), dtype=np.uint8),
            )
        )
    frames = merge_frames(tables)
    return replace(frames, t=frames.t + EPOCH, t_first=frames.t_first + EPOCH)


def generate(workdir: Path, minutes: float, formats: list[str]) -> dict[str, Path]:
    """The DBC, the mapping and the logs in ``formats``; files already made are reused."""
    import yaml

    from parknss.data.canwrite import write_frames

    workdir.mkdir(parents=True, exist_ok=True)
    stamp = workdir / "stamp.json"
    want = {"minutes": minutes, "version": CACHE_VERSION}
    if not stamp.is_file() or json.loads(stamp.read_text()) != want:
        for old in workdir.iterdir():
            old.unlink()
    files = {"dbc": workdir / "bench.dbc", "mapping": workdir / "mapping.yaml"}
    files |= {f: workdir / f"park_in_left_r1{SUFFIX[f]}" for f in formats}
    db = _db()
    files["dbc"].write_text(db.as_dbc_string())
    channels = {}
    for ch, (msg, sig, unit) in MAPPING.items():
        channels[ch] = {"message": msg, "signal": sig} | ({"unit": unit} if unit else {})
    doc = {
        "can": {"dbc": files["dbc"].name},
        "channels": channels,
        "gear_values": {"P": 0, "R": -1, "N": 0, "D": 1},
        "vehicle": {"id": "bench"},
    }
    files["mapping"].write_text(yaml.safe_dump(doc, sort_keys=False))
    frames = None
    for f in formats:
        if files[f].is_file():
            continue
        frames = _frames(db, minutes) if frames is None else frames
        t0 = time.perf_counter()
        write_frames(files[f], frames)
        print(
            f"wrote {files[f]} ({len(frames)} frames) in {time.perf_counter() - t0:.1f} s",
            file=sys.stderr,
        )
    stamp.write_text(json.dumps(want))
    return files


def peak_mb() -> float:
    """This process's peak resident memory, MB (VmHWM: reset by exec, unlike ru_maxrss,
    which a child inherits from the parent that spawned it)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _child(path: str, mapping: str, how: str) -> dict:
    """One import in this (fresh) process: wall s, frames, peak RSS MB."""
    from parknss.data.mapping import load_mapping

    m = load_mapping(mapping)
    if not Path(str(m.can.dbc)).is_absolute():
        m = m.model_copy(
            update={"can": m.can.model_copy(update={"dbc": str(Path(mapping).parent / m.can.dbc)})}
        )
    base_mb = peak_mb()
    t0 = time.perf_counter()
    out: dict = {"how": how}
    try:
        if how == "series":
            from parknss.data.canlog import CanRequest, read_can_series

            requests = [
                CanRequest(f"{ch}#0", ch, src.message, src.signal, f"channel {ch!r}")
                for ch, src in _can_sources(m)
            ]
            series, prov = read_can_series(Path(path), requests, m.can)
            out["frames"] = prov["frames_read"]
            out["samples"] = int(sum(len(s.t) for s in series))
        else:
            from parknss.data.io import read_trial

            trial = read_trial(path, mapping)
            out["samples"] = len(trial["t"])  # on the 100 Hz grid
        out["ok"] = True
    except Exception as exc:  # reported, not raised: the benchmark goes on
        out["ok"] = False
        out["error"] = f"{exc.__class__.__name__}: {' '.join(str(exc).split())}"[:400]
    out["wall_s"] = time.perf_counter() - t0
    out["peak_mb"] = peak_mb()
    out["baseline_mb"] = base_mb
    return out


def _can_sources(m):
    """(channel, source with message and signal) of a mapping, old or new layout."""
    for ch, src in m.channels.items():
        refs = getattr(src, "sources", None) or [src]
        for ref in refs:
            if getattr(ref, "message", None):
                yield ch, ref
                break


def run(path: Path, mapping: Path, how: str) -> dict:
    cmd = [sys.executable, __file__, "--child", str(path), str(mapping), how]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if res.returncode != 0:
        return {"how": how, "ok": False, "error": res.stderr.strip().splitlines()[-1:]}
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/parknss_bench_import"))
    ap.add_argument("--formats", default="blf,mf4", help="of blf,mf4,asc,log,csv")
    ap.add_argument("--paths", default="series,trial")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--child", nargs=3, metavar=("LOG", "MAPPING", "HOW"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(_child(*args.child)))
        return 0
    formats = args.formats.split(",")
    files = generate(args.workdir / f"{args.minutes:g}min", args.minutes, formats)
    n_frames = round(args.minutes * 60 * FRAMES_PER_S)
    rows = []
    for fmt in formats:
        for how in args.paths.split(","):
            r = run(files[fmt], files["mapping"], how) | {"format": fmt}
            r["file_mb"] = files[fmt].stat().st_size / 2**20
            if r.get("ok"):
                r["frames_per_s"] = n_frames / r["wall_s"]
            rows.append(r)
            if not args.json:
                if r.get("ok"):
                    print(
                        f"{fmt:4s} {how:6s} {n_frames} frames ({r['file_mb']:.0f} MB file): "
                        f"{r['wall_s']:.1f} s, {r['frames_per_s'] / 1e3:.0f} k frames/s, "
                        f"{r['samples']} samples out, "
                        f"peak {r['peak_mb']:.0f} MB (interpreter + libraries "
                        f"{r['baseline_mb']:.0f} MB)"
                    )
                else:
                    print(f"{fmt:4s} {how:6s} FAILED: {r.get('error')}")
    if args.json:
        print(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
