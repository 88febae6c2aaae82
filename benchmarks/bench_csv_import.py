"""Benchmark: peak memory of importing a very long table CSV (10 million rows).

    python benchmarks/bench_csv_import.py [--rows 10000000] [--workdir /tmp/parknss_bench_csv]
                                          [--json]

Generates (once; cached under ``--workdir``) a CSV log of ``--rows`` samples at 100 Hz
with every schema channel (smooth signals in schema units, Arrow's shortest number
format), then reads it with :func:`parknss.data.io.read_trial` in a fresh process under
``/usr/bin/time -v`` and reports the file size, the wall time and the peak resident
memory ("Maximum resident set size", interpreter and libraries included). The CSV is
parsed by Arrow block by block (:mod:`parknss.data.csvlog`), so memory holds the float64
columns, never the text. Target (issue 43): 10 M rows with peak memory under 2 GB.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

CHUNK = 1_000_000


def make_csv(path: Path, rows: int) -> Path:
    """The benchmark log (written in chunks of CHUNK rows through Arrow)."""
    import pyarrow as pa
    import pyarrow.csv as pc

    from parknss.signals import REQUIRED_CHANNELS

    tmp = path.with_suffix(".tmp")
    with pc.CSVWriter(tmp, pa.schema([(c, pa.float64()) for c in REQUIRED_CHANNELS])) as w:
        for start in range(0, rows, CHUNK):
            k = np.arange(start, min(rows, start + CHUNK))
            t = k / 100.0
            cols = {c: np.zeros(len(k)) for c in REQUIRED_CHANNELS}
            cols["t"] = t
            cols["gear"] = np.where(np.sin(t / 30) > 0, 1.0, -1.0)
            cols["vx"] = np.round(cols["gear"] * (1 + np.abs(np.sin(t / 7))), 4)
            cols["steer"] = np.round(300 * np.sin(t / 11), 2)
            cols["yaw_rate"] = np.round(0.3 * np.sin(t / 5), 5)
            cols["torque"] = np.round(100 * np.sin(t / 3), 1)
            cols["brake_pressure"] = np.round(5 + 5 * np.sin(t / 13), 2)
            cols["ax"] = np.round(np.sin(t / 2), 4)
            cols["ay"] = np.round(np.cos(t / 2), 4)
            w.write_table(pa.table(cols))
    tmp.replace(path)
    return path


_READ = (
    "import sys, time; from parknss.data.io import read_trial; t0 = time.perf_counter(); "
    "tr = read_trial(sys.argv[1]); print(tr.n, time.perf_counter() - t0)"
)


def measure(path: Path) -> dict:
    """read_trial in a fresh process under /usr/bin/time -v: samples, wall s, peak MB."""
    proc = subprocess.run(
        ["/usr/bin/time", "-v", sys.executable, "-c", _READ, str(path)],
        capture_output=True, text=True, check=False,
    )
    if proc.returncode != 0:
        raise SystemExit(f"import failed: {proc.stderr.strip().splitlines()[-1]}")
    n, wall = proc.stdout.split()
    peak_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)[1])
    return {"samples": int(n), "read_s": round(float(wall), 1), "peak_mb": round(peak_kb / 1024)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=10_000_000)
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/parknss_bench_csv"))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    args.workdir.mkdir(parents=True, exist_ok=True)
    path = args.workdir / f"long_{args.rows}.csv"
    t0 = time.perf_counter()
    if not path.exists():
        make_csv(path, args.rows)
    made = time.perf_counter() - t0
    out = {"rows": args.rows, "file_mb": round(path.stat().st_size / 1e6), **measure(path),
           "generate_s": round(made, 1)}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{out['rows']} rows, {out['file_mb']} MB CSV: read_trial {out['read_s']} s, "
              f"peak memory {out['peak_mb']} MB (/usr/bin/time -v, max RSS)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
