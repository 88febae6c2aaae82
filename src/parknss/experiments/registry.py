"""The paper's reproducible artefacts by name (what ``parknss reproduce`` runs).

The artefact functions are :mod:`parknss.experiments.artefacts` (in registration order);
their types, :mod:`parknss.experiments.results`.
"""

from __future__ import annotations

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
