"""The entry point: ``parknss --version`` prints the package version and exits 0."""

from __future__ import annotations

from parknss import __version__
from parknss.cli import main


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"parknss {__version__}"
