"""Commands start at once: the CLI and every command's ``--help`` import no heavy module.

The heavy libraries (PyTorch, SciPy, matplotlib, CasADi, pandas/pyarrow, FastAPI, ...) are
imported inside the functions that use them, so ``parknss --help`` and the help of every
command stay well under a second. Each check runs in a fresh interpreter, since this test
process has imported them all already.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

HEAVY = ("torch", "scipy", "matplotlib", "casadi", "pandas", "pyarrow", "fastapi",
         "uvicorn", "onnxruntime", "ray", "numpy", "gymnasium", "safetensors")

_PROBE = """
import json, sys
import typer
from parknss.cli import app, main

heavy = set(json.loads(sys.argv[1]))

def paths(cmd, prefix):
    yield prefix
    for name, sub in sorted(getattr(cmd, "commands", {}).items()):
        yield from paths(sub, prefix + [name])

report = {}
for path in paths(typer.main.get_command(app), []):
    try:
        main(path + ["--help"])
    except SystemExit:
        pass
    loaded = sorted({m.split(".")[0] for m in sys.modules} & heavy)
    if loaded:
        report[" ".join(path) or "(top)"] = loaded
        break
report["_checked"] = len(list(paths(typer.main.get_command(app), [])))
print(json.dumps(report), file=sys.stderr)
"""


def _probe(code: str, *args: str) -> dict:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, env=env,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stderr.strip().splitlines()[-1])


def test_help_of_every_command_imports_no_heavy_module():
    report = _probe(_PROBE, json.dumps(HEAVY))
    checked = report.pop("_checked")
    assert checked > 20  # the top level, every group and every subcommand
    assert report == {}, f"--help imported heavy modules (first offender): {report}"


def test_importing_the_cli_imports_no_config_machinery():
    # pydantic and YAML come with the first command that loads a config, not with the CLI
    report = _probe(
        "import json, sys; import parknss.cli; "
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} "
        "& {'yaml', 'pydantic', 'tqdm', 'numpy'})), file=sys.stderr)"
    )
    assert report == []


def test_the_iso_module_imports_no_scipy():
    # scipy.signal alone took seconds to import; only the low-pass needs it
    report = _probe(
        "import json, sys; import parknss.metrics.iso18571; "
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} "
        "& {'scipy', 'torch', 'matplotlib'})), file=sys.stderr)"
    )
    assert report == []


RESULTS = Path(__file__).resolve().parents[2] / "results"

LIGHT_COMMANDS = {
    # a command that runs (not only its --help) -> the heavy modules it may import
    "--version": (),
    # the store's listing reads JSON; parked training states are checked without torch;
    # whether a derived entry (Table V cell, ladder, rating) is current is computed from
    # what it reads (NumPy, no torch)
    "results list --json --store {results}": ("numpy",),
    # the refinement needs CasADi (the search alone does not); the figure is SVG (no
    # matplotlib); a scene's heuristic grid is small enough for the plain-Python
    # Dijkstra, the closed-loop configs need no scipy.linalg: no SciPy at all
    "plan --scene 26 --json --out {tmp}/plan": ("numpy", "casadi"),
    "plan --scene 26 --no-refine --json --out {tmp}/coarse": ("numpy",),
    "plan --scene 26 --no-figure --json --out {tmp}/bare": ("numpy", "casadi"),
}

_RUN = """
import json, sys
from parknss.cli import main

try:
    code = main(sys.argv[2].split())
except SystemExit as exc:
    code = exc.code
heavy = set(json.loads(sys.argv[1])) | {"matplotlib.pyplot"}
names = {m.split(".")[0] for m in sys.modules} | set(sys.modules)
print(json.dumps([code, sorted(names & heavy)]), file=sys.stderr)
"""


def test_light_commands_import_only_what_they_use(tmp_path):
    for command, allowed in LIGHT_COMMANDS.items():
        line = command.format(tmp=tmp_path, results=RESULTS)
        code, loaded = _probe(_RUN, json.dumps(HEAVY), line)
        assert code in (0, None), (command, code)
        extra = sorted(set(loaded) - set(allowed))
        assert extra == [], f"`parknss {command}` imported {extra}"
