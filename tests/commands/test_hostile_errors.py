"""Failures a user can cause are one line ``parknss: error: ...`` with exit status 2,
never a traceback: an unreadable input file, an ``--out`` that cannot be written (under a
regular file, on /proc, in a read-only folder) refused before the work, a full disk
(partial output removed), a 100000-level nested JSON or YAML, vehicle parameters outside
their physical ranges (the range in the message)."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
import yaml

import parknss.data.io as data_io
import parknss.outputs as outputs
from parknss.cli import main
from parknss.config import MAX_NESTING, nesting_depth, parse_json
from parknss.errors import ConfigError
from parknss.reference.params import load_vehicle_params
from parknss.sim.scenarios import grid_scene
from parknss.vehicle_ranges import RANGES, check_vehicle

DEEP_JSON = "[" * 100_000 + "]" * 100_000


def _line(capsys) -> str:
    """The one ``parknss:`` line on stderr (after any progress bar), the last one."""
    err = [ln for ln in capsys.readouterr().err.replace("\r", "\n").splitlines() if ln.strip()]
    ours = [ln for ln in err if ln.startswith("parknss:")]
    assert ours == err[-1:] and ours[0].startswith("parknss: error: "), err[-3:]
    assert not any("Traceback" in ln for ln in err)
    return ours[0]


def _scene(path: Path, **meta) -> Path:
    doc = grid_scene(14).to_json()
    doc["meta"].update(meta)
    path.write_text(json.dumps(doc))
    return path


# ----------------------------------------------------------------------- vehicle ranges


@pytest.mark.parametrize(("key", "value", "shown"), [
    ("steer_lock_deg", 100000, "steer_lock_deg: 100000 is outside the physical range "
     "[90, 1440] deg of steering-wheel angle"),
    ("wheelbase", 1e-9, "wheelbase: 1e-09 is outside the physical range [1.5, 7] m"),
    ("track", 40.0, "[0.9, 2.6] m"),
    ("length", 30.0, "[2, 15] m"),
    ("width", 5.0, "width: 5 is outside the physical range [1, 3] m"),
])
def test_a_vehicle_yaml_out_of_range_is_refused_with_the_range(key, value, shown, tmp_path,
                                                              capsys):
    car = tmp_path / "car.yaml"
    car.write_text(yaml.safe_dump({"geometry": {key: value}}))
    scene = _scene(tmp_path / "s.json")
    assert main(["plan", "--scene", str(scene), "--vehicle", str(car), "--out",
                 str(tmp_path / "out")]) == 2
    assert shown in _line(capsys)
    assert not (tmp_path / "out").exists()


def test_derived_quantities_are_ranged():
    with pytest.raises(ConfigError, match=r"road_wheel_lock_deg .* \[10, 60\] deg"):
        check_vehicle({"steer_lock_deg": 1400.0, "steer_ratio_lock": 12.0}, "car")
    with pytest.raises(ConfigError, match=r"front_overhang .* \[0.1, 5\] m"):
        check_vehicle({"length": 4.0, "wheelbase": 3.0, "rear_overhang": 1.0}, "car")
    check_vehicle({"wheelbase": 2.8, "steer_lock_deg": 520.0, "steer_ratio_lock": 12.1}, "ok")


def test_reference_vehicle_mass_is_ranged(tmp_path, capsys):
    car = tmp_path / "ref.yaml"
    car.write_text(yaml.safe_dump({"body": {"mass_kg": 1.0e9}}))
    with pytest.raises(ConfigError, match=r"mass_kg: 1e\+09 is outside .*\[300, 20000\] kg"):
        load_vehicle_params(car)
    assert main(["campaign", "generate", "--out", str(tmp_path / "c"), "--vehicle",
                 str(car)]) == 2
    assert "mass_kg" in _line(capsys)
    assert set(RANGES) >= {"wheelbase", "track", "steer_lock_deg", "mass_kg", "length",
                           "width", "rear_overhang", "wheel_radius_m"}


def test_an_import_mapping_geometry_is_ranged(tmp_path):
    from parknss.data.mapping import load_mapping

    m = tmp_path / "map.yaml"
    m.write_text(yaml.safe_dump({"vehicle": {"geometry": {"steer_lock_deg": 100000}}}))
    with pytest.raises(ConfigError, match=r"\[90, 1440\]"):
        load_mapping(m)


# ------------------------------------------------------------------------- nested input


def test_json_depth_is_limited_in_one_place():
    with pytest.raises(ConfigError, match=f"nested deeper than {MAX_NESTING}"):
        parse_json(DEEP_JSON, "deep.json")
    shallow_but_too_deep = "[" * (MAX_NESTING + 1) + "]" * (MAX_NESTING + 1)
    with pytest.raises(ConfigError, match="nested deeper"):
        parse_json(shallow_but_too_deep, "d.json")
    assert nesting_depth(parse_json('{"a": [1, {"b": []}]}', "ok")) == 4


def test_a_deeply_nested_scene_config_and_campaign_are_one_line(tmp_path, capsys):
    deep = tmp_path / "deep.json"
    deep.write_text(DEEP_JSON)
    assert main(["plan", "--scene", str(deep), "--out", str(tmp_path / "o")]) == 2
    assert "nested deeper than" in _line(capsys)
    cfg = tmp_path / "deep.yaml"
    cfg.write_text("a: " + "[" * 100_000 + "]" * 100_000)
    assert main(["plan", "--scene", "14", "--config", str(cfg), "--out",
                 str(tmp_path / "o")]) == 2
    assert "nested deeper than" in _line(capsys)
    camp = tmp_path / "camp"
    camp.mkdir()
    (camp / "campaign.json").write_text(DEEP_JSON)
    assert main(["campaign", "describe", str(camp)]) == 2
    assert "nested deeper than" in _line(capsys)


def test_a_deeply_nested_manifest_is_no_manifest(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text(DEEP_JSON)
    assert outputs.read_manifest(out) is None
    assert main(["plan", "--scene", "14", "--no-refine", "--out", str(out)]) == 2
    assert "holds a run (1 entry) already" in _line(capsys)


# --------------------------------------------------------------------------- unreadable


def test_an_unreadable_scene_is_one_line(tmp_path, capsys, monkeypatch):
    scene = _scene(tmp_path / "s.json")
    real = Path.read_bytes

    def denied(self):
        if self == scene:
            raise PermissionError(errno.EACCES, "Permission denied", str(self))
        return real(self)

    monkeypatch.setattr(Path, "read_bytes", denied)
    assert main(["plan", "--scene", str(scene)]) == 2
    assert _line(capsys).endswith(f"{scene}: cannot read (Permission denied)")


def test_an_unreadable_log_is_one_line(tmp_path, capsys, monkeypatch):
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "park_in_left_r1.csv").write_text("t,vx\n0,0\n")

    def denied(path, *_a, **_k):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(data_io, "_read_log", denied)
    assert main(["campaign", "import", str(logs), "--out", str(tmp_path / "c")]) == 2
    assert _line(capsys).endswith("park_in_left_r1.csv: Permission denied")
    assert not (tmp_path / "c").exists()


# ------------------------------------------------------------------ --out that cannot be


def _commands(tmp_path: Path, out: Path) -> list[list[str]]:
    logs = tmp_path / "logs"
    logs.mkdir(exist_ok=True)
    return [
        ["campaign", "import", str(logs), "--out", str(out)],
        ["campaign", "generate", "--out", str(out)],
        ["plan", "--scene", "14", "--out", str(out)],
        ["evaluate", "--out", str(out)],
        ["export", "onnx", "--out", str(out)],
    ]


@pytest.fixture
def no_work(monkeypatch):
    """The work of each command fails the test if it starts (the refusal comes first)."""
    import parknss.experiments.evaluate as evaluate
    import parknss.export.onnx_step as onnx_step
    import parknss.reference.campaign as ref_campaign
    import parknss.sim.planner as planner

    def started(*_a, **_k):
        raise AssertionError("the work started before --out was checked")

    monkeypatch.setattr(planner, "plan_named_scene", started)  # imported where used
    monkeypatch.setattr(onnx_step, "step_module", started)
    monkeypatch.setattr(ref_campaign, "generate_campaign", started)
    monkeypatch.setattr(data_io, "import_folder", started)
    monkeypatch.setattr(evaluate, "predict_trials", started)


@pytest.mark.parametrize("where", ["under a file", "on /proc"])
def test_an_unwritable_out_is_refused_before_the_work(where, tmp_path, capsys, no_work):
    afile = tmp_path / "afile"
    afile.write_text("x")
    out = afile / "sub" / "x.onnx" if where == "under a file" else Path("/proc/parknss-x")
    for argv in _commands(tmp_path, out):
        assert main(argv) == 2, argv
        line = _line(capsys)
        assert ("is a file, not a folder" if where == "under a file"
                else "cannot write in /proc") in line, (argv, line)
    assert afile.read_text() == "x" and sorted(p.name for p in tmp_path.iterdir()) == [
        "afile", "logs"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_out_is_refused_before_the_work(tmp_path, capsys, no_work):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        for argv in _commands(tmp_path, ro / "out"):
            assert main(argv) == 2, argv
            assert "cannot write in" in _line(capsys)
    finally:
        ro.chmod(0o755)


def test_export_onto_a_folder_is_refused_before_the_work(tmp_path, capsys, no_work):
    assert main(["export", "onnx", "--out", str(tmp_path)]) == 2
    assert "is a folder; --out names the file to write" in _line(capsys)


# ----------------------------------------------------------------------------- full disk


def _full(*_a, **_k):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_in_campaign_generate_leaves_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(data_io, "write_trial_parquet", _full)
    out = tmp_path / "deep" / "camp"
    assert main(["campaign", "generate", "--out", str(out)]) == 2
    assert _line(capsys).endswith("No space left on device")
    assert list(tmp_path.iterdir()) == []  # no folder, no temporary folder


def test_a_full_disk_in_plan_removes_the_partial_run(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(outputs, "write_text_atomic", _full)
    out = tmp_path / "deep" / "plan"
    assert main(["plan", "--scene", "14", "--no-refine", "--out", str(out)]) == 2
    assert _line(capsys).endswith("No space left on device")
    assert list(tmp_path.iterdir()) == []  # the figure written before is gone too
