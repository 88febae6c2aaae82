"""Start-up of the command line: whole-process times of light commands, in one run.

    python benchmarks/bench_startup.py [--repeats 5] [--json] [--baseline ../main/src]
        [--no-bytecode-cache]

Runs, interleaved ``--repeats`` times each as a fresh process: the bare interpreter
(``python -c pass``), ``parknss --help``, ``parknss plan --help``, importing the ISO/TS
18571 module, and ``parknss plan --scene 26 --json`` (planning, refinement and the SVG
figure into a temporary folder; and again with ``--no-figure``); and, inside this process, the
planning of cell 26 alone (``plan_named_scene``, imports already paid). Prints the median
and range of each wall time and the ratios the start-up goals are about: each command
against the bare interpreter, and the whole ``plan`` process against its planning, and
each process's CPU time (user + system; on a loaded machine steadier than the wall time).
``--baseline SRC`` also runs ``--help`` and ``plan`` from another checkout's ``src``
(main's), interleaved, and prints baseline / this. The machine's load is printed with
them: on a shared machine every absolute time is inflated, ratios less so.

Bytecode: an installed package runs from cached bytecode (.pyc), but a checkout run with
``PYTHONDONTWRITEBYTECODE`` set (as here) compiles every parknss module from source in
every process (about 0.05-0.1 CPU s of ``plan`` here). So the processes run with a cache
in the temporary folder (``PYTHONPYCACHEPREFIX``, warmed by one untimed run of each
command), as a user's would; ``--no-bytecode-cache`` runs them in the environment as
given.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
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
BARE = "parknss plan --scene 26 --json --no-figure"


def _wall(cmd: list[str], cpu: list[float] | None = None, env: dict | None = None) -> float:
    """Wall time (s) of one fresh process; its CPU time (user + system, s) appended to
    ``cpu``: on a loaded machine the CPU time is the steadier of the two."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env=env)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if cpu is not None:
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return wall


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
    ap.add_argument("--baseline", metavar="SRC", help="another checkout's src/ (e.g. main's): "
                    "its --help and plan runs interleaved with these, as ratios")
    ap.add_argument("--no-bytecode-cache", action="store_true",
                    help="run the processes in the environment as given (with "
                    "PYTHONDONTWRITEBYTECODE set, parknss compiles from source every time)")
    args = ap.parse_args()
    names = [*CASES, PLAN, BARE]
    if args.baseline:
        names += [f"{k} [baseline]" for k in ("parknss --help", PLAN)]
    times: dict[str, list[float]] = {k: [] for k in names}
    cpus: dict[str, list[float]] = {k: [] for k in times}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        env0 = dict(os.environ)
        if not args.no_bytecode_cache:
            env0.pop("PYTHONDONTWRITEBYTECODE", None)
            env0["PYTHONPYCACHEPREFIX"] = str(Path(tmp) / "pycache")
        plan = [PY, "-m", "parknss.cli", "plan", "--scene", "26", "--json", "--out"]
        if not args.no_bytecode_cache:  # warm the cache: one untimed run of each
            for src in [None, args.baseline] if args.baseline else [None]:
                env = env0 if src is None else {**env0, "PYTHONPATH": src}
                for cmd in [*CASES.values(), [*plan, str(Path(tmp) / "warm"), "--overwrite"]]:
                    _wall(cmd, None, env)
        for r in range(args.repeats):
            for name, cmd in CASES.items():
                times[name].append(_wall(cmd, cpus[name], env0))
            times[PLAN].append(_wall([*plan, str(Path(tmp) / f"plan{r}")], cpus[PLAN], env0))
            times[BARE].append(_wall([*plan, str(Path(tmp) / f"bare{r}"), "--no-figure"],
                                     cpus[BARE], env0))
            if args.baseline:
                env = {**env0, "PYTHONPATH": args.baseline}
                for name, cmd in (("parknss --help", CASES["parknss --help"]),
                                  (PLAN, [*plan, str(Path(tmp) / f"base{r}")])):
                    key = f"{name} [baseline]"
                    times[key].append(_wall(cmd, cpus[key], env))
    planning = [_planning_s() for _ in range(max(1, args.repeats // 2))]
    load1 = os.getloadavg()[0]
    med = {k: float(np.median(v)) for k, v in times.items()}
    plan_alone = float(np.median(planning))
    doc = {
        "repeats": args.repeats, "load_average": [load0, load1], "cores": os.cpu_count(),
        "bytecode_cache": not args.no_bytecode_cache,
        "median_s": med, "median_cpu_s": {k: float(np.median(v)) for k, v in cpus.items()},
        "range_s": {k: [min(v), max(v)] for k, v in times.items()},
        "planning_in_process_s": plan_alone,
        "ratio_to_bare_python": {k: v / med["python -c pass"] for k, v in med.items()},
        "plan_process_over_planning": med[PLAN] / plan_alone,
    }
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"one run, median [range] of {args.repeats} fresh processes each; load average "
          f"{load0:.1f} -> {load1:.1f} on {os.cpu_count()} cores; bytecode "
          f"{'cached' if doc['bytecode_cache'] else 'as the environment has it'}")
    for k, v in times.items():
        print(f"  {k:34s} {med[k]:6.3f} s [{min(v):.3f}-{max(v):.3f}]  "
              f"{doc['ratio_to_bare_python'][k]:6.1f}x bare python; CPU "
              f"{doc['median_cpu_s'][k]:6.3f} s")
    for name in ("parknss --help", PLAN):
        if f"{name} [baseline]" in med:
            b = f"{name} [baseline]"
            print(f"  {name}: baseline / this {med[b] / med[name]:.2f}x wall, "
                  f"{doc['median_cpu_s'][b] / doc['median_cpu_s'][name]:.2f}x CPU")
    print(f"  planning cell 26 in process        {plan_alone:6.3f} s; the whole plan process "
          f"is {doc['plan_process_over_planning']:.2f}x its planning")
    cpu = doc["median_cpu_s"]
    print(f"  goals (issue 49): `parknss --help` under 0.3 s: {med['parknss --help']:.2f} s wall, "
          f"{cpu['parknss --help']:.2f} CPU s; `parknss plan --scene 26` under 2 s: "
          f"{med[PLAN]:.2f} s wall, {cpu[PLAN]:.2f} CPU s (bare python {med['python -c pass']:.3f}"
          f" s wall, {cpu['python -c pass']:.3f} CPU s: the load's inflation)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
