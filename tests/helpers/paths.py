"""Paths the tests share: the checkout and the real cars' public logs beside it
(../shared/realdata, read in place; tests that need them carry ``@pytest.mark.realdata``
and are skipped by tests/conftest.py when the folder is missing)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the checkout (tests/helpers/paths.py)
TESTS = ROOT / "tests"
REALDATA = ROOT.parent / "shared" / "realdata"
KONA = REALDATA / "kona_ev_2019"
CANEDGE = REALDATA / "css_canedge_gnss_imu"
TPCAP = ROOT.parent / "shared" / "planning" / "tpcap"  # the TPCAP cases, read in place
