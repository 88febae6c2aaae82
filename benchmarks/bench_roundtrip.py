"""Round trip of the bundled campaign through every format parknss reads.

    python benchmarks/bench_roundtrip.py [--data campaigns/default] [--workdir DIR]
        [--fit] [--epochs 200] [--seeds 0,1,2] [--workers 2] [--json]

Each trial of the campaign is written in each format and the folder imported back with
the format's mapping, through the same `import_folder` users call:

* ``csv97``: CSV at a 97 Hz clock with 1 % jitter, time in ms (values linearly
  interpolated onto the jittered times, gear held): resampled back onto 100 Hz;
* ``parquet``, ``mat``, ``mdf4``: parknss's writers (decoded MDF4: one data group);
* ``blf``, ``asc``, ``trc`` (PCAN 2.1), ``candump``, ``gvret``, ``mf4-bus``: CAN frames in
  the layout of
  configs/buses/parknss_bus.dbc at 100 Hz (absolute time stamps), imported with
  configs/buses/parknss_bus.yaml; the DBC's resolutions quantise the values.

Prints, per format, the largest absolute error of every schema channel after re-import
(schema units, over the samples both share) and the write/import wall times. With
``--fit`` it then fits the NSS on CV fold 0 of the original campaign with every seed of
``--seeds`` (the seed-noise band) and, with the first seed, on each distinct re-imported
campaign (formats whose re-import is bit-identical share one fit), at ``--epochs``, and
reports each held-out score beside the band.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from parknss.config import CONFIG_DIR
from parknss.data.canwrite import frames_from_signals, write_frames
from parknss.data.dbc import load_dbc
from parknss.data.io import import_folder, read_campaign, write_campaign, write_trial
from parknss.data.trial import Campaign, Trial
from parknss.signals import DEG_PER_RAD, KMH_PER_MS, REQUIRED_CHANNELS

BUS = CONFIG_DIR / "buses"
EPOCH_S = 1.7e9  # loggers stamp absolute time
GEAR_LABEL = {-1.0: "R", 0.0: "P", 1.0: "D"}
# schema channel -> (message, signal, factor from schema unit to the DBC unit)
LAYOUT = {
    "vx": ("PK_SPEED", "VehSpd", KMH_PER_MS),
    "yaw_rate": ("PK_SPEED", "YawRate", DEG_PER_RAD),
    "ax": ("PK_SPEED", "AccX", 1.0),
    "ay": ("PK_SPEED", "AccY", 1.0),
    "brake_pressure": ("PK_CHASSIS", "BrkPrs", 1.0),
    "steer": ("PK_CHASSIS", "StrWhlAng", 1.0),
    "torque": ("PK_CHASSIS", "MotTrq", 1.0),
    "gear": ("PK_CHASSIS", "GearPos", None),
    "torque_cmd": ("PK_COMMAND", "MotTrqReq", 1.0),
    "decel_cmd": ("PK_COMMAND", "DecelReq", 1.0),
    "steer_cmd": ("PK_COMMAND", "StrWhlAngReq", 1.0),
}
BUS_FORMATS = {"blf": ".blf", "asc": ".asc", "trc": ".trc", "candump": ".log", "gvret": ".csv",
               "mf4-bus": ".mf4"}


def write_csv97(tr: Trial, path: Path, rng: np.random.Generator) -> None:
    """A 97 Hz logger with 1 % clock jitter, time in ms; linear values, held gear."""
    dt = 1.0 / 97.0
    t = np.arange(int(tr["t"][-1] / dt) + 1) * dt
    t = np.clip(t + rng.uniform(-0.01, 0.01, len(t)) * dt, 0.0, tr["t"][-1])
    t = np.maximum.accumulate(t)
    t[1:] = np.maximum(t[1:], t[:-1] + 1e-6)
    cols = {"t": t * 1000.0}
    for name in REQUIRED_CHANNELS[1:]:
        if name == "gear":
            idx = np.searchsorted(tr["t"], t, side="right") - 1
            cols[name] = tr["gear"][np.clip(idx, 0, tr.n - 1)]
        else:
            cols[name] = np.interp(t, tr["t"], tr[name])
    lines = [",".join(cols)]
    rows = np.column_stack(list(cols.values()))
    lines += [",".join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")


def write_bus(tr: Trial, path: Path, db) -> None:
    """The trial's channels as CAN frames of the parknss bus layout at 100 Hz."""
    t = tr["t"] + EPOCH_S
    schedule: dict[str, dict] = {}
    for name, (msg, sig, factor) in LAYOUT.items():
        if factor is None:
            values = np.array([GEAR_LABEL[g] for g in tr[name]], dtype=object)
        else:
            values = tr[name] * factor
        schedule.setdefault(msg, {})[sig] = (t, values)
    write_frames(path, frames_from_signals(db, schedule))


