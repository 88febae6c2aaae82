"""The entry point: ``parknss --version`` prints the package version and exits 0; every
command list (``parknss --help``, ``parknss GROUP --help``) reads whole."""

from __future__ import annotations

import re

import typer

from parknss import __version__
from parknss.cli import app, main

# A short help that ends in one of these was cut at an abbreviation's full stop.
_CUT = re.compile(r"(\b(Fig|Figs|Eq|Eqs|Tab|Sec|No|vs|etc|cf|approx)\.|\be\.g\.|\bi\.e\.|\.\.\.)$")


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"parknss {__version__}"


def _groups(cmd, path: list[str]):
    if hasattr(cmd, "commands"):  # a group (typer vendors its own click)
        yield path, cmd
        for name, sub in sorted(cmd.commands.items()):
            yield from _groups(sub, [*path, name])


def test_every_command_in_every_list_has_a_whole_short_help(capsys):
    root = typer.main.get_command(app)
    listed = 0
    for path, group in _groups(root, []):
        for name, sub in group.commands.items():
            short = sub.short_help or ""
            assert short.strip(), f"parknss {' '.join([*path, name])}: no explicit short help"
            assert not _CUT.search(short.strip()), f"{name}: short help cut: {short!r}"
        # ... and the rendered list shows each one whole (no '...' cut, no 'Fig.' end)
        assert main([*path, "--help"]) == 0
        out = capsys.readouterr().out
        rows = out.split("Commands:\n", 1)[1].splitlines()
        names = [r.split()[0] for r in rows if r.startswith("  ") and not r.startswith("   ")]
        assert sorted(names) == sorted(group.commands), out
        for row in rows:
            assert row.strip() and not _CUT.search(row.strip()), f"{path}: {row!r}"
            listed += 1
    assert listed > 30  # the top level and every group's subcommands
