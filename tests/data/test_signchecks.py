"""describe's sign and offset checks: on a log of the bundled campaign with ax and ay
inverted and a yaw-rate offset it flags all three and prints the mapping lines that fix
them; imported with those lines, yaw R² and the ratio fit are the campaign's own."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers.paths import ROOT
from parknss.data.describe import describe_campaign
from parknss.data.io import import_folder, read_campaign, write_trial_csv
from parknss.data.trial import Campaign, Trial
from parknss.signals import DEG_PER_RAD

OFFSET_DPS = -0.34  # the real RAV4 log's yaw-rate offset
BUNDLED = ROOT / "campaigns" / "default"


@pytest.fixture(scope="module")
def original() -> Campaign:
    camp = read_campaign(BUNDLED)
    return Campaign(camp.trials[:4], name="four", meta=camp.meta)


def _bad_logs(camp: Campaign, folder):
    folder.mkdir()
    for tr in camp:
        ch = dict(tr.channels)
        ch["ax"], ch["ay"] = -ch["ax"], -ch["ay"]
        ch["yaw_rate"] = ch["yaw_rate"] + OFFSET_DPS / DEG_PER_RAD
        write_trial_csv(Trial(tr.id, tr.maneuver, tr.repetition, ch), folder / f"{tr.id}.csv")
    return folder


def test_the_bundled_campaign_passes_the_checks(original):
    checks = {c.check: c for c in describe_campaign(original).sign_checks}
    assert [c.ok for c in checks.values()] == [True, True, True]
    assert checks["ax_sign"].value > 0.9 and checks["ay_sign"].value > 0.2


def test_inverted_imu_and_yaw_offset_are_flagged_with_the_fixing_lines(original, tmp_path):
    folder = _bad_logs(original, tmp_path / "logs")
    bad = import_folder(folder)
    bad.meta["vehicle_geometry"] = original.meta["vehicle_geometry"]
    summary = describe_campaign(bad)
    checks = {c.check: c for c in summary.sign_checks}
    assert not checks["ax_sign"].ok and checks["ax_sign"].value < -0.9
    assert not checks["ay_sign"].ok and checks["ay_sign"].value < -0.2
    assert not checks["yaw_offset"].ok
    assert checks["yaw_offset"].extra["offset_dps"] == pytest.approx(OFFSET_DPS, abs=0.06)
    table = summary.table()
    assert "    fix in the mapping: ax: {..., invert: true}" in table
    assert "    fix in the mapping: ay: {..., invert: true}" in table
    fix = checks["yaw_offset"].fix
    assert fix.startswith("yaw_rate: {..., offset: ")
    assert float(fix.split("offset: ")[1].split("}")[0]) == pytest.approx(-OFFSET_DPS, abs=0.06)
    assert "yaw R²" in checks["yaw_offset"].detail
    ref = describe_campaign(original)
    assert summary.yaw_r2 < ref.yaw_r2 - 0.005  # the offset hurts eq. 4
    # the offset as the check measured it, in the mapping's unit (rad/s for this CSV)
    off_rad = float(fix.split("; ")[1].split(" in rad/s")[0])
    mapping = tmp_path / "fix.yaml"
    mapping.write_text(
        "channels:\n  ax: {invert: true}\n  ay: {invert: true}\n"
        f"  yaw_rate: {{offset: {off_rad!r}}}\n"
    )
    fixed = import_folder(folder, mapping)
    fixed.meta["vehicle_geometry"] = original.meta["vehicle_geometry"]
    after = describe_campaign(fixed)
    assert [c.ok for c in after.sign_checks] == [True, True, True]
    np.testing.assert_allclose(fixed[0]["ax"], original[0]["ax"], atol=1e-12)
    # offset removal as measured and printed (the median at standstill, to 4 digits)
    assert after.yaw_r2 == pytest.approx(checks["yaw_offset"].extra["yaw_r2_after"], abs=1e-6)
    assert after.yaw_r2 == pytest.approx(ref.yaw_r2, abs=2e-3)
    # the fix also removes the synthetic gyro's own +0.05 °/s standstill bias, so the
    # ratio fit lands within 1 % of the campaign's, not bit for bit
    assert after.steer_ratio_fit == pytest.approx(ref.steer_ratio_fit, rel=0.01)
    js = after.to_json()
    assert json.dumps(js["sign_checks"]) and js["short_frames"] == {}
