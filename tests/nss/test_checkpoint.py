"""The model artefact: round trip, one-line refusals, safetensors only (nothing unpickled),
the SHA256SUMS manifest, checks of the safetensors header before anything is allocated."""

from __future__ import annotations

import hashlib
import json
import struct

import numpy as np
import pytest
import torch

from helpers.synth import make_campaign, tiny_model
from parknss.durable import MANIFEST, write_manifest
from parknss.errors import CheckpointError
from parknss.nss.checkpoint import MAX_LAYERS, MAX_UNITS, META, WEIGHTS, load_model, save_model
from parknss.nss.predict import predict_campaign, predict_trials

CAMP = make_campaign(120, reps=1)


@pytest.fixture
def saved(tmp_path):
    m, cfg = tiny_model(CAMP, seed=7)
    save_model(tmp_path / "m", m, cfg, {"epochs": 3, "seed": 7})
    return tmp_path / "m", m, cfg


def _edit(folder, fn, reseal=True):
    """Edit model.json; ``reseal``: and rewrite the manifest (as a careful forger would),
    so that the checks behind it are reached."""
    p = folder / META
    doc = json.loads(p.read_text())
    fn(doc)
    p.write_text(json.dumps(doc))
    if reseal:
        write_manifest(folder)


def _set_weights(folder, tensors):
    """Replace the weights, record their hash in model.json and reseal the manifest."""
    from safetensors.torch import save_file

    save_file(tensors, str(folder / WEIGHTS))
    sha = hashlib.sha256((folder / WEIGHTS).read_bytes()).hexdigest()
    _edit(folder, lambda d: d["weights"].__setitem__("sha256", sha))


def _refused(path, match) -> str:
    with pytest.raises(CheckpointError, match=match) as ei:
        load_model(path)
    msg = str(ei.value)
    assert "\n" not in msg and msg.strip() == msg
    return msg


def test_round_trip_identical_predictions(saved):
    folder, m, cfg = saved
    lm = load_model(folder)
    assert lm.config == cfg and lm.normalizer == m.normalizer and lm.geometry == m.geometry
    assert lm.training["epochs"] == 3 and "git_revision" in lm.training
    assert lm.model.dtype == torch.float64 and not lm.model.training
    assert not any(p.requires_grad for p in lm.model.parameters())
    a = predict_trials(m, CAMP)
    b = predict_campaign(folder, CAMP)
    c = predict_campaign(folder / META, CAMP)  # the JSON path works too
    assert a.keys() == b.keys() == set(CAMP.ids)
    for tid in a:
        for ch in ("vx", "yaw_rate", "ax", "ay"):
            assert np.array_equal(a[tid][ch], b[tid][ch]) and np.array_equal(b[tid][ch], c[tid][ch])
            assert a[tid][ch].shape == (CAMP[tid].n,)


def test_weights_are_plain_safetensors(saved):
    folder, m, _ = saved
    raw = (folder / WEIGHTS).read_bytes()
    assert raw[:2] != b"PK" and raw[:1] != b"\x80"  # neither a torch zip nor a pickle
    (hlen,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8 : 8 + hlen])
    header.pop("__metadata__", None)
    sd = m.state_dict()
    assert set(header) == set(sd)
    for k, v in header.items():
        assert v["dtype"] == "F64" and v["shape"] == list(sd[k].shape)
        a, b = v["data_offsets"]
        got = np.frombuffer(raw[8 + hlen + a : 8 + hlen + b], dtype="<f8")
        assert np.array_equal(got, sd[k].numpy().ravel())


def test_missing_folder_and_files(saved, tmp_path):
    folder, _, _ = saved
    _refused(tmp_path / "nowhere", "not found")
    (folder / WEIGHTS).unlink()
    _refused(folder, "model.safetensors: listed in SHA256SUMS but missing")
    (folder / META).unlink()
    _refused(folder, "not found")


def test_malformed_json(saved):
    folder, _, _ = saved
    (folder / META).write_text('{"format": "parknss-nss", ')
    _refused(folder, "model.json: differs from the SHA-256")
    write_manifest(folder)
    _refused(folder, "malformed JSON")


