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


def test_plan_imports_neither_torch_nor_pyplot(tmp_path):
    # planning needs CasADi; the figure needs matplotlib, not pyplot; a scene's heuristic
    # grid is small enough for the plain-Python Dijkstra (no scipy at all)
    report = _probe(
        "import json, sys; from parknss.cli import main; "
        "code = main(['plan', '--scene', '26', '--no-refine', '--json', '--out', sys.argv[1]]); "
        "print(json.dumps([code, sorted({m for m in sys.modules} & {'torch', "
        "'matplotlib.pyplot', 'scipy', 'pandas', 'pyarrow', 'fastapi'})]), "
        "file=sys.stderr)",
        str(tmp_path / "plan"),
    )
    assert report == [0, []]
