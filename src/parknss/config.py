"""Typed configuration: pydantic models read from the YAML files shipped in the package.

Each subsystem declares its own config model next to the code that uses it (one idea per
module); this module holds the one set of rules they share:

* :func:`load_config` reads a model from a YAML file, or from the shipped default file
  (``parknss/configs/<name>``, package data, so a wheel has it too), then applies
  overrides; a missing shipped file is an error, never a silent fall-back to code defaults.
* :func:`override` deep-merges a nested dict (``{"train": {"epochs": 30}}``) into a
  config and validates the result; :func:`parse_set` turns ``--set section.field=value``
  strings into that dict.
* Unknown keys and wrong types are one-line :class:`ConfigError` naming the file (or the
  override) and the field.

The shipped configs, the shipped plant (``models/``) and the bundled campaign
(``campaigns/``) live inside the package and are found from it (:data:`PACKAGE_DIR`);
the checkout's top-level ``configs``, ``models`` and ``campaigns`` are links to them.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError, model_serializer

from parknss.errors import ConfigError

PACKAGE_DIR = Path(__file__).resolve().parent
"""The installed package folder; configs, models and campaigns are package data in it."""
CONFIG_DIR = PACKAGE_DIR / "configs"
MODELS_DIR = PACKAGE_DIR / "models"
CAMPAIGNS_DIR = PACKAGE_DIR / "campaigns"
BUNDLED_CAMPAIGN = CAMPAIGNS_DIR / "default"
SHIPPED_NSS = MODELS_DIR / "nss"
SHIPPED_CHAIN = MODELS_DIR / "chain"
"""The paper-recipe chain on SHIPPED_NSS: the paper's protocol (Table IV, Fig. 7, the demo's
open-loop rollout)."""
SHIPPED_PLANT = MODELS_DIR / "plant"
"""The deployed plant: the chain of the closed-loop recipe (configs/plant/), the default of
everything closed loop (simulate, grid, fidelity, web, gym) and of the exports."""
REPO_ROOT = PACKAGE_DIR.parents[1]
"""The checkout root when running from a source tree (``src/parknss`` -> ``.``); for an
installed wheel this is the ``site-packages`` parent and holds no repository."""


class StrictModel(BaseModel):
    """Base for every config: frozen, no unknown keys.

    ``omit_at_default`` names fields that a dump (and so :meth:`digest`) leaves out while
    they hold their default: a field added to a config after results keyed by its dump
    exist (run folders' manifests, fits in progress, stored entries) goes there, so those
    keep reading as the same config, and a run folder started before the field existed
    resumes; set to another value, the field is dumped and digested."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    omit_at_default: ClassVar[frozenset[str]] = frozenset()

    @model_serializer(mode="wrap")
    def _omit_defaults(self, handler) -> dict:
        doc = handler(self)
        fields = type(self).model_fields
        for name in self.omit_at_default:
            if getattr(self, name) == fields[name].default:
                doc.pop(name, None)
        return doc

    def digest(self) -> str:
        """Stable short hash of the config values (for caches and run folders)."""
        blob = json.dumps(self.model_dump(mode="json"), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


C = TypeVar("C", bound=BaseModel)


def shipped_config(name: str) -> Path:
    """The shipped default file ``name`` (e.g. ``"closed_loop.yaml"``) in the package.

    Raises ConfigError when the file is not there (a broken install), so code defaults are
    never used silently in place of the shipped values.
    """
    p = CONFIG_DIR / name
    if not p.is_file():
        raise ConfigError(f"{p}: shipped default config file not found (broken install?)")
    return p


MAX_NESTING = 64
"""The deepest nesting of lists and mappings a JSON or YAML input parknss reads may have
(scenes, configs, manifests: a few levels in practice); deeper documents are refused in
one line instead of exhausting Python's recursion."""


def nesting_depth(doc: Any) -> int:
    """The nesting depth of lists and mappings in ``doc`` (a scalar: 0), without recursion."""
    depth, stack = 0, [(doc, 1)]
    while stack:
        node, level = stack.pop()
        if isinstance(node, Mapping):
            children = list(node.values())
        elif isinstance(node, list | tuple):
            children = list(node)
        else:
            continue
        depth = max(depth, level)
        if depth > MAX_NESTING:
            return depth
        stack.extend((c, level + 1) for c in children)
    return depth


def parse_json(
    text: str | bytes, source: str, error: type[Exception] = ConfigError
) -> Any:
    """``text`` parsed as JSON, or one-line ``error`` naming ``source``: not valid JSON,
    or nested deeper than :data:`MAX_NESTING` (a RecursionError never escapes)."""
    try:
        doc = json.loads(text)
    except RecursionError as exc:
        raise error(f"{source}: nested deeper than {MAX_NESTING} levels; refused") from exc
    except (ValueError, UnicodeDecodeError) as exc:
        raise error(f"{source}: not valid JSON ({exc.__class__.__name__})") from exc
    if nesting_depth(doc) > MAX_NESTING:
        raise error(f"{source}: nested deeper than {MAX_NESTING} levels; refused")
    return doc


def read_json(path: str | Path, error: type[Exception] = ConfigError) -> Any:
    """The JSON file ``path`` through :func:`parse_json`; one-line ``error`` when it
    cannot be read (missing, no permission) or parsed."""
    p = Path(path)
    try:
        text = p.read_bytes()
    except OSError as exc:
        raise error(f"{p}: cannot read ({exc.strerror or exc.__class__.__name__})") from exc
    return parse_json(text, str(p), error)


def parse_yaml(text: str, source: str, error: type[Exception] = ConfigError) -> Any:
    """``text`` parsed as YAML (safe loader), or one-line ``error`` naming ``source``: not
    valid YAML, or nested deeper than :data:`MAX_NESTING`."""
    try:
        doc = yaml.safe_load(text)
    except RecursionError as exc:
        raise error(f"{source}: nested deeper than {MAX_NESTING} levels; refused") from exc
    except yaml.YAMLError as exc:
        raise error(f"{source}: not valid YAML ({exc.__class__.__name__})") from exc
    if nesting_depth(doc) > MAX_NESTING:
        raise error(f"{source}: nested deeper than {MAX_NESTING} levels; refused")
    return doc


def read_yaml_mapping(path: str | Path) -> dict[str, Any]:
    """The top-level mapping of a YAML file ({} for an empty file); one-line ConfigError
    for a missing file, invalid YAML or a top level that is not a mapping."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: config file not found")
    try:
        loaded = parse_yaml(p.read_text(), str(p))
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read ({exc.__class__.__name__})") from exc
    if loaded is None:
        return {}
    if not isinstance(loaded, dict):
        raise ConfigError(f"{p}: expected a mapping at top level")
    return loaded


def _deep_merge(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    """``base`` with ``top`` merged in: mappings merge key by key, anything else replaces."""
    out = dict(base)
    for key, val in top.items():
        old = out.get(key)
        if isinstance(val, Mapping) and isinstance(old, Mapping):
            out[key] = _deep_merge(old, val)
        else:
            out[key] = val
    return out


def _has_path(doc: Any, loc: tuple) -> bool:
    for part in loc:
        if not isinstance(doc, Mapping) or part not in doc:
            return False
        doc = doc[part]
    return True


def _validate(cls: type[C], data: dict, source: str, overrides: Mapping | None) -> C:
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = tuple(err["loc"])
        field = ".".join(str(x) for x in loc) or "(top level)"
        where = " (override)" if overrides and loc and _has_path(overrides, loc[:1]) else ""
        msg = " ".join(str(err["msg"]).split())
        raise ConfigError(f"{source}: field {field!r}{where}: {msg}") from exc


def override(cfg: C, overrides: Mapping[str, Any] | None, *, source: str | None = None) -> C:
    """A copy of ``cfg`` with the nested dict ``overrides`` deep-merged in, validated.

    ``override(nss_cfg, {"train": {"epochs": 30}})`` changes one field and keeps the rest
    of the section. Unknown keys and bad values raise a one-line ConfigError naming
    ``source`` (default: the model's class name) and the field. An empty or None
    ``overrides`` returns ``cfg`` itself.
    """
    if not overrides:
        return cfg
    if not isinstance(overrides, Mapping):
        raise ConfigError(f"{source or type(cfg).__name__}: overrides must be a mapping")
    doc = _deep_merge(cfg.model_dump(), overrides)
    return _validate(type(cfg), doc, source or type(cfg).__name__, overrides)


def load_config(
    cls: type[C],
    path: str | Path | None = None,
    *,
    default: str | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> C:
    """Read ``cls`` from the YAML file ``path``, then apply ``overrides`` (:func:`override`).

    When ``path`` is None the shipped default file ``default`` (a name in the package's
    configs folder, e.g. ``"closed_loop.yaml"``) is read; it must exist. With neither,
    the model's code defaults plus overrides. Every problem is a one-line ConfigError
    with the file and the offending field.
    """
    if path is None and default is not None:
        path = shipped_config(default)
    data: dict[str, Any] = read_yaml_mapping(path) if path is not None else {}
    if overrides:
        if not isinstance(overrides, Mapping):
            raise ConfigError(f"{path or cls.__name__}: overrides must be a mapping")
        data = _deep_merge(data, overrides)
    return _validate(cls, data, str(path) if path is not None else cls.__name__, overrides)


def parse_set(items: list[str] | None, *, option: str = "--set") -> dict[str, Any]:
    """``["train.lr=1e-3", "model.state_units=32"]`` -> ``{"train": {"lr": 0.001, ...}}``.

    Each item is ``key.key...=value``; the value is parsed as YAML (``1e-3``, ``true``,
    ``[1, 2]``, ``null``). A malformed item, an invalid value or two items that disagree
    on a key's shape (``train=1`` and ``train.lr=2``) raise a one-line ConfigError.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, raw = str(item).partition("=")
        parts = [p.strip() for p in key.split(".")]
        if not sep or not all(parts):
            raise ConfigError(
                f"{option} {item!r}: expected section.field=value, e.g. train.lr=1e-3"
            )
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{option} {item!r}: value is not valid YAML") from exc
        node = out
        for part in parts[:-1]:
            nxt = node.setdefault(part, {})
            if not isinstance(nxt, dict):
                raise ConfigError(f"{option} {item!r}: {part!r} was already set to a value")
            node = nxt
        if isinstance(node.get(parts[-1]), dict) and not isinstance(value, dict):
            raise ConfigError(f"{option} {item!r}: {parts[-1]!r} already has fields set")
        node[parts[-1]] = value
    return out