def export(camp: Campaign, fmt: str, folder: Path, db) -> Path | None:
    """Write every trial in ``fmt``; returns the mapping to import them with (or None)."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    mapping = None
    for tr in camp:
        if fmt == "csv97":
            write_csv97(tr, folder / f"{tr.id}.csv", rng)
            mapping = folder.parent / f"{fmt}.yaml"
            mapping.write_text("time: {column: t, unit: ms}\n")
        elif fmt in ("parquet", "mat"):
            write_trial(tr, folder / f"{tr.id}.{fmt}")
        elif fmt == "mdf4":
            write_trial(tr, folder / f"{tr.id}.mf4")
        else:
            write_bus(tr, folder / f"{tr.id}{BUS_FORMATS[fmt]}", db)
            mapping = BUS / "parknss_bus.yaml"
    return mapping


def errors(orig: Campaign, back: Campaign) -> tuple[dict, dict, int, int]:
    """Over the samples both share: largest and RMS |error| per schema channel (schema
    units), gear samples that differ, and samples lost at the trials' ends."""
    worst = dict.fromkeys(REQUIRED_CHANNELS[1:], 0.0)
    sq = dict.fromkeys(REQUIRED_CHANNELS[1:], 0.0)
    n_all, lost, gear_diff = 0, 0, 0
    for a in orig:
        b = back[a.id]
        ka = np.round(a["t"] * 100).astype(np.int64)
        kb = np.round(b["t"] * 100).astype(np.int64)
        if b["t"][0] == 0.0 and a["t"][0] != 0.0:
            kb = kb + ka[0]
        common, ia, ib = np.intersect1d(ka, kb, return_indices=True)
        lost += a.n - len(common)
        n_all += len(common)
        for name in worst:
            d = np.abs(a[name][ia] - b[name][ib])
            worst[name] = max(worst[name], float(d.max()))
            sq[name] += float(np.sum(d**2))
        gear_diff += int(np.count_nonzero(a["gear"][ia] != b["gear"][ib]))
    rms = {k: (v / max(n_all, 1)) ** 0.5 for k, v in sq.items()}
    return worst, rms, gear_diff, lost


def roundtrip(data: Path, work: Path, formats: list[str]) -> list[dict]:
    orig = read_campaign(data)
    db = load_dbc(BUS / "parknss_bus.dbc").db
    rows = []
    for fmt in formats:
        folder = work / fmt
        t0 = time.perf_counter()
        mapping = export(orig, fmt, folder, db)
        t1 = time.perf_counter()
        back = import_folder(folder, mapping)
        t2 = time.perf_counter()
        worst, rms, gear_diff, lost = errors(orig, back)
        out = work / f"campaign_{fmt}"
        write_campaign(back, out)
        rows.append(
            {
                "format": fmt,
                "write_s": round(t1 - t0, 2),
                "import_s": round(t2 - t1, 2),
                "samples_lost": lost,
                "max_abs_error": worst,
                "rms_error": rms,
                "gear_samples_differing": gear_diff,
                "data_hash": back.data_hash(),
                "campaign": str(out),
            }
        )
        print(f"{fmt:8s} write {t1 - t0:6.1f} s  import {t2 - t1:6.1f} s  lost {lost}",
              file=sys.stderr)
    return rows