def test_json_that_is_not_an_object(saved):
    folder, _, _ = saved
    (folder / META).write_text("[1, 2]")
    write_manifest(folder)
    _refused(folder, "not a parknss NSS model")


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("format", "something-else", "not a parknss NSS model"),
        ("format_version", 99, "format version"),
        ("schema_version", "0", "schema version"),
    ],
)
def test_wrong_format_or_version(saved, key, value, match):
    folder, _, _ = saved
    _edit(folder, lambda d: d.__setitem__(key, value))
    _refused(folder, match)


def test_flipped_byte_and_truncation(saved):
    folder, _, _ = saved
    p = folder / WEIGHTS
    good = p.read_bytes()
    flipped = bytearray(good)
    flipped[len(good) // 2] ^= 0x01
    p.write_bytes(bytes(flipped))
    _refused(folder, "model.safetensors: differs from the SHA-256")
    write_manifest(folder)  # the manifest "fixed up": model.json's own hash still refuses
    _refused(folder, "SHA-256 mismatch")
    p.write_bytes(good[:-16])
    write_manifest(folder)
    _refused(folder, "SHA-256 mismatch")
    # a truncated file whose hashes were all "fixed up" is still refused, by its header
    _edit(
        folder, lambda d: d["weights"].__setitem__("sha256", hashlib.sha256(good[:-16]).hexdigest())
    )
    _refused(folder, "malformed safetensors header")


def test_weight_of_the_wrong_shape(saved):
    folder, _, _ = saved
    _edit(folder, lambda d: d["config"]["model"].__setitem__("state_units", 16))
    msg = _refused(folder, "has shape")
    assert "state_net.0." in msg
    _edit(folder, lambda d: d["config"]["model"].update(state_units=8, state_layers=3))
    _refused(folder, "has shape|weights lack|unexpected weight")


def test_invalid_config(saved):
    folder, _, _ = saved
    _edit(folder, lambda d: d["config"]["model"].__setitem__("integrator", "leapfrog"))
    _refused(folder, "invalid config field 'model.integrator'")


def test_normalizer_missing_a_channel(saved):
    folder, _, _ = saved
    _edit(folder, lambda d: d["normalizer"]["channels"].pop("brake_pressure"))
    _refused(folder, "normalizer lacks channel.*brake_pressure")


def test_normalizer_of_another_kind(saved):
    folder, _, _ = saved
    _edit(folder, lambda d: d["normalizer"].__setitem__("kind", "zscore"))
    _refused(folder, "normalizer kind 'zscore' does not match")
    _edit(folder, lambda d: d["normalizer"].update(kind="clipped", percentiles=[1.0, 99.0]))
    _refused(folder, "percentiles")


def test_malformed_normalizer(saved):
    folder, _, _ = saved
    _edit(folder, lambda d: d["normalizer"]["channels"]["vx"].__setitem__("scale", 0.0))
    _refused(folder, "normalizer is malformed")


@pytest.mark.parametrize("geometry", ["EXEED", [3.0], {"wheelbase": "long"}])
def test_invalid_geometry(saved, geometry):
    folder, _, _ = saved
    _edit(folder, lambda d: d.__setitem__("geometry", geometry))
    _refused(folder, "invalid vehicle geometry")


def test_float32_round_trip(tmp_path):
    m, cfg = tiny_model(CAMP, seed=2, dtype="float32")
    save_model(tmp_path, m, cfg)
    lm = load_model(tmp_path)
    assert lm.model.dtype == torch.float32 and lm.model.in_sc.dtype == torch.float32
    a, b = predict_trials(m, CAMP), predict_trials(lm.model, CAMP)
    assert all(np.array_equal(a[t][c], b[t][c]) for t in a for c in a[t])


def test_batched_prediction_equals_one_trial_at_a_time():
    """Padding to the longest trial does not leak into the shorter ones."""
    m, _ = tiny_model(CAMP, seed=5)
    both = predict_trials(m, CAMP)
    for tr in CAMP:
        one = predict_trials(m, [tr])[tr.id]
        for ch in ("vx", "yaw_rate", "ax", "ay"):
            np.testing.assert_allclose(both[tr.id][ch], one[ch], rtol=0, atol=1e-12)
        assert both[tr.id]["vx"][0] == pytest.approx(tr["vx"][0], abs=1e-12)
    assert predict_trials(m, []) == {}


def test_tampered_model_json_is_refused_by_the_manifest(saved):
    """Issue 43: a normaliser scale edited (39 -> 3.9) was used silently."""
    folder, _, _ = saved
    assert (folder / MANIFEST).read_text().splitlines() == [
        f"{hashlib.sha256((folder / n).read_bytes()).hexdigest()}  {n}" for n in (META, WEIGHTS)]
    _edit(folder, lambda d: d["normalizer"]["channels"]["vx"].__setitem__(
        "scale", d["normalizer"]["channels"]["vx"]["scale"] / 10), reseal=False)
    msg = _refused(folder, "model.json: differs from the SHA-256 its SHA256SUMS records")
    assert "refusing the artefact" in msg
    (folder / MANIFEST).unlink()
    _refused(folder, "no SHA256SUMS .*sha256sum")
    (folder / MANIFEST).write_text(f"{'0' * 64}  ../../etc/passwd\n")
    _refused(folder, "malformed line 1")
    (folder / MANIFEST).write_text(f"{'0' * 64}  {WEIGHTS}\n")
    _refused(folder, "does not list model.json")


def test_weights_swapped_for_another_models_are_refused(saved, tmp_path):
    folder, _, _ = saved
    other, cfg = tiny_model(CAMP, seed=8)
    save_model(tmp_path / "other", other, cfg)
    (folder / WEIGHTS).write_bytes((tmp_path / "other" / WEIGHTS).read_bytes())
    _refused(folder, "model.safetensors: differs from the SHA-256 its SHA256SUMS")


@pytest.mark.parametrize("field", ["state_units", "state_layers", "output_units", "output_layers"])
def test_a_huge_config_is_refused_before_the_model_is_built(saved, field, monkeypatch):
    """Issue 43: 200000 units or layers built the model first (a 160 GB allocation)."""
    import parknss.nss.checkpoint as ckpt

    folder, _, _ = saved
    monkeypatch.setattr(ckpt, "NSSModel", lambda *a, **k: pytest.fail("model built"))
    _edit(folder, lambda d: d["config"]["model"].__setitem__(field, 200000))
    limit = MAX_UNITS if field.endswith("units") else MAX_LAYERS
    _refused(folder, f"model.{field} = 200000 exceeds the limit {limit}")


def test_shapes_are_checked_from_the_header_before_loading(saved, monkeypatch):
    import parknss.nss.checkpoint as ckpt

    folder, _, _ = saved
    monkeypatch.setattr(ckpt, "load_file", lambda *a, **k: pytest.fail("tensors loaded"))
    _edit(folder, lambda d: d["config"]["model"].__setitem__("state_units", 16))
    _refused(folder, "has shape")


def test_int32_weights_are_refused(saved):
    """Issue 43: weights stored as int32 ended in a TypeError."""
    folder, m, _ = saved
    _set_weights(folder, {k: v.to(torch.int32) for k, v in m.state_dict().items()})
    _refused(folder, "is stored as I32; parknss weights are F32 or F64")
    sd = m.state_dict()
    first = sorted(sd)[0]
    _set_weights(folder, {k: v.float() if k == first else v for k, v in sd.items()})
    _refused(folder, "weights mix dtypes F32, F64")


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_weights_are_refused(saved, tmp_path, bad):
    """Issue 43: a NaN weight made every metric null with exit 0."""
    _, m, cfg = saved
    with torch.no_grad():
        m.state_net[0].weight[0, 0] = bad
    save_model(tmp_path / "nan", m, cfg)
    _refused(tmp_path / "nan", "weight 'state_net.0.weight' holds NaN or infinite values")


def test_a_malformed_header_is_refused(saved):
    folder, _, _ = saved
    raw = (folder / WEIGHTS).read_bytes()
    for blob in (b"\xff" * 8 + raw[8:], raw[:8] + b"[" + raw[9:], b"\x01\x00"):
        (folder / WEIGHTS).write_bytes(blob)
        sha = hashlib.sha256(blob).hexdigest()
        _edit(folder, lambda d, sha=sha: d["weights"].__setitem__("sha256", sha))
        _refused(folder, "malformed safetensors header")


def test_save_over_an_existing_model_replaces_it_whole(saved):
    folder, _, _ = saved
    other, cfg = tiny_model(CAMP, seed=9)
    (folder / "stray.txt").write_text("old")
    save_model(folder, other, cfg)
    assert sorted(p.name for p in folder.iterdir()) == [MANIFEST, META, WEIGHTS]
    assert [p.name for p in folder.parent.iterdir() if p.name.startswith(".")] == []
    assert torch.equal(load_model(folder).model.state_net[0].weight, other.state_net[0].weight)
