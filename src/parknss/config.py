"""Typed configuration: pydantic models read from YAML files in ``configs/``.

Each subsystem declares its own config model next to the code that uses it (one idea per
module); this module holds the loading rules they share: the defaults are the paper's, a
YAML file overrides any subset of fields, unknown keys and wrong types are errors.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from parknss.errors import ConfigError

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_DIR = REPO_ROOT / "configs"
MODELS_DIR = REPO_ROOT / "models"
BUNDLED_CAMPAIGN = REPO_ROOT / "campaigns" / "default"
SHIPPED_NSS = MODELS_DIR / "nss"
SHIPPED_CHAIN = MODELS_DIR / "chain"


class StrictModel(BaseModel):
    """Base for every config: frozen, no unknown keys."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    def digest(self) -> str:
        """Stable short hash of the config values (for caches and run folders)."""
        blob = json.dumps(self.model_dump(mode="json"), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


C = TypeVar("C", bound=StrictModel)


def load_config(cls: type[C], path: str | Path | None = None, **overrides) -> C:
    """Read ``cls`` from a YAML file (or its defaults when path is None) plus overrides.

    Raises ConfigError with the file and the offending field on any problem.
    """
    data: dict = {}
    if path is not None:
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"{p}: config file not found")
        try:
            loaded = yaml.safe_load(p.read_text())
        except yaml.YAMLError as exc:
            raise ConfigError(f"{p}: not valid YAML ({exc.__class__.__name__})") from exc
        if loaded is None:
            loaded = {}
        if not isinstance(loaded, dict):
            raise ConfigError(f"{p}: expected a mapping at top level")
        data.update(loaded)
    data.update(overrides)
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        raise ConfigError(f"{path or cls.__name__}: field {loc!r}: {err['msg']}") from exc
