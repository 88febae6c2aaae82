"""Community DBCs as published: each tolerated fault is one warning line with the file's
own line number (strict mode refuses them as before); ``CM_ "IMPORT x.dbc";`` lines are
followed relative to the DBC's folder, cycles refused."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from parknss.data.dbc import DbcWarning, clear_dbc_cache, load_dbc
from parknss.errors import DataError, show_warnings_as_lines

HEAD = """VERSION ""

NS_ :
	CM_

BS_:

BU_: ECU

BO_ 256 ESP: 8 ECU
 SG_ VehSpd : 0|16@1+ (0.01,0) [0|300] "km/h" Vector__XXX
 SG_ Gear : 16|3@1+ (1,0) [0|7] "" Vector__XXX

BO_ 300 BRK: 8 ECU
 SG_ Prs : 0|16@1+ (0.1,0) [0|250] "bar" Vector__XXX

"""  # 16 lines; the first statement below is line 17

FAULTS = {
    "missing_semicolon": (
        'CM_ SG_ 256 VehSpd "speed"\nVAL_ 256 Gear 0 "P" 1 "D" ;\n',
        "line 17: CM_ statement has no closing ';' (added)",
    ),
    "unused_val": (
        'VAL_ 256 Nope 0 "P" 1 "D" ;\nVAL_ 256 Gear 0 "P" 1 "D" ;\n',
        "line 17: VAL_ table for 'Nope' unused (message id 256 has no signal 'Nope'; ignored)",
    ),
    "cm_quotes": (
        'CM_ SG_ 256 VehSpd "the "fast" speed";\nVAL_ 256 Gear 0 "P" 1 "D" ;\n',
        "line 17: CM_ comment has unescaped quotes (read as text)",
    ),
}


def _load(path: Path, strict: bool = False):
    clear_dbc_cache()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loaded = load_dbc(path, strict=strict)
    return loaded, [str(w.message) for w in caught if issubclass(w.category, DbcWarning)]


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_each_fault_is_one_warning_with_the_files_line_and_strict_refuses_it(tmp_path, fault):
    tail, expected = FAULTS[fault]
    path = tmp_path / f"{fault}.dbc"
    path.write_text(HEAD + tail)
    loaded, lines = _load(path)
    assert lines == [f"DBC file {path}: {expected}"]
    assert loaded.warnings == (expected,)
    esp = loaded.message("ESP")
    assert esp.get_signal_by_name("Gear").choices[1] == "D"  # the rest of the file is read
    assert loaded.message_names() == ["ESP", "BRK"]
    with pytest.raises(DataError, match="refused in strict mode") as exc:
        _load(path, strict=True)
    assert "\n" not in str(exc.value)


def test_standard_id_beyond_11_bits_is_read_as_extended(tmp_path):
    path = tmp_path / "big_id.dbc"
    path.write_text(HEAD.replace("BO_ 300 BRK", "BO_ 13274 BRK") + 'CM_ BO_ 13274 "brakes";\n'
                    'VAL_ 13274 Prs 0 "off" ;\n')
    loaded, lines = _load(path)
    assert lines == [
        f"DBC file {path}: line 14: message 'BRK': standard frame id 0x33DA is more than 11 "
        "bits (read as an extended id)"
    ]
    brk = loaded.message("BRK")
    assert brk.frame_id == 0x33DA and brk.is_extended_frame and brk.comment == "brakes"
    assert brk.get_signal_by_name("Prs").choices[0] == "off"  # its VAL_ follows the id
    with pytest.raises(DataError, match="Standard frame id 0x33da is more than 11 bits"):
        _load(path, strict=True)


def test_line_numbers_are_the_files_own_when_sections_are_inserted(tmp_path):
    path = tmp_path / "nosections.dbc"
    text = HEAD.replace("BS_:\n\nBU_: ECU\n", "") + 'CM_ SG_ 256 VehSpd "a "b" c";\nBO_ x\n'
    path.write_text(text)
    with pytest.raises(DataError) as exc:
        _load(path)
    n = text.splitlines().index("BO_ x") + 1
    assert f'Invalid syntax at line {n}: "BO_ x"' in str(exc.value)
    path.write_text(text.replace("BO_ x\n", ""))
    _, lines = _load(path)
    n = text.splitlines().index('CM_ SG_ 256 VehSpd "a "b" c";') + 1
    assert lines[1].endswith(f"line {n}: CM_ comment has unescaped quotes (read as text)")


def test_several_faults_in_one_file_are_one_line_each(tmp_path):
    path = tmp_path / "many.dbc"
    body = "".join(tail for tail, _ in FAULTS.values())
    path.write_text(HEAD + body.replace('VAL_ 256 Gear 0 "P" 1 "D" ;\n', "") +
                    'VAL_ 256 Gear 0 "P" 1 "D" ;\n')
    loaded, lines = _load(path)
    assert len(lines) == 3 and all("\n" not in x for x in lines)
    assert loaded.message("ESP").get_signal_by_name("VehSpd").comment is not None


def test_imports_are_followed_relative_to_the_dbc_folder(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "_common.dbc").write_text(HEAD.split("BO_ 300")[0])
    car = tmp_path / "sub" / "car.dbc"
    car.write_text('CM_ "IMPORT _common.dbc";\nBU_: GW\nBO_ 300 BRK: 8 GW\n'
                   ' SG_ Prs : 0|16@1+ (0.1,0) [0|250] "" Vector__XXX\n\n'
                   'CM_ SG_ 256 VehSpd "from the import"\n')
    loaded, lines = _load(car)
    assert loaded.message_names() == ["ESP", "BRK"]
    assert loaded.message("ESP").get_signal_by_name("VehSpd").comment == "from the import"
    assert lines == [f"DBC file {car}: line 6: CM_ statement has no closing ';' (added)"]
    # a fault inside the imported file names that file and its line; an edit of the
    # imported file alone is seen (the cache key covers the imports)
    (tmp_path / "sub" / "_common.dbc").write_text(HEAD.split("BO_ 300")[0] +
                                                   'VAL_ 256 Nope 0 "x" ;\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_dbc(car)
    assert any("line 14 of _common.dbc" in str(w.message) for w in caught)
    _, lines = _load(car)
    assert lines[1] == (f"DBC file {car}: line 14 of _common.dbc: VAL_ table for 'Nope' "
                        "unused (message id 256 has no signal 'Nope'; ignored)")


def test_import_cycles_and_missing_imports_are_refused_in_one_line(tmp_path):
    (tmp_path / "a.dbc").write_text('CM_ "IMPORT b.dbc";\n')
    (tmp_path / "b.dbc").write_text('\nCM_ "IMPORT a.dbc";\n')
    with pytest.raises(DataError, match=r"b.dbc: line 2: IMPORT cycle \(a.dbc -> b.dbc -> "
                                        r"a.dbc\); remove one"):
        _load(tmp_path / "a.dbc")
    (tmp_path / "c.dbc").write_text('CM_ "IMPORT nowhere.dbc";\n')
    with pytest.raises(DataError, match=r"line 1: imported file 'nowhere\.dbc' not found"):
        _load(tmp_path / "c.dbc")


def test_the_command_line_prints_a_warning_as_one_line_without_a_source_path(tmp_path, capsys):
    path = tmp_path / "w.dbc"
    path.write_text(HEAD + FAULTS["cm_quotes"][0])
    saved = warnings.showwarning
    try:
        show_warnings_as_lines()
        clear_dbc_cache()
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = warnings.showwarning
            load_dbc(path)
    finally:
        warnings.showwarning = saved
    err = capsys.readouterr().err
    assert err == f"parknss: warning: DBC file {path}: {FAULTS['cm_quotes'][1]}\n"
