"""Readers/writers, campaigns, mapping and import: round trips and malformed logs."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import scipy.io

from helpers.kinematic import kinematic_trial
from parknss.cli import main
from parknss.config import CONFIG_DIR
from parknss.data.io import (
    import_folder,
    read_campaign,
    read_trial,
    write_campaign,
    write_trial,
    write_trial_csv,
    write_trial_mat,
    write_trial_parquet,
)
from parknss.data.mapping import load_mapping
from parknss.data.trial import Campaign, Trial
from parknss.errors import ConfigError, DataError, ParknssError
from parknss.signals import DEG_PER_RAD, KMH_PER_MS, REQUIRED_CHANNELS, G

EXAMPLE_MAPPING = CONFIG_DIR / "mapping_example.yaml"


def _same(a: Trial, b: Trial, atol: float = 1e-9) -> None:
    assert set(a.channels) == set(b.channels)
    for name in a.channels:
        np.testing.assert_allclose(b[name], a[name], rtol=0, atol=atol, err_msg=name)


def _modified(tr: Trial, drop: str | None = None, **changes) -> Trial:
    ch = {k: v.copy() for k, v in tr.channels.items() if k != drop}
    ch.update(changes)
    return Trial(tr.id, tr.maneuver, tr.repetition, ch, tr.vehicle_id, provenance=tr.provenance)


# ------------------------------------------------------------------ round trips


def test_round_trip_parquet_csv_mat_parquet_is_lossless(trial, tmp_path):
    p1 = write_trial_parquet(trial, tmp_path / "a.parquet")
    c = write_trial_csv(read_trial(p1), tmp_path / "b.csv")
    m = write_trial_mat(read_trial(c), tmp_path / "c.mat")
    p2 = write_trial(read_trial(m), tmp_path / "d.parquet")
    back = read_trial(p2)
    _same(trial, back, atol=1e-9)
    assert all(np.array_equal(trial[k], back[k]) for k in trial.channels)  # in fact exact
    assert (back.id, back.maneuver, back.repetition, back.vehicle_id, back.provenance) == (
        trial.id,
        trial.maneuver,
        trial.repetition,
        trial.vehicle_id,
        trial.provenance,
    )
    assert pq.read_table(p2).column_names[: len(REQUIRED_CHANNELS)] == list(REQUIRED_CHANNELS)


def test_campaign_round_trip(trial, tmp_path):
    other = kinematic_trial(ratio=13.0, duration_s=21.0, trial_id="park_out_right_r2")
    camp = Campaign([trial, other], name="mini", meta={"synthetic": True, "seed": 3})
    write_campaign(camp, tmp_path / "c")
    index = json.loads((tmp_path / "c" / "campaign.json").read_text())
    assert index["schema_version"] == "1" and index["trials"][1]["n_samples"] == 2100
    back = read_campaign(tmp_path / "c")
    assert back.ids == camp.ids and back.name == "mini" and back.meta == camp.meta
    assert back.data_hash() == camp.data_hash()
    _same(other, back["park_out_right_r2"], atol=0.0)
    assert read_campaign(tmp_path / "c" / "campaign.json").ids == camp.ids


def test_write_campaign_refuses_invalid_trial(trial, tmp_path):
    g = trial["gear"].copy()
    g[9] = 2
    with pytest.raises(DataError, match=r"park_in_left_r1\.parquet: channel 'gear': value 2"):
        write_campaign(Campaign([_modified(trial, gear=g)]), tmp_path / "c")
    assert not (tmp_path / "c" / "campaign.json").exists()


def test_mat_single_struct_of_row_vectors(trial, tmp_path):
    """The other documented .mat layout: one struct whose fields are 1 x T channels."""
    fields = {k: v.reshape(1, -1) for k, v in trial.channels.items()}
    scipy.io.savemat(tmp_path / "park_in_left_r2.mat", {"log": fields})
    back = read_trial(tmp_path / "park_in_left_r2.mat")
    assert (back.id, back.repetition) == ("park_in_left_r2", 2)
    _same(trial, back, atol=0.0)


def test_newer_schema_version_is_refused(trial, tmp_path):
    p = write_trial_csv(trial, tmp_path / "x_r1.csv")
    p.write_text(p.read_text().replace('"schema_version": "1"', '"schema_version": "9"'))
    with pytest.raises(DataError, match="written with schema version '9'"):
        read_trial(p)


# --------------------------------------------------------------- campaign errors


def _campaign(tmp_path: Path, trial: Trial) -> Path:
    return write_campaign(Campaign([trial], name="one"), tmp_path / "camp")


def test_read_campaign_errors(trial, tmp_path):
    with pytest.raises(DataError, match="campaign folder not found"):
        read_campaign(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match=r"no campaign\.json"):
        read_campaign(tmp_path / "empty")
    camp = _campaign(tmp_path, trial)
    pfile = camp / "park_in_left_r1.parquet"
    good = pfile.read_bytes()
    cases = [
        (b"", "empty file"),
        (good[: len(good) // 2], "not a readable Parquet file, corrupt or truncated"),
        (b"PAR1 this is not parquet at all PAR1", "not a readable Parquet file"),
    ]
    for content, expected in cases:
        pfile.write_bytes(content)
        with pytest.raises(DataError, match=expected) as exc:
            read_campaign(camp)
        assert str(pfile) in str(exc.value) and "\n" not in str(exc.value)
    write_trial_parquet(trial.slice(0, 2000), pfile)  # valid Parquet, fewer rows than indexed
    with pytest.raises(DataError, match=r"channel 't': 2000 samples, campaign\.json says 3000"):
        read_campaign(camp)
    pfile.write_bytes(good)
    index = camp / "campaign.json"
    doc = json.loads(index.read_text())
    index.write_text(index.read_text()[:-20])
    with pytest.raises(DataError, match=r"campaign\.json: not valid JSON"):
        read_campaign(camp)
    del doc["trials"][0]["file"]
    index.write_text(json.dumps(doc))
    with pytest.raises(DataError, match=r"field 'trials\.0\.file': Field required"):
        read_campaign(camp)


def test_describe_cli_on_missing_campaign(tmp_path, capsys):
    assert main(["campaign", "describe", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "campaign folder not found" in err


# ------------------------------------------------------------------------ import


def test_import_by_file_names_mixed_formats(trial, tmp_path):
    src = tmp_path / "logs"
    src.mkdir()
    b = kinematic_trial(ratio=12.5, trial_id="park_out_left_r2")
    write_trial_csv(trial, src / "park_in_left_r3.csv")  # name wins over the file's metadata
    write_trial_mat(b, src / "park_out_left_r2.mat")
    camp = import_folder(src)
    assert camp.ids == ["park_in_left_r3", "park_out_left_r2"]
    assert camp["park_in_left_r3"].repetition == 3 and camp.name == "logs"
    assert camp.meta["synthetic"] is False and "vehicle_geometry" not in camp.meta
    prov = json.loads(camp["park_out_left_r2"].provenance)
    assert prov["imported_from"].endswith("park_out_left_r2.mat") and len(prov["sha256"]) == 64
    _same(b, camp["park_out_left_r2"], atol=0.0)


def test_import_with_manifest(trial, tmp_path):
    src = tmp_path / "logs"
    src.mkdir()
    write_trial_parquet(trial, src / "log_a.parquet")
    write_trial_csv(trial, src / "log_b.csv")
    (src / "manifest.csv").write_text(
        "file,class,repetition\nlog_b.csv,my_class,2\nlog_a.parquet,my_class,1\n"
    )
    camp = import_folder(src)
    assert camp.ids == ["my_class_r2", "my_class_r1"]
    assert [t.repetition for t in camp.by_class()["my_class"]] == [1, 2]


def _csv_in_example_layout(tr: Trial, path: Path) -> None:
    """The trial as a log of configs/mapping_example.yaml: other names, units, codes,
    dialect, four unsigned wheel speeds, raw brake counts, a steering start-up sentinel,
    no command channels."""
    gear_code = {-1.0: "R", 0.0: "P", 1.0: "D"}
    speed = np.abs(tr["vx"]) * KMH_PER_MS
    steer = tr["steer"].copy()
    steer[:50] = 3276.7  # the first 0.5 s: the sensor's start-up value
    cols = {
        "Timestamp": tr["t"] * 1000.0 + 1.7e9,
        "WhlSpdFL": speed - 0.01,
        "WhlSpdFR": speed + 0.01,
        "WhlSpdRL": speed + 0.02,
        "WhlSpdRR": speed - 0.02,
        "YawRate": -tr["yaw_rate"] * DEG_PER_RAD,
        "AccX": tr["ax"] / G,
        "AccY": tr["ay"] / G,
        "BrkPrsRaw": tr["brake_pressure"] / 0.1,
        "MotTrq": tr["torque"],
        "StrWhlAng": steer,
        "Unused": np.zeros(tr.n),
    }
    lines = [";".join([*cols, "GearPos"])]
    for i in range(tr.n):
        vals = [repr(float(v[i])).replace(".", ",") for v in cols.values()]
        lines.append(";".join([*vals, gear_code[tr["gear"][i]]]))
    path.write_text("\n".join(lines) + "\n")


def test_import_with_example_mapping_recovers_schema_units(trial, tmp_path, capsys):
    src = tmp_path / "logs"
    src.mkdir()
    _csv_in_example_layout(trial, src / "park_in_right_r1.csv")
    camp = import_folder(src, mapping=EXAMPLE_MAPPING)
    got = camp["park_in_right_r1"]
    assert camp.meta["absent_channels"] == ["torque_cmd", "decel_cmd", "steer_cmd"]
    assert got.n == trial.n - 50  # the sentinel's 0.5 s are cropped off the start
    assert got["t"][0] == 0.0  # start_at_zero after the crop
    for name in got.channels:
        ref = trial[name][50:] - (trial["t"][50] if name == "t" else 0.0)
        np.testing.assert_allclose(got[name], ref, rtol=0, atol=1e-6, err_msg=name)
    assert got.vehicle_id == "my_car" and camp.meta["vehicle_geometry"]["wheelbase"] == 2.9
    out = tmp_path / "camp"
    args = ["campaign", "import", str(src), "--out", str(out), "--mapping", str(EXAMPLE_MAPPING)]
    assert main(args) == 0
    assert main(["campaign", "describe", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["trials"][0]["id"] == "park_in_right_r1" and doc["direction_changes"] == 1
    assert doc["wheelbase_m"] == 2.9


def test_mapping_unit_of_the_wrong_kind_is_a_config_error(tmp_path):
    bad = tmp_path / "m.yaml"
    bad.write_text("channels:\n  vx: {column: VehSpd, unit: deg/s}\n")
    with pytest.raises(ConfigError, match=r"channel 'vx': unit 'deg/s' cannot be converted"):
        load_mapping(bad)
    bad.write_text("channels:\n  vx: {column: VehSpd, unit: furlong/fortnight}\n")
    with pytest.raises(ConfigError, match="channel 'vx': unknown unit 'furlong/fortnight'"):
        load_mapping(bad)
    bad.write_text("channels:\n  speed: {column: VehSpd}\n")
    with pytest.raises(ConfigError, match="channel 'speed': not a schema channel"):
        load_mapping(bad)
    bad.write_text("gear_values: {R: -2}\n")
    with pytest.raises(ConfigError, match="gear_values: 'R' -> -2"):
        load_mapping(bad)


# -------------------------------------------------------------- malformed logs

Case = Callable[[Trial, Path], Path | None]  # writes the bad log into the folder; mapping or None


def _csv(tr: Trial, src: Path, name: str = "park_in_left_r1.csv") -> Path:
    return write_trial_csv(tr, src / name)


def _truncated(tr, src):
    text = _csv(tr, src).read_text()
    cut = text.index(",", text.index("\n", len(text) * 3 // 5) + 1) + 1
    (src / "park_in_left_r1.csv").write_text(text[:cut])


def _nan(tr, src):
    vx = tr["vx"].copy()
    vx[[321, 322]] = np.nan
    _csv(_modified(tr, vx=vx), src)


def _missing(tr, src):
    _csv(_modified(tr, drop="ay"), src)


def _backwards(tr, src):
    t = tr["t"].copy()
    t[1500:] -= 0.5
    _csv(_modified(tr, t=t), src)


def _gear2(tr, src):
    g = tr["gear"].copy()
    g[2000] = 2.0
    _csv(_modified(tr, gear=g), src)


def _duplicate(tr, src):
    t = tr["t"].copy()
    t[700] = t[699]
    _csv(_modified(tr, t=t), src)


def _empty(tr, src):
    (src / "park_in_left_r1.csv").write_bytes(b"")


def _wrong_units(tr, src):
    ch = {k: v for k, v in tr.channels.items() if k != "yaw_rate"}
    ch["YawRate"] = tr["yaw_rate"] * DEG_PER_RAD  # logged in deg/s ...
    write_trial_csv(Trial(tr.id, tr.maneuver, 1, ch), src / "park_in_left_r1.csv")
    m = src.parent / "mapping.yaml"
    m.write_text("channels:\n  yaw_rate: {column: YawRate, unit: rad/s}\n")  # ... mapped as rad/s
    return m


def _incompatible_unit(tr, src):
    _csv(tr, src)
    m = src.parent / "mapping.yaml"
    m.write_text("channels:\n  brake_pressure: {column: brake_pressure, unit: km/h}\n")
    return m


def _text(tr, src):
    p = _csv(tr, src)
    lines = p.read_text().splitlines()
    fields = lines[102].split(",")
    fields[REQUIRED_CHANNELS.index("vx")] = "abc"
    lines[102] = ",".join(fields)
    p.write_text("\n".join(lines) + "\n")


def _corrupt_parquet(tr, src):
    data = write_trial_parquet(tr, src / "park_in_left_r1.parquet").read_bytes()
    (src / "park_in_left_r1.parquet").write_bytes(data[: len(data) // 3])


def _corrupt_mat(tr, src):
    data = write_trial_mat(tr, src / "park_in_left_r1.mat").read_bytes()
    (src / "park_in_left_r1.mat").write_bytes(data[:200])


def _manifest_missing_column(tr, src):
    _csv(tr, src, "a.csv")
    (src / "manifest.csv").write_text("file,class\na.csv,park_in_left\n")


def _manifest_missing_file(tr, src):
    _csv(tr, src, "a.csv")
    (src / "manifest.csv").write_text("file,class,repetition\na.csv,x,1\nb.csv,x,2\n")


def _manifest_bad_repetition(tr, src):
    _csv(tr, src, "a.csv")
    (src / "manifest.csv").write_text("file,class,repetition\na.csv,x,first\n")


def _unmapped_gear_code(tr, src):
    codes = np.where(tr["gear"] < 0, "R", np.where(tr["gear"] > 0, "L", "P"))
    lines = _csv(tr, src).read_text().splitlines()
    gi = REQUIRED_CHANNELS.index("gear")
    for i in range(tr.n):
        f = lines[2 + i].split(",")
        f[gi] = str(codes[i])
        lines[2 + i] = ",".join(f)
    (src / "park_in_left_r1.csv").write_text("\n".join(lines) + "\n")
    m = src.parent / "mapping.yaml"
    m.write_text("gear_values: {R: -1, N: 0, P: 0, D: 1}\n")
    return m


# (case, file named in the message, fragments the one line must contain)
MALFORMED: dict[str, tuple[Case, str, tuple[str, ...]]] = {
    "truncated": (
        _truncated,
        "park_in_left_r1.csv",
        ("(the last): 2 fields, the header has 13 (truncated file?)",),
    ),
    "nan": (_nan, "park_in_left_r1.csv", ("channel 'vx': 2 NaN values (first at line 324)",)),
    "missing_channel": (_missing, "park_in_left_r1.csv", ("channel 'ay': missing",)),
    "time_backwards": (
        _backwards,
        "park_in_left_r1.csv",
        ("channel 't': time goes backwards at 1 steps (first from t=14.99 s to t=14.50 s)",),
    ),
    "gear_2": (_gear2, "park_in_left_r1.csv", ("channel 'gear': value 2 at t=20.00 s",)),
    "duplicate_t": (_duplicate, "park_in_left_r1.csv", ("channel 't': 1 duplicate timestamps",)),
    "empty_file": (_empty, "park_in_left_r1.csv", ("empty file",)),
    "wrong_units": (
        _wrong_units,
        "park_in_left_r1.csv",
        ("channel 'yaw_rate'", "plausible range", "column 'YawRate' in 'rad/s'", "unit"),
    ),
    "incompatible_unit": (
        _incompatible_unit,
        "mapping.yaml",
        ("channel 'brake_pressure': unit 'km/h' cannot be converted",),
    ),
    "non_numeric": (
        _text,
        "park_in_left_r1.csv",
        ("channel 'vx': non-numeric value 'abc' at line 103",),
    ),
    "corrupt_parquet": (
        _corrupt_parquet,
        "park_in_left_r1.parquet",
        ("not a readable Parquet file",),
    ),
    "corrupt_mat": (_corrupt_mat, "park_in_left_r1.mat", ("not a readable MATLAB file",)),
    "manifest_column": (
        _manifest_missing_column,
        "manifest.csv",
        ("column 'repetition' missing",),
    ),
    "manifest_file": (_manifest_missing_file, "manifest.csv", ("line 3: file 'b.csv' not found",)),
    "manifest_repetition": (
        _manifest_bad_repetition,
        "manifest.csv",
        ("repetition 'first' is not an integer",),
    ),
    "unmapped_gear_code": (
        _unmapped_gear_code,
        "park_in_left_r1.csv",
        ("channel 'gear': value 'L' at line", "not in gear_values"),
    ),
}


@pytest.mark.parametrize("kind", sorted(MALFORMED))
def test_malformed_log_gives_one_clear_line(kind, trial, tmp_path, capsys):
    case, fname, fragments = MALFORMED[kind]
    src = tmp_path / "logs"
    src.mkdir()
    write_trial_csv(kinematic_trial(trial_id="park_out_left_r1"), src / "park_out_left_r1.csv")
    if "manifest" in kind:
        (src / "park_out_left_r1.csv").unlink()
    mapping = case(trial, src)

    with pytest.raises(ParknssError) as exc:  # the library
        import_folder(src, mapping=mapping)
    msg = str(exc.value)
    assert "\n" not in msg and fname in msg, msg
    for frag in fragments:
        assert frag in msg, msg

    out = tmp_path / "camp"  # the CLI
    args = ["campaign", "import", str(src), "--out", str(out)]
    assert main(args + (["--mapping", str(mapping)] if mapping else [])) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and captured.err == f"parknss: error: {msg}\n"
    assert captured.out == "" and not (out / "campaign.json").exists()
