"""CSV logs as people save them: sniffed dialects (';' and decimal comma, tabs, quotes),
units rows and bracketed units, trailing delimiters, case-insensitive names, time units
guessed from the step (or refused with the fix), and hostile files refused in one line."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from parknss.cli import main
from parknss.data import csvlog
from parknss.data.io import read_trial
from parknss.errors import DataError, ParknssWarning
from parknss.signals import KMH_PER_MS, REQUIRED_CHANNELS

N = 300  # 3 s at 100 Hz


def _channels() -> dict[str, np.ndarray]:
    t = np.arange(N) / 100.0
    ch = {c: np.zeros(N) for c in REQUIRED_CHANNELS}
    ch["t"] = t
    ch["vx"] = 1.0 + 0.5 * np.sin(t)
    ch["steer"] = 30.0 * np.cos(t)
    ch["yaw_rate"] = 0.1 * np.sin(2 * t)
    ch["gear"] = np.ones(N)
    return ch


def _write(path: Path, names, rows, delimiter=",", decimal=".", units=None, trailing=False,
           quote=False) -> Path:
    def cell(x) -> str:
        s = x if isinstance(x, str) else repr(float(x))
        s = s.replace(".", decimal) if not isinstance(x, str) else s
        return f'"{s}"' if quote else s

    end = delimiter if trailing else ""
    lines = [delimiter.join(names) + end]
    if units is not None:
        lines.append(delimiter.join(units) + end)
    lines += [delimiter.join(cell(x) for x in r) + end for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _rows(ch, names, scale=None):
    scale = scale or {}
    return list(zip(*[ch[n] * scale.get(n, 1.0) for n in names], strict=True))


def _check(trial, ch):
    for c in ("t", "vx", "steer", "yaw_rate", "gear"):
        np.testing.assert_allclose(trial[c], ch[c], rtol=0, atol=1e-9, err_msg=c)


@pytest.mark.parametrize("dialect", ["comma", "semicolon_decimal_comma", "tab", "quoted"])
def test_dialects_are_sniffed_and_recorded(tmp_path, dialect):
    ch = _channels()
    d, dec, q = {"comma": (",", ".", False), "semicolon_decimal_comma": (";", ",", False),
                 "tab": ("\t", ".", False), "quoted": (",", ".", True)}[dialect]
    p = _write(tmp_path / "log.csv", REQUIRED_CHANNELS, _rows(ch, REQUIRED_CHANNELS), d, dec,
               quote=q)
    trial = read_trial(p)
    _check(trial, ch)
    prov = json.loads(trial.provenance)["csv"]
    assert (prov["delimiter"], prov["decimal"], prov["sniffed"]) == (d, dec, True)
    assert prov["quoted"] is q


def test_units_row_trailing_delimiter_and_bracketed_units(tmp_path):
    ch = _channels()
    names = list(REQUIRED_CHANNELS)
    units = ["ms" if n == "t" else "km/h" if n == "vx" else "deg/s" if n == "yaw_rate"
             else "" for n in names]
    scale = {"t": 1000.0, "vx": KMH_PER_MS, "yaw_rate": 180.0 / np.pi}
    p = _write(tmp_path / "log.csv", names, _rows(ch, names, scale), ";", ",", units=units,
               trailing=True)
    trial = read_trial(p)
    _check(trial, ch)
    prov = json.loads(trial.provenance)
    assert prov["csv"]["units_row"] and prov["csv"]["trailing_delimiter"]
    assert prov["time_unit"] == {"unit": "ms", "from": "file"}
    # the same as bracketed, upper-case names
    heads = [n.upper() + (f" [{u}]" if u else "") for n, u in zip(names, units, strict=True)]
    p = _write(tmp_path / "log2.csv", heads, _rows(ch, names, scale))
    _check(read_trial(p, tmp_path / _mapping(tmp_path, "time: {column: T}\n")), ch)


def _mapping(folder: Path, text: str) -> str:
    (folder / "m.yaml").write_text(text)
    return "m.yaml"


def test_unknown_units_row_is_refused_with_the_option(tmp_path):
    ch = _channels()
    names = list(REQUIRED_CHANNELS)
    units = ["sec", "x", "y", "z", "w", "v", "u", "q", "furlong/fortnight", "r", "s2", "s3"]
    p = _write(tmp_path / "log.csv", names, _rows(ch, names), units=units)
    with pytest.raises(DataError, match=r"line 2: a row of text under the header .*set "
                                        r"csv.units_row: true"):
        read_trial(p)


def test_time_unit_is_guessed_from_the_step_and_stated_or_refused(tmp_path):
    ch = _channels()
    names = list(REQUIRED_CHANNELS)
    p = _write(tmp_path / "log.csv", names, _rows(ch, names, {"t": 1000.0}))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        trial = read_trial(p)
    _check(trial, ch)
    msgs = [str(w.message) for w in caught if issubclass(w.category, ParknssWarning)]
    assert msgs == [f"{p}: time unit 'ms' guessed from the median step 10 (set time.unit in "
                    "the mapping to state it)"]
    p = _write(tmp_path / "log.csv", names, _rows(ch, names, {"t": 1e-3}))  # 1e-5 steps
    with pytest.raises(DataError, match=r"median time step 1e-05 is not a sampling rate .* state "
                                        r"the unit with time.unit in the mapping"):
        read_trial(p)


def test_names_differing_in_case_match_and_a_missing_time_column_names_the_fix(tmp_path):
    ch = _channels()
    names = [n.upper() for n in REQUIRED_CHANNELS]
    p = _write(tmp_path / "log.csv", names, _rows(ch, list(REQUIRED_CHANNELS)))
    _check(read_trial(p), ch)
    names[0] = "Timestamp"
    p = _write(tmp_path / "log.csv", names, _rows(ch, list(REQUIRED_CHANNELS)))
    with pytest.raises(DataError, match=r"time column 't' not found .*; set time.column in "
                                        r"the mapping \(e.g. time.column: 'Timestamp'\)"):
        read_trial(p)


def test_gear_values_without_a_column_read_its_own_column(tmp_path):
    ch = _channels()
    names = list(REQUIRED_CHANNELS)
    rows = [tuple("D" if n == "gear" else v for n, v in zip(names, r, strict=True))
            for r in _rows(ch, names)]
    p = _write(tmp_path / "log.csv", names, rows)
    m = tmp_path / _mapping(tmp_path, "channels:\n  gear: {values: {P: 0, R: -1, D: 1}}\n")
    _check(read_trial(p, m), ch)


def test_stray_quote_and_unreadable_file_are_one_line(tmp_path, capsys):
    ch = _channels()
    names = list(REQUIRED_CHANNELS)
    p = _write(tmp_path / "park_in_left_r1.csv", names, _rows(ch, names))
    lines = p.read_text().splitlines()
    lines[150] = lines[150].replace(",", ',"', 1)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataError, match=r"line 151: unbalanced quote"):
        read_trial(p)
    out = tmp_path / "out"
    assert main(["campaign", "import", str(tmp_path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "line 151: unbalanced quote" in err
    p.write_text("\n".join(lines[:150] + lines[151:]) + "\n")


def test_an_unreadable_file_is_one_line(tmp_path, monkeypatch, capsys):
    ch = _channels()
    p = _write(tmp_path / "park_in_left_r1.csv", REQUIRED_CHANNELS,
               _rows(ch, list(REQUIRED_CHANNELS)))

    def denied(path, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(csvlog, "open", denied, raising=False)  # as chmod 000 (even as root)
    with pytest.raises(DataError, match=r"park_in_left_r1.csv: cannot read the file "
                                        r"\(permission denied\)"):
        read_trial(p)
    assert main(["campaign", "import", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "permission denied" in err
