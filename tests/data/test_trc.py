"""PCAN-View .trc logs: every version python-can reads (1.0, 1.1, 1.3, 2.0, 2.1) decodes
as the same drive as a .blf of the same frames; other versions are refused in one line;
a folder's skipped files (other types, dangling links) are listed by the import."""

from __future__ import annotations

import os
from pathlib import Path

import can
import numpy as np
import pytest

from helpers.candrive import EPOCH, frames, setup_logs, vehicle_dbc, write_log
from parknss.cli import main
from parknss.data.canframes import read_frames
from parknss.data.io import import_folder, read_trial
from parknss.errors import DataError

START_DAYS = EPOCH / 86400.0 + 25569.0  # ;$STARTTIME: days since 1899-12-30


def _hex_id(m: can.Message) -> str:
    return f"{m.arbitration_id:08X}" if m.is_extended_id else f"{m.arbitration_id:04X}"


def _data(m: can.Message) -> str:
    return " ".join(f"{b:02X}" for b in m.data)


def write_trc_by_hand(path: Path, messages: list[can.Message], version: str) -> Path:
    """A .trc as PCAN-View writes it (header and one line per frame), by hand."""
    t0 = messages[0].timestamp
    head = [f";$FILEVERSION={version}", f";$STARTTIME={START_DAYS!r}"]
    if version == "2.0":
        head.append(";$COLUMNS=N,O,T,I,d,l,D")
    lines = [*head, ";", ";   Message Number", ";---+--   ----+----  --+--  ----+---"]
    for k, m in enumerate(messages, start=1):
        ms = (m.timestamp - t0) * 1000.0
        if version == "1.1":
            row = f"{k:>6}) {ms:11.1f}  Rx  {_hex_id(m):>8}  {len(m.data)}  {_data(m)}"
        elif version == "1.3":
            row = f"{k:>6}) {ms:11.1f} 1  Rx  {_hex_id(m):>8} -  {len(m.data)}  {_data(m)}"
        else:
            row = f"{k:>7} {ms:13.3f} DT {_hex_id(m):>8} Rx {len(m.data)} {_data(m)}"
        lines.append(row)
    path.write_text("\r\n".join(lines) + "\r\n", encoding="latin-1")
    return path


def write_trc_python_can(path: Path, messages: list[can.Message], version: str) -> Path:
    from can.io.trc import TRCFileVersion

    writer = can.TRCWriter(str(path))
    writer.file_version = {"1.0": TRCFileVersion.V1_0, "2.1": TRCFileVersion.V2_1}[version]
    for m in messages:
        writer.on_message_received(m)
    writer.stop()
    return path


def _ms_frames() -> list[can.Message]:
    """The drive of test_can with times rounded to 0.1 ms (what v1.x files hold)."""
    out = frames(vehicle_dbc())
    for m in out:
        m.timestamp = EPOCH + round((m.timestamp - EPOCH) * 1e4) / 1e4
    return out


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("trc") / "logs"
    mapping = setup_logs(folder, ".blf", messages=_ms_frames())
    return mapping, read_trial(folder / "park_in_left_r1.blf", mapping)


@pytest.mark.parametrize("version, by", [("1.0", "python-can"), ("1.1", "hand"),
                                         ("1.3", "hand"), ("2.0", "hand"),
                                         ("2.1", "python-can")])
def test_every_trc_version_decodes_as_the_blf_of_the_same_frames(reference, tmp_path,
                                                                  version, by):
    mapping, blf = reference
    path = tmp_path / "park_in_left_r1.trc"
    write = write_trc_by_hand if by == "hand" else write_trc_python_can
    write(path, _ms_frames(), version)
    table = read_frames(path)
    assert table.kind == "trc" and table.n_frames == len(_ms_frames())
    assert set(np.unique(table.bus).tolist()) == {0}  # the file's bus 1 is bus 0
    trial = read_trial(path, mapping)
    assert trial.channels.keys() == blf.channels.keys()
    for name, v in blf.channels.items():
        np.testing.assert_allclose(trial[name], v, rtol=0, atol=1e-9, err_msg=name)
    assert '"format": "trc"' in trial.provenance


def test_a_trc_version_python_can_does_not_read_is_refused_in_one_line(tmp_path):
    path = write_trc_by_hand(tmp_path / "x.trc", _ms_frames()[:5], "1.3")
    path.write_text(path.read_text(encoding="latin-1").replace("=1.3", "=1.2"))
    with pytest.raises(DataError, match=r"x\.trc: \.trc file version '1\.2' is not one "
                                        r"parknss reads \(1\.0, 1\.1, 1\.3, 2\.0, 2\.1\); save"):
        read_frames(path)


def test_a_corrupt_trc_line_is_one_line_naming_it(tmp_path):
    path = write_trc_python_can(tmp_path / "x.trc", _ms_frames()[:50], "2.1")
    text = path.read_text(encoding="latin-1").splitlines()
    text[30] = text[30].replace(" DT ", " DT ").replace(text[30].split()[1], "1.2.3")
    path.write_text("\n".join(text) + "\n", encoding="latin-1")
    with pytest.raises(DataError, match=r"x\.trc: not a readable \.trc log, corrupt or "
                                        r"truncated \(line 31, after frame 1[0-9]: "):
        read_frames(path)


def test_a_folder_with_a_log_and_a_trc_imports_both_and_lists_what_it_skips(tmp_path, capsys):
    src = tmp_path / "logs"
    mapping = setup_logs(src, ".blf", messages=_ms_frames())
    write_trc_python_can(src / "park_out_left_r2.trc", _ms_frames(), "2.1")
    write_log(src / "park_out_right_r3.asc", _ms_frames())
    (src / "notes.txt").write_text("drive on the test track\n")
    os.symlink(src / "gone.log", src / "park_in_right_r4.log")
    camp = import_folder(src, mapping)
    assert camp.ids == ["park_in_left_r1", "park_out_left_r2", "park_out_right_r3"]
    np.testing.assert_allclose(camp[1]["vx"], camp[0]["vx"], atol=1e-9)
    assert camp.meta["skipped_files"] == [
        {"file": "notes.txt", "why": ".txt: not a log type parknss reads"},
        {"file": "park_in_right_r4.log", "why": "dangling symbolic link"},
    ]
    out = tmp_path / "camp"
    assert main(["campaign", "import", str(src), "--out", str(out), "--mapping",
                 str(mapping)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[-2:] == [
        f"imported 3 trials to {out}",
        "skipped 2 files: notes.txt (.txt: not a log type parknss reads), "
        "park_in_right_r4.log (dangling symbolic link)",
    ]
