"""`parknss demo` needs the shipped plant: a missing artefact is one line and exit 2."""

from __future__ import annotations

from parknss.cli import main
from parknss.config import SHIPPED_CHAIN, SHIPPED_NSS


def test_demo_names_a_missing_shipped_model(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path / "run"), "--nss", str(tmp_path / "no_nss")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "no_nss" in err[0] and "shipped NSS model is missing" in err[0]


def test_the_shipped_plant_is_in_the_checkout():
    # the demo (README's main job) runs on these; they are committed artefacts
    assert (SHIPPED_NSS / "model.json").is_file() and (SHIPPED_NSS / "model.safetensors").is_file()
    assert (SHIPPED_CHAIN / "chain.json").is_file()
