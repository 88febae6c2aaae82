"""parknss.config: one typed, validated way to load and override configs; shipped files
found from the package."""

from __future__ import annotations

import importlib.resources
from pathlib import Path

import pytest
import yaml
from pydantic import Field

import parknss.config as pc
from parknss.actuators.config import ActuatorConfig, load_actuator_config
from parknss.config import (
    CONFIG_DIR,
    PACKAGE_DIR,
    StrictModel,
    load_config,
    override,
    parse_set,
    read_yaml_mapping,
)
from parknss.data.describe import DescribeConfig, load_describe_config
from parknss.data.validate import ValidationConfig, load_validation_config
from parknss.errors import ConfigError
from parknss.experiments.config import ExperimentsConfig, load_experiments_config
from parknss.nss.config import NSSConfig, load_nss_config, with_overrides
from parknss.reference.params import ReferenceVehicleParams, load_vehicle_params
from parknss.sim.closed_loop import ClosedLoopConfig, load_closed_loop_config
from parknss.sim.control.interface import InterfaceConfig, load_interface_config
from parknss.sim.planning.hybrid_astar import PlanningConfig, load_planning_config
from parknss.sim.scenarios import ScenariosConfig, load_scenarios_config
from parknss.web.config import WebConfig, load_web_config

# (shipped file, model, the loader the commands call with no path)
SHIPPED = [
    ("nss.yaml", NSSConfig, load_nss_config),
    ("actuators.yaml", ActuatorConfig, load_actuator_config),
    ("web.yaml", WebConfig, load_web_config),
    ("planning.yaml", PlanningConfig, load_planning_config),
    ("scenarios.yaml", ScenariosConfig, load_scenarios_config),
    ("closed_loop.yaml", ClosedLoopConfig, load_closed_loop_config),
    ("interface.yaml", InterfaceConfig, load_interface_config),
    ("reference_vehicle.yaml", ReferenceVehicleParams, load_vehicle_params),
    ("experiments.yaml", ExperimentsConfig, load_experiments_config),
]


class Inner(StrictModel):
    a: int = 1
    b: float = 2.0
    tags: dict[str, int] = Field(default_factory=dict)


class Outer(StrictModel):
    inner: Inner = Inner()
    name: str = "x"


# -- package data ---------------------------------------------------------------------------


def test_package_holds_configs_models_campaigns():
    root = importlib.resources.files("parknss")
    for sub in ("configs", "models", "campaigns"):
        assert root.joinpath(sub).is_dir(), sub
    assert root.joinpath("configs", "nss.yaml").is_file()
    assert root.joinpath("models", "nss", "model.json").is_file()
    assert root.joinpath("models", "chain", "chain.json").is_file()
    assert root.joinpath("campaigns", "default", "campaign.json").is_file()
    assert root.joinpath("web", "static").is_dir()


def test_config_resolves_from_the_package():
    pkg = Path(pc.__file__).resolve().parent
    assert pkg == PACKAGE_DIR
    assert pkg / "configs" == pc.CONFIG_DIR
    assert pkg / "models" == pc.MODELS_DIR
    assert pkg / "models" / "nss" == pc.SHIPPED_NSS
    assert pkg / "models" / "chain" == pc.SHIPPED_CHAIN
    assert pkg / "models" / "plant" == pc.SHIPPED_PLANT
    assert pkg / "campaigns" / "default" == pc.BUNDLED_CAMPAIGN
    assert Path(str(importlib.resources.files("parknss"))).resolve() == pkg


def test_checkout_links_point_into_the_package():
    """The documented paths (configs/..., models/chain, campaigns/default) keep working."""
    root = pc.REPO_ROOT
    if not (root / "pyproject.toml").is_file():
        pytest.skip("not a checkout")
    for sub in ("configs", "models", "campaigns"):
        assert (root / sub).resolve() == PACKAGE_DIR / sub, sub


# -- shipped files ----------------------------------------------------------------------------


def test_every_shipped_yaml_parses():
    files = sorted(CONFIG_DIR.rglob("*.yaml"))
    assert len(files) >= 15
    for f in files:
        assert isinstance(yaml.safe_load(f.read_text()), dict), f


@pytest.mark.parametrize("name,cls,loader", SHIPPED, ids=[s[0] for s in SHIPPED])
def test_shipped_yaml_is_what_the_commands_use(name, cls, loader):
    from_file = load_config(cls, CONFIG_DIR / name)
    assert loader() == from_file
    assert load_config(cls, default=name) == from_file


@pytest.mark.parametrize(
    "name,cls,loader",
    [s for s in SHIPPED if s[0] != "experiments.yaml"],
    ids=[s[0] for s in SHIPPED if s[0] != "experiments.yaml"],
)
def test_code_defaults_agree_with_shipped_yaml(name, cls, loader):
    """Library code still builds ``cls()`` where no config is passed; the shipped YAML is
    the source of the shipped values and the code defaults must not drift from it
    (experiments.yaml's quick budget is deliberately richer than the model's defaults)."""
    assert cls() == loader()


def test_data_yaml_sections():
    assert load_validation_config() == load_validation_config(CONFIG_DIR / "data.yaml")
    assert load_validation_config().ranges  # the ranges live only in data.yaml
    assert load_describe_config() == DescribeConfig()
    assert isinstance(load_validation_config(), ValidationConfig)


