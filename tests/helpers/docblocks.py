"""The fenced code blocks of README.md and docs/*.md, and how the docs test runs each.

A block's info string and the ``<!-- docs-test: ... -->`` comments on the lines right
above its opening fence decide what tests/test_docs_blocks.py does with it
(docs/architecture.md, "Docs test"):

* ``python``: executed in-process, in the docs work folder (below), with the repository's
  ``src`` importable;
* ``bash`` / ``console``: each command run through ``bash -c`` in the work folder, with the
  interpreter's bin folder first on PATH (its ``parknss``); in a ``console`` block only the
  ``$ `` lines are commands, the rest is their output sample: each of its lines (but
  ``...``) must appear in what the commands printed (spaces aside);
* ``json`` / ``yaml``: parsed;
* ``text``: an output sample, listing or diagram: not run; a ``text`` block that reads
  like commands fails (run it, mark it ``synopsis``, or skip it with a reason).

Directives (one per comment, several comments may stack):

* ``skip REASON``: not run; the reason is required;
* ``synopsis``: usage lines, not run: every ``parknss`` line's command must exist and
  every ``--option`` it names must be one of that command's options; every ``*.py``
  script it names must exist;
* ``replace "OLD" "NEW"``: small settings; OLD must occur in the block;
* ``drop "TEXT" REASON``: leave out the command lines containing TEXT (a reason is
  required, as for a skip);
* ``env NAME=VALUE ...``: environment of the block;
* ``file NAME``: the block is also written to NAME in the work folder before any block
  runs (a scene or mapping example that a command of another block reads);
* ``needs PATH``: run only where PATH (relative to the work folder) exists, e.g.
  ``../shared`` for a block that uses what an earlier block read from there (a block
  whose text names ``../shared`` needs it anyway); blocks run in file order in one
  work folder.

The work folder is a temporary stand-in for the checkout: links to each top-level entry of
the repository (so ``configs/...``, ``benchmarks/...`` and ``.venv/bin/python`` resolve;
``campaigns``, ``configs`` and ``models`` are folders of links, so that what a block writes
there, ``campaigns/mine``, stays in the work folder),
a copy of ``results/`` (commands that write the result store write the copy), and
``../shared`` linked to the checkout's neighbour (``PARKNSS_SHARED`` overrides it), so
that blocks read ``../shared`` inputs in place.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

from helpers.paths import ROOT

FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([\w+-]*)\s*$")
DIRECTIVE = re.compile(r"^\s*<!--\s*docs-test:\s*(.*?)\s*-->\s*$")
RUN_LANGS = {"python", "bash", "sh", "shell", "console"}
PARSE_LANGS = {"json", "yaml"}
KINDS = {"skip", "synopsis", "replace", "drop", "env", "file", "output", "needs"}
# a line of a `text` block that reads like a command someone would type
COMMANDISH = re.compile(r"^\s*(\$ |parknss |python |\.venv/|pip |curl |make |git |ray )")


@dataclass
class Block:
    """One fenced block: file (relative to the checkout), 1-based line of the opening
    fence, info string, body, and its docs-test directives as (kind, argument) pairs."""

    file: str
    line: int
    lang: str
    text: str
    directives: list[tuple[str, str]] = field(default_factory=list)

    @property
    def id(self) -> str:
        return f"{self.file}:{self.line}"

    def args(self, kind: str) -> list[str]:
        return [a for k, a in self.directives if k == kind]

    @property
    def mode(self) -> str:
        """skip | synopsis | output | python | commands | parse | unknown."""
        if self.args("skip"):
            return "skip"
        if self.args("synopsis"):
            return "synopsis"
        if self.args("output") or self.lang == "text":
            return "output"
        if self.lang == "python":
            return "python"
        if self.lang in RUN_LANGS:
            return "commands"
        if self.lang in PARSE_LANGS:
            return "parse"
        return "unknown"

    def prepared(self) -> str:
        """The body after the ``replace`` directives (each OLD must occur)."""
        text = self.text
        for arg in self.args("replace"):
            old, new = shlex.split(arg)
            assert old in text, f"{self.id}: replace {old!r}: not in the block (stale?)"
            text = text.replace(old, new)
        return text

    def env(self) -> dict[str, str]:
        pairs = [p for arg in self.args("env") for p in shlex.split(arg)]
        return dict(p.split("=", 1) for p in pairs)

    def commands(self) -> list[str]:
        """The command lines (continuations joined; ``drop`` lines left out)."""
        lines = self.prepared().splitlines()
        if self.lang == "console":
            cmds, cont = [], False
            for ln in lines:
                if ln.startswith("$ ") or cont:
                    cmds.append(ln[2:] if ln.startswith("$ ") else ln)
                    cont = ln.rstrip().endswith("\\")
            lines = cmds
        joined, cur = [], ""
        for ln in lines:
            cur += ln.rstrip()[:-1] + " " if ln.rstrip().endswith("\\") else ln
            if not ln.rstrip().endswith("\\"):
                joined.append(cur)
                cur = ""
        drops = [shlex.split(a)[0] for a in self.args("drop")]
        return [c for c in joined
                if c.strip() and not c.lstrip().startswith("#")
                and not any(d in c for d in drops)]


def sample_lines(block: Block) -> list[str]:
    """The output lines of a ``console`` block (not ``$`` lines, their continuations or
    ``...``), spaces collapsed."""
    if block.lang != "console":
        return []
    out, cont = [], False
    for ln in block.prepared().splitlines():
        if ln.startswith("$ ") or cont:
            cont = ln.rstrip().endswith("\\")
            continue
        if ln.strip() and ln.strip() != "...":
            out.append(" ".join(ln.split()))
    return out


def _directives(lines: list[str], fence: int) -> list[tuple[str, str]]:
    out = []
    i = fence - 1
    while i >= 0 and (m := DIRECTIVE.match(lines[i])):
        kind, _, arg = m.group(1).partition(" ")
        out.append((kind, arg.strip()))
        i -= 1
    return out[::-1]


def read_blocks(path: Path) -> list[Block]:
    """Every fenced block of one markdown file."""
    lines = path.read_text(encoding="utf-8").splitlines()
    rel = path.relative_to(ROOT).as_posix()
    blocks, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, j = m.group(2), i + 1
        while j < len(lines) and not (lines[j].strip().startswith(fence[0] * len(fence))
                                      and set(lines[j].strip()) == {fence[0]}):
            j += 1
        indent = len(m.group(1))
        body = "\n".join(ln[indent:] for ln in lines[i + 1:j])
        blocks.append(Block(rel, i + 1, m.group(3), body + "\n", _directives(lines, i)))
        i = j + 1
    return blocks


def doc_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def all_blocks() -> list[Block]:
    return [b for f in doc_files() for b in read_blocks(f)]


def problems(block: Block) -> list[str]:
    """What is wrong with a block's marking (empty: it is run, checked or justified)."""
    bad = [f"unknown directive {k!r}" for k, _ in block.directives if k not in KINDS]
    for kind in ("skip", "drop"):
        for arg in block.args(kind):
            reason = arg if kind == "skip" else arg.partition('" ')[2] if arg.startswith('"') \
                else ""
            if not reason.strip():
                bad.append(f"{kind} without a reason")
    if block.mode == "unknown":
        bad.append(f"info string {block.lang!r}: neither run, parsed, an output sample "
                   "(text), nor skipped with a reason")
    if block.mode == "output" and block.lang in ("text", ""):
        cmds = [ln for ln in block.text.splitlines() if COMMANDISH.match(ln)]
        if cmds:
            bad.append(f"an output sample that reads like commands ({cmds[0].strip()!r}): "
                       "run it, mark it synopsis, or skip it with a reason")
    return bad


