"""The chain artefact's integrity (issue 43), on a copy of the shipped chain: its manifest
covers every file (an edited chain.json or nss/model.json, swapped weights are refused in
one line), the weights' dtypes and shapes are read from the safetensors header, candidate
sizes are bounded before anything is built, non-finite weights are refused."""

from __future__ import annotations

import hashlib
import json
import shutil

import pytest
import torch
from safetensors.torch import load_file, save_file

from parknss.chain import load_chain
from parknss.chain.artefact import MAX_LAGS, MEMBERS, META, WEIGHTS
from parknss.config import CONFIG_DIR, SHIPPED_CHAIN, SHIPPED_PLANT
from parknss.durable import MANIFEST, read_manifest, write_manifest
from parknss.errors import CheckpointError
from parknss.nss.checkpoint import MAX_UNITS


@pytest.fixture
def chain(tmp_path):
    dst = tmp_path / "chain"
    shutil.copytree(SHIPPED_CHAIN, dst)
    return dst


def _refused(folder, match) -> str:
    with pytest.raises(CheckpointError, match=match) as ei:
        load_chain(folder)
    msg = str(ei.value)
    assert "\n" not in msg
    return msg


def _edit(path, fn, reseal=False):
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc, indent=2))
    if reseal:
        write_manifest(path.parent)


@pytest.mark.parametrize("folder", [SHIPPED_CHAIN, SHIPPED_PLANT], ids=["chain", "plant"])
def test_the_shipped_chains_list_every_file_and_load(folder):
    assert set(read_manifest(folder)) == set(MEMBERS)
    assert set(read_manifest(folder / "nss")) == {"model.json", "model.safetensors"}
    load_chain(folder)


def test_the_deployed_plant_is_what_configs_plant_builds():
    """models/plant's NSS carries exactly configs/plant/nss.yaml's config, and its chain the
    selection and co-tuning of configs/plant/ (the recipe the README rebuilds it with)."""
    from parknss.actuators.config import ArchConfig, load_actuator_config
    from parknss.nss.checkpoint import load_model
    from parknss.nss.config import load_nss_config

    recipe = CONFIG_DIR / "plant"
    assert load_model(SHIPPED_PLANT / "nss").config == load_nss_config(recipe / "nss.yaml")
    meta = json.loads((SHIPPED_PLANT / META).read_text())
    build = meta["build"]
    assert build["selection"] == json.loads((recipe / "selection.json").read_text())["winners"]
    cfg = load_actuator_config(recipe / "actuators.yaml")
    cotune = cfg.cotune
    assert (build["cotune"]["target"], build["cotune"]["iters"]) == (cotune.target, cotune.iters)
    assert build["deployed"]["brake"] == f"{cotune.target}+cotuned"
    # the brake's structure values (hold-speed ceiling, release shape) are the recipe's
    assert ArchConfig.model_validate(meta["channels"]["brake"]["arch"]) == cfg.arch


def test_an_edited_nss_normaliser_is_refused(chain):
    """Issue 43: editing a normaliser scale of nss/model.json (39 -> 3.9) was used silently
    (vx error 0.100 -> 17.3 (km/h)^2); the chain pinned only the NSS weights."""
    def tenth(d):
        ch = d["normalizer"]["channels"]["vx"]
        ch["scale"] = ch["scale"] / 10

    _edit(chain / "nss" / "model.json", tenth)
    _refused(chain, r"nss/model.json: differs from the SHA-256 its SHA256SUMS records")
    write_manifest(chain / "nss")  # the NSS's own manifest forged too: the chain's still refuses
    _refused(chain, r"nss/(model.json|SHA256SUMS): differs from the SHA-256")


def test_an_edited_chain_json_or_swapped_weights_are_refused(chain, tmp_path):
    backup = (chain / META).read_bytes()
    _edit(chain / META, lambda d: d["envelope"].__setitem__("steer_lock_deg", 100000.0))
    _refused(chain, r"chain.json: differs from the SHA-256")
    (chain / META).write_bytes(backup)
    t = load_file(str(chain / WEIGHTS))
    first = sorted(t)[0]
    t[first] = t[first] + 1e-3
    save_file(t, str(chain / WEIGHTS))
    _refused(chain, r"actuators.safetensors: differs from the SHA-256")
    (chain / MANIFEST).unlink()
    _refused(chain, "no SHA256SUMS")


def _set_weights(chain, tensors):
    save_file(tensors, str(chain / WEIGHTS))
    sha = hashlib.sha256((chain / WEIGHTS).read_bytes()).hexdigest()
    _edit(chain / META, lambda d: d["weights"].__setitem__("sha256", sha), reseal=True)


def test_int32_and_non_finite_weights_are_refused(chain):
    t = load_file(str(chain / WEIGHTS))
    _set_weights(chain, {k: v.to(torch.int32) for k, v in t.items()})
    _refused(chain, "is stored as I32; parknss weights are F32 or F64")
    first = sorted(t)[0]
    _set_weights(chain, {**t, first: torch.full_like(t[first], float("nan"))})
    _refused(chain, f"weight '{first}' holds NaN or infinite values")


@pytest.mark.parametrize(("field", "value", "limit"), [
    ("narx_hidden", [200000], MAX_UNITS), ("gru_hidden", 200000, MAX_UNITS),
    ("narx_long_lags", 200000, MAX_LAGS), ("hammerstein_hidden", [8] * 200, 16)])
def test_huge_candidate_sizes_are_refused_before_building(chain, field, value, limit):
    _edit(chain / META, lambda d: d["channels"]["brake"]["arch"].__setitem__(field, value),
          reseal=True)
    _refused(chain, f"channel 'brake'.*arch.{field}.* exceeds the limit {limit}")
