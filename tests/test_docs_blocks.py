"""Every fenced code block of README.md and docs/*.md is run (with small settings where it
says so), parsed, checked against the CLI, marked an output sample, or skipped with a
written reason; one test per block, named ``file:line``. The marking and the work folder
are described in tests/helpers/docblocks.py and docs/architecture.md ("Docs test")."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
import yaml

from helpers.docblocks import all_blocks, problems, sample_lines, synopsis_problems
from helpers.paths import ROOT

BLOCKS = all_blocks()
SHARED = Path(os.environ.get("PARKNSS_SHARED", ROOT.parent / "shared"))
COMMAND_TIMEOUT_S = 120


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """The stand-in checkout the blocks run in (helpers/docblocks.py)."""
    base = tmp_path_factory.mktemp("docs")
    work = base / "checkout"
    work.mkdir()
    for entry in ROOT.iterdir():
        if entry.name in {"campaigns", "configs", "models"}:  # blocks write campaigns/mine
            (work / entry.name).mkdir()
            for sub in entry.iterdir():
                (work / entry.name / sub.name).symlink_to(sub.resolve())
        elif entry.name not in {".git", "results", "runs"}:
            (work / entry.name).symlink_to(entry)
    if not (work / ".venv").exists():
        (work / ".venv").symlink_to(Path(sys.prefix))
    shutil.copytree(ROOT / "results", work / "results")
    if SHARED.is_dir():
        (base / "shared").symlink_to(SHARED.resolve())
    for block in BLOCKS:
        for name in block.args("file"):
            (work / name).write_text(block.prepared())
    return work


def _env(block, work: Path) -> dict[str, str]:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MPLBACKEND": "Agg",
           "PARKNSS_RESULTS": str(work / "results")}
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    return {**env, **block.env()}


def test_every_block_is_run_checked_or_justified():
    bad = {b.id: p for b in BLOCKS if (p := problems(b))}
    counts = Counter(b.mode for b in BLOCKS)
    print(f"{len(BLOCKS)} blocks: {dict(counts)}")
    assert not bad, "blocks neither run nor justified:\n" + "\n".join(
        f"  {k}: {'; '.join(v)}" for k, v in bad.items())
    assert len(BLOCKS) > 40 and counts["python"] + counts["commands"] > 15


@pytest.mark.parametrize("block", BLOCKS, ids=[b.id for b in BLOCKS])
def test_block(block, work, monkeypatch, capsys):
    assert not problems(block), problems(block)
    mode = block.mode
    if mode == "skip":
        pytest.skip(block.args("skip")[0])
    text = block.prepared()
    ran = "\n".join(block.commands()) if mode == "commands" else text
    needs = block.args("needs") + (["../shared"] if "../shared" in ran else [])
    if mode not in ("python", "commands"):
        needs = []  # parsed or checked against the CLI: nothing is read
    for need in needs:
        if not (work / need).exists():
            where = f"not beside this checkout ({SHARED})" if need == "../shared" else "missing"
            pytest.skip(f"needs {need}: {where}")
    if mode == "synopsis":
        import typer

        from parknss.cli import app

        assert not synopsis_problems(block, typer.main.get_command(app))
    elif mode in ("output", "parse"):
        assert text.strip()
        if block.lang == "json":
            json.loads(text)
        elif block.lang == "yaml":
            assert isinstance(yaml.safe_load(text), dict)
    elif mode == "python":
        monkeypatch.chdir(work)
        for k, v in _env(block, work).items():
            monkeypatch.setenv(k, v)
        exec(compile(text, block.id, "exec"), {"__name__": "__docs__"})
    else:
        env, printed = _env(block, work), []
        for cmd in block.commands():
            proc = subprocess.run(["bash", "-c", cmd], cwd=work, env=env, text=True,
                                  capture_output=True, timeout=COMMAND_TIMEOUT_S)
            assert proc.returncode == 0, (
                f"{block.id}: `{cmd}` exited {proc.returncode}:\n{proc.stderr[-3000:]}")
            printed += (proc.stdout + proc.stderr).splitlines()
        seen = {" ".join(ln.split()) for ln in printed}
        stale = [ln for ln in sample_lines(block) if ln not in seen]
        assert not stale, f"{block.id}: output sample lines not printed: {stale}"


def test_markings_are_enforced():
    """An unmarked block, a skip without a reason, a text block of commands, a stale
    option or command in a synopsis and a stale replace are each reported."""
    import typer

    from helpers.docblocks import Block
    from parknss.cli import app

    root = typer.main.get_command(app)
    assert problems(Block("x.md", 1, "", "a\n"))
    assert problems(Block("x.md", 1, "bash", "true\n", [("skip", "")]))
    assert problems(Block("x.md", 1, "bash", "true\n", [("drop", '"true"')]))
    assert problems(Block("x.md", 1, "text", "parknss plan --scene 5\n"))
    assert not problems(Block("x.md", 1, "text", "parknss: error: x\n"))
    syn = [("synopsis", "")]
    ok = Block("x.md", 1, "bash", "parknss plan --scene S [--json]\n"
                                  "    [--workers N]\nparknss actuators study|build --nss M\n",
               syn)
    assert synopsis_problems(ok, root) == []
    for text, said in [("parknss plan --scenes S\n", "no option --scenes"),
                       ("parknss plan --scene S\n    [--nope]\n", "no option --nope"),
                       ("parknss actuators study|nope\n", "no command 'nope'"),
                       ("python benchmarks/bench_nope.py\n", "no such script")]:
        assert any(said in p for p in synopsis_problems(Block("x.md", 1, "bash", text, syn),
                                                        root)), text
    with pytest.raises(AssertionError, match="stale"):
        Block("x.md", 1, "bash", "true\n", [("replace", '"false" "true"')]).prepared()
