"""The paper's reproducible artefacts by name (what ``parknss reproduce`` runs).

The artefact functions are :mod:`parknss.experiments.artefacts` (in registration order);
their types, :mod:`parknss.experiments.results`.
"""

from __future__ import annotations

import subprocess

from parknss.config import REPO_ROOT
from parknss.errors import ConfigError
from parknss.experiments.artefacts import ARTEFACTS
from parknss.experiments.results import Artefact


def artefacts() -> dict[str, Artefact]:
    """All registered artefacts by name, in registration order."""
    return {a.name: a for a in ARTEFACTS}


def get(name: str) -> Artefact:
    """The artefact ``name`` (one-line ConfigError listing the names otherwise)."""
    arts = artefacts()
    if name not in arts:
        raise ConfigError(f"unknown artefact {name!r}; choose from {', '.join(arts)}")
    return arts[name]


def git_revision() -> str:
    """The repository's HEAD commit (with '+dirty' if the tree has changes), or 'unknown'."""
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO_ROOT,
            capture_output=True,
            text=True,
        ).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
