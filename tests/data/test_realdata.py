"""Real cars' public logs (../shared/realdata, read in place) import as published with the
shipped mappings in configs/mappings/, and describe says what they support."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from helpers.paths import CANEDGE, KONA
from parknss.cli import main
from parknss.config import CONFIG_DIR
from parknss.data.describe import describe_campaign
from parknss.data.io import import_folder, read_campaign
from parknss.data.mapping import load_mapping
from parknss.data.trial import UNLABELLED
from parknss.errors import ParknssError
from parknss.signals import DEG_PER_RAD

MAPPINGS = CONFIG_DIR / "mappings"

pytestmark = [
    pytest.mark.filterwarnings("ignore::UserWarning"),
    pytest.mark.realdata,
]


@pytest.fixture(scope="module")
def kona(realdata):
    return import_folder(realdata / "kona_ev_2019", MAPPINGS / "kona_ev_2019.yaml")


@pytest.fixture(scope="module")
def css(realdata):
    return import_folder(
        realdata / "css_canedge_gnss_imu" / "raw_mf4", MAPPINGS / "css_canedge_gnss_imu.yaml"
    )


def _file_prov(tr) -> dict:
    return json.loads(json.loads(tr.provenance)["file_provenance"])


def test_kona_gvret_capture_imports_as_published(kona):
    assert len(kona) == 1
    tr = kona[0]
    assert tr.maneuver == UNLABELLED and tr.vehicle_id == "hyundai_kona_ev_2019"
    assert kona.meta["absent_channels"] == ["torque_cmd", "torque", "decel_cmd", "steer_cmd"]
    prov = _file_prov(tr)
    assert prov["format"] == "gvret" and prov["dbc_warnings"]  # lenient DBC, said so
    # the gateway forwards these onto the second bus: one copy kept, the other dropped
    assert prov["duplicates_dropped"]["StabilityControl"] == 679
    assert prov["duplicates_dropped"]["Steering"] == 863
    # start-up values masked: the trial starts when the ESC's values are valid
    assert prov["span_s"][0] == pytest.approx(3.66, abs=0.01)
    assert prov["masked_samples"]["channel 'steer' (message 'Steering', signal 'Angle')"] == 39
    assert np.all(tr["vx"] == 0.0) and np.all(tr["gear"] == 0.0)  # parked, gear P
    assert np.all(np.abs(tr["steer"] - 40.0) < 1.0)  # no 3276.7 left
    assert np.all(np.abs(tr["yaw_rate"] * DEG_PER_RAD) < 1.0)  # no -40.95 left
    assert 19.0 < tr["brake_pressure"].mean() < 21.0  # "Bar" read as bar


def test_kona_describe_says_what_is_missing(kona):
    d = describe_campaign(kona)
    assert d.workflows["nss"].ok is False and d.workflows["nss"].missing == ("torque",)
    assert not d.workflows["actuators"].ok
    assert d.outside_parking_domain == []


def test_kona_strict_dbc_is_one_line(tmp_path, capsys):
    doc = yaml.safe_load((MAPPINGS / "kona_ev_2019.yaml").read_text())
    doc["can"]["strict_dbc"] = True
    doc["can"]["dbc"] = str(KONA / "pcan.dbc")
    m = tmp_path / "strict.yaml"
    m.write_text(yaml.safe_dump(doc))
    with pytest.raises(ParknssError) as exc:
        import_folder(KONA, m)
    assert "pcan.dbc" in str(exc.value) and "\n" not in str(exc.value)
    assert main(["campaign", "import", str(KONA), "--out", str(tmp_path / "c"),
                 "--mapping", str(m)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len([ln for ln in err if ln.startswith("parknss: error:")]) == 1
    assert "Traceback" not in "\n".join(err)


def test_css_bus_logging_mf4_imports_as_published(css):
    assert css.ids == ["00000005-60FEBFEB", "00000006-60FFE42F"]
    a = css[0]
    assert set(a.channels) >= {"t", "gear", "vx", "yaw_rate", "ax", "ay"}
    assert 598.0 < a.duration_s < 601.0
    # the GNSS speed is interpolated between epochs, never negative (gear constant 1)
    assert a["vx"].min() >= 0.0 and a["vx"].max() == pytest.approx(21.145, abs=0.01)
    assert np.count_nonzero(np.diff(a["vx"]) == 0.0) < 0.05 * a.n  # not a staircase
    # IMU axes as measured: X vertical, ax = -AccelerationY; gravity is not in ax
    assert abs(np.mean(a["ax"])) < 1.0 and abs(np.mean(a["ay"])) < 1.5
    assert _file_prov(a)["format"].startswith("mdf")


def test_css_describe_and_the_cli(css, tmp_path, capsys):
    out = tmp_path / "css"
    args = ["campaign", "import", str(CANEDGE / "raw_mf4"), "--out", str(out),
            "--mapping", str(MAPPINGS / "css_canedge_gnss_imu.yaml")]
    assert main(args) == 0
    assert len(read_campaign(out)) == 2
    d = describe_campaign(css)
    assert d.workflows["nss"].missing == ("torque", "brake_pressure", "steer")
    assert d.outside_parking_domain == css.ids  # a road drive: up to 76 km/h
    capsys.readouterr()
    assert main(["campaign", "describe", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n_trials"] == 2


def test_shipped_mappings_load():
    for f in sorted(MAPPINGS.glob("*.yaml")):
        load_mapping(f)