def _options(cmd) -> set[str]:
    return {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)} | {"--help"}


def synopsis_problems(block: Block, root) -> list[str]:
    """Usage lines against the CLI ``root`` (a click group): each ``parknss`` line's
    command path exists and each ``--option`` is one of its options; each script exists."""
    bad, lines = [], []
    for line in block.commands():  # an indented line continues the usage line above it
        if lines and line[:1].isspace():
            lines[-1] += " " + line.strip()
        else:
            lines.append(line)
    for line in lines:
        text = re.sub(r"\s#.*$", "", line)
        toks = text.split()
        for tok in toks:
            if re.fullmatch(r"[\w./-]+\.py", tok) and not (ROOT / tok).is_file():
                bad.append(f"{tok}: no such script")
        if "parknss" not in toks:
            continue
        rest = toks[toks.index("parknss") + 1:]
        cmds, path = [root], ["parknss"]
        while rest and all(hasattr(c, "commands") for c in cmds) and rest[0][0] not in "-[<":
            names = rest.pop(0).split("|")
            missing = [n for n in names if not any(n in c.commands for c in cmds)]
            if missing:
                bad.append(f"{' '.join(path)} has no command {missing[0]!r}")
                break
            cmds = [c.commands[n] for c in cmds for n in names if n in c.commands]
            path.append("|".join(names))
        known = set().union(*(_options(c) for c in cmds))
        for opt in re.findall(r"(?<![\w-])--[a-z][\w-]*", " ".join(rest)):
            if opt not in known:
                bad.append(f"{' '.join(path)}: no option {opt}")
    return bad