def fit_all(
    data: Path, rows: list[dict], epochs: int, seeds: list[int], workers: int, cache: Path
) -> dict:
    """Fold-0 NSS fits: the original with every seed, each distinct re-import with seeds[0]."""
    from parknss.executor import Job, run_jobs

    fn = "parknss.experiments.folds:fold_job"

    original = read_campaign(data).data_hash()
    distinct: dict[str, list[str]] = {}
    for r in rows:
        if r["data_hash"] != original:  # a bit-identical re-import fits identically
            distinct.setdefault(r["data_hash"], []).append(r["format"])
    jobs = [
        Job(fn, {"split": "cv", "index": 0, "data": str(data),
                  "overrides": {"train": {"epochs": epochs, "seed": s}}})
        for s in seeds
    ]
    keys = [f"original seed {s}" for s in seeds]
    for fmts in distinct.values():
        r = next(x for x in rows if x["format"] == fmts[0])
        jobs.append(Job(fn, {"split": "cv", "index": 0, "data": r["campaign"],
                             "overrides": {"train": {"epochs": epochs, "seed": seeds[0]}}}))
        keys.append(",".join(fmts) + f" seed {seeds[0]}")
    results = run_jobs(jobs, workers=workers, cache_dir=cache, desc="fold fits")
    out = {}
    for key, res in zip(keys, results, strict=True):
        e = res["errors"]
        out[key] = {k: e[k] for k in ("vx_mse_moving_kmh2", "yaw_mse_moving_degs2")}
    band = {
        k: (float(np.mean([out[f"original seed {s}"][k] for s in seeds])),
            float(np.std([out[f"original seed {s}"][k] for s in seeds])))
        for k in ("vx_mse_moving_kmh2", "yaw_mse_moving_degs2")
    }
    identical = [r["format"] for r in rows if r["data_hash"] == original]
    return {"epochs": epochs, "seeds": seeds, "scores": out, "original_mean_std": band,
            "bit_identical_to_original": identical}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path("campaigns/default"))
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/parknss_roundtrip"))
    ap.add_argument("--formats", default="csv97,parquet,mat,mdf4," + ",".join(BUS_FORMATS))
    ap.add_argument("--fit", action="store_true")
    ap.add_argument("--epochs", type=int, default=200)
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=Path("runs/roundtrip_cache"),
                    help="result cache of the fits (an interrupted run resumes)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.workdir.exists():
        shutil.rmtree(args.workdir)
    rows = roundtrip(args.data, args.workdir, args.formats.split(","))
    doc: dict = {"roundtrip": rows}
    names = REQUIRED_CHANNELS[1:]
    print("largest |error| per channel (schema units; gear: samples differing); "
          "RMS below each row")
    print("format    " + " ".join(f"{n[:10]:>10s}" for n in names) + "  lost  import s")
    for r in rows:
        errs = " ".join(
            f"{r['gear_samples_differing']:10d}" if n == "gear" else
            f"{r['max_abs_error'][n]:10.2e}" for n in names
        )
        rms = " ".join(" " * 10 if n == "gear" else f"{r['rms_error'][n]:10.2e}" for n in names)
        print(f"{r['format']:9s} {errs} {r['samples_lost']:5d} {r['import_s']:8.1f}")
        print(f"{'  rms':9s} {rms}")
    if args.fit:
        seeds = [int(s) for s in args.seeds.split(",")]
        doc["fit"] = fit_all(args.data, rows, args.epochs, seeds, args.workers, args.cache)
        for key, sc in doc["fit"]["scores"].items():
            print(f"{key:60s} vx {sc['vx_mse_moving_kmh2']:.4f} (km/h)^2  "
                  f"yaw {sc['yaw_mse_moving_degs2']:.4f} (deg/s)^2")
        for k, (mu, sd) in doc["fit"]["original_mean_std"].items():
            print(f"original over seeds: {k} {mu:.4f} +- {sd:.4f}")
    if args.json:
        print(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
