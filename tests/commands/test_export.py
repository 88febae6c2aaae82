"""``parknss export fmu|onnx``: the files are written, --json documents, refusals in one line."""

from __future__ import annotations

import json
import zipfile

from parknss.cli import main


def test_export_onnx_and_fmu(tmp_path, capsys):
    out = tmp_path / "step.onnx"
    assert main(["export", "onnx", "--out", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["kind"] == "chain" and out.is_file()
    assert main(["export", "onnx", "--out", str(out)]) == 2  # exists: refused
    assert "already exists" in capsys.readouterr().err
    fmu = tmp_path / "chain.fmu"
    assert main(["export", "fmu", "--out", str(fmu)]) == 0
    assert "wrote" in capsys.readouterr().out
    assert "modelDescription.xml" in zipfile.ZipFile(fmu).namelist()


def test_export_refuses_a_corrupt_chain(tmp_path, capsys):
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "chain.json").write_text("{not json")
    assert main(["export", "fmu", "--chain", str(tmp_path / "bad"),
                 "--out", str(tmp_path / "x.fmu")]) == 2
    err = capsys.readouterr().err  # checked against its manifest before it is parsed
    assert "no SHA256SUMS" in err and len(err.strip().splitlines()) == 1