def test_missing_shipped_file_is_an_error_not_code_defaults(monkeypatch, tmp_path):
    monkeypatch.setattr(pc, "CONFIG_DIR", tmp_path)
    with pytest.raises(ConfigError, match="shipped default config file not found"):
        load_config(ClosedLoopConfig, default="closed_loop.yaml")
    with pytest.raises(ConfigError, match="shipped default"):
        load_closed_loop_config()
    with pytest.raises(ConfigError, match="shipped default"):
        load_validation_config()


# -- load_config ------------------------------------------------------------------------------


def test_load_config_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    cases = {
        "inner: {a: [1, 2]}\n": "field 'inner.a'",
        "inner: {zz: 1}\n": "field 'inner.zz'",
        "- 1\n": "expected a mapping",
        "inner: {a: 1\n": "not valid YAML",
    }
    for text, want in cases.items():
        bad.write_text(text)
        with pytest.raises(ConfigError) as ei:
            load_config(Outer, bad)
        msg = str(ei.value)
        assert want in msg and str(bad) in msg and "\n" not in msg, msg
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(Outer, tmp_path / "absent.yaml")


def test_load_config_path_beats_default_and_overrides_merge(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("inner: {a: 5}\nname: y\n")
    cfg = load_config(Outer, f, default="does-not-matter.yaml", overrides={"inner": {"b": 7}})
    assert cfg == Outer(inner=Inner(a=5, b=7.0), name="y")
    assert load_config(Outer) == Outer()
    with pytest.raises(ConfigError, match=r"field 'inner.c' \(override\)"):
        load_config(Outer, f, overrides={"inner": {"c": 1}})


# -- override ---------------------------------------------------------------------------------


def test_override_deep_merges_and_validates():
    base = Outer(inner=Inner(a=3, tags={"k": 1}))
    got = override(base, {"inner": {"b": 4.5, "tags": {"j": 2}}})
    assert got == Outer(inner=Inner(a=3, b=4.5, tags={"k": 1, "j": 2}))
    assert override(base, {}) is base and override(base, None) is base
    for bad, field in [
        ({"inner": {"nope": 1}}, "inner.nope"),
        ({"nope": 1}, "nope"),
        ({"inner": {"a": "many"}}, "inner.a"),
        ({"inner": 3}, "inner"),
    ]:
        with pytest.raises(ConfigError) as ei:
            override(base, bad)
        assert f"field {field!r}" in str(ei.value) and "\n" not in str(ei.value)


def test_override_runs_model_validators():
    with pytest.raises(ConfigError, match="fused"):
        override(NSSConfig(), {"model": {"engine": "fused", "integrator": "rk4"}})


def test_with_overrides_is_override():
    cfg = NSSConfig()
    a = with_overrides(cfg, train={"epochs": 30}, model={"state_units": 16})
    assert a == override(cfg, {"train": {"epochs": 30}, "model": {"state_units": 16}})
    assert a.train.lr == cfg.train.lr and a.train.epochs == 30
    with pytest.raises(ConfigError, match="field 'nope'"):
        with_overrides(cfg, nope={"x": 1})


# -- parse_set --------------------------------------------------------------------------------


def test_parse_set():
    got = parse_set(["train.lr=1e-3", "train.epochs=30", "model.engine=eager",
                     "limiter.enabled=true", "data.window=shortest", "a.b.c=[1, 2]"])
    assert got == {
        "train": {"lr": "1e-3", "epochs": 30},  # YAML 1.1: a string, the model coerces it
        "model": {"engine": "eager"},
        "limiter": {"enabled": True},
        "data": {"window": "shortest"},
        "a": {"b": {"c": [1, 2]}},
    }
    assert parse_set(None) == {} and parse_set([]) == {}
    cfg = override(NSSConfig(), parse_set(["train.epochs=3", "train.lr=1e-3"]))
    assert cfg.train.epochs == 3 and cfg.train.lr == 1e-3


@pytest.mark.parametrize(
    "items,want",
    [
        (["train.lr"], "expected section.field=value"),
        (["=3"], "expected section.field=value"),
        (["train..lr=3"], "expected section.field=value"),
        (["train.lr=[1"], "not valid YAML"),
        (["train=1", "train.lr=2"], "already set"),
        (["train.lr=2", "train=1"], "already has fields"),
    ],
)
def test_parse_set_errors(items, want):
    with pytest.raises(ConfigError, match=want) as ei:
        parse_set(items)
    assert "\n" not in str(ei.value)


def test_read_yaml_mapping_empty_file(tmp_path):
    f = tmp_path / "e.yaml"
    f.write_text("")
    assert read_yaml_mapping(f) == {}


class _Before(StrictModel):
    a: int = 1


class _After(StrictModel):
    """``_Before`` with a field added later, registered as omitted at its default."""

    omit_at_default = frozenset({"b"})
    a: int = 1
    b: str = "old"


def test_a_field_added_at_its_default_leaves_the_dump_and_digest_as_before():
    assert _After().model_dump() == _Before().model_dump() == {"a": 1}
    assert _After().digest() == _Before().digest()
    changed = _After(b="new")
    assert changed.model_dump() == {"a": 1, "b": "new"}
    assert changed.digest() != _Before().digest()
    # the dump still round-trips through validation and override
    assert _After.model_validate(_After().model_dump()) == _After()
    assert override(_After(), {"a": 2}).model_dump() == {"a": 2}
