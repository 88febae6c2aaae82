"""Start-up of the command line: whole-process times of light commands, in one run.

    python benchmarks/bench_startup.py [--repeats 5] [--json]

Runs, interleaved ``--repeats`` times each as a fresh process: the bare interpreter
(``python -c pass``), ``parknss --help``, ``parknss plan --help``, importing the ISO/TS
18571 module, and ``parknss plan --scene 26 --json`` (planning, refinement and the figure
into a temporary folder); and, inside this process, the planning of cell 26 alone
(``plan_named_scene``, imports already paid). Prints the median and range of each wall
time and the ratios the start-up goals are about: each command against the bare
interpreter, and the whole ``plan`` process against its planning. The machine's load is
printed with them: on a shared machine every absolute time is inflated, ratios less so.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PY = sys.executable
CASES: dict[str, list[str]] = {
    "python -c pass": [PY, "-c", "pass"],
    "parknss --help": [PY, "-m", "parknss.cli", "--help"],
    "parknss plan --help": [PY, "-m", "parknss.cli", "plan", "--help"],
    "import parknss.metrics.iso18571": [PY, "-c", "import parknss.metrics.iso18571"],
}
PLAN = "parknss plan --scene 26 --json"


def _wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _planning_s() -> float:
    """Planning cell 26 in this process (imports and the first solve warmed up)."""
    from parknss.sim.closed_loop import SimConfigFiles
    from parknss.sim.planner import plan_named_scene

    files = SimConfigFiles()
    plan_named_scene("26", files)
    t0 = time.perf_counter()
    plan_named_scene("26", files)
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    times: dict[str, list[float]] = {k: [] for k in [*CASES, PLAN]}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for name, cmd in CASES.items():
                times[name].append(_wall(cmd))
            out = Path(tmp) / f"plan{r}"
            times[PLAN].append(_wall([PY, "-m", "parknss.cli", "plan", "--scene", "26",
                                      "--json", "--out", str(out)]))
    planning = [_planning_s() for _ in range(max(1, args.repeats // 2))]
    load1 = os.getloadavg()[0]
    med = {k: float(np.median(v)) for k, v in times.items()}
    plan_alone = float(np.median(planning))
    doc = {
        "repeats": args.repeats, "load_average": [load0, load1], "cores": os.cpu_count(),
        "median_s": med, "range_s": {k: [min(v), max(v)] for k, v in times.items()},
        "planning_in_process_s": plan_alone,
        "ratio_to_bare_python": {k: v / med["python -c pass"] for k, v in med.items()},
        "plan_process_over_planning": med[PLAN] / plan_alone,
    }
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"one run, median [range] of {args.repeats} fresh processes each; load average "
          f"{load0:.1f} -> {load1:.1f} on {os.cpu_count()} cores")
    for k, v in times.items():
        print(f"  {k:34s} {med[k]:6.3f} s [{min(v):.3f}-{max(v):.3f}]  "
              f"{doc['ratio_to_bare_python'][k]:6.1f}x bare python")
    print(f"  planning cell 26 in process        {plan_alone:6.3f} s; the whole plan process "
          f"is {doc['plan_process_over_planning']:.2f}x its planning")
    return 0


if __name__ == "__main__":
    sys.exit(main())
