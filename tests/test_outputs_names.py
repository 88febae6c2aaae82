"""Names never become paths (``parknss.outputs``): :func:`safe_stem` accepts real names
unchanged and refuses hostile ones in one line; :func:`inside` holds every product path
inside its folder after resolution; :func:`check_location` refuses unwritable ``--out``
before any work; a full disk leaves no partial output."""

import errno
import os
from pathlib import Path

import pytest

from parknss.errors import ParknssError
from parknss.outputs import (
    NAME_MAX_CHARS,
    OutputLocationError,
    UnsafeNameError,
    artefact_folder,
    check_location,
    default_run_folder,
    inside,
    run_folder,
    safe_stem,
)

REAL = [
    "perpendicular-left-t1-open",
    "angled-right-t2-barrier-combined",
    "commonroad-ZAM_Tutorial-1_2_T-1",
    "tpcap-Case1",
    "park_in_left_r1",
    "Parkplatz Süd (Ebene 2)",
    "駐車場-3",
    "a.b",
    "x" * NAME_MAX_CHARS,
]

HOSTILE = [
    ("../../../../victim", "'/'"),
    ("..", "'..'"),
    ("a..b", "'..'"),
    ("sub/name", "'/'"),
    ("back\\slash", "'\\\\'"),
    ("nul\x00byte", "U+0000"),
    ("new\nline", "U+000A"),
    ("tab\tname", "U+0009"),
    ("rtl\u202eevil", "U+202E"),
    ("mark\u200fname", "U+200F"),
    ("zero\u200bwidth", "U+200B"),
    ("line\u2028sep", "U+2028"),
    ("nbsp\u00a0name", "U+00A0"),
    ("glob*", "'*'"),
    ("which?", "'?'"),
    ("[set]", "'['"),
    (".hidden", "starts with"),
    ("-rf", "starts with"),
    (" padded", "starts with"),
    ("x" * (NAME_MAX_CHARS + 1), f"at most {NAME_MAX_CHARS}"),
    ("x" * 300, "300 characters"),
    ("é" * 80, "bytes"),
    ("", "empty"),
]


@pytest.mark.parametrize("name", REAL)
def test_real_names_pass_unchanged(name):
    assert safe_stem(name, what="scene name") == name


@pytest.mark.parametrize(("name", "why"), HOSTILE)
def test_hostile_names_are_refused_in_one_line(name, why):
    with pytest.raises(UnsafeNameError) as ei:
        safe_stem(name, what="scene name")
    msg = str(ei.value)
    assert isinstance(ei.value, ParknssError)
    assert msg.startswith("scene name ") and why in msg
    assert "\n" not in msg and "\x00" not in msg and "\u202e" not in msg
    assert len(msg) < 300


@pytest.mark.parametrize("name", [123, None, ["a"]])
def test_a_name_that_is_not_a_string_is_refused(name):
    with pytest.raises(UnsafeNameError, match="not a string"):
        safe_stem(name, what="scene name")


def test_inside_follows_links_and_refuses_escapes(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (tmp_path / "victim").mkdir()
    (out / "link").symlink_to(tmp_path / "victim")
    assert inside(out, "plan_a.json") == out / "plan_a.json"
    for rel in ("../x.json", "link/x.json", "/etc/passwd", ".", "a/../../x"):
        with pytest.raises(UnsafeNameError, match="outside the output folder"):
            inside(out, rel)


def test_default_run_folder_is_under_runs_command(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert default_run_folder("plan", "cell-1") == Path("runs/plan/cell-1")
    with pytest.raises(UnsafeNameError):
        default_run_folder("plan", "../../x")


def test_a_run_folder_refuses_products_outside_it(tmp_path):
    with run_folder(tmp_path / "run", command="parknss t", args={}, overwrite=False) as run:
        with pytest.raises(UnsafeNameError):
            run.write_json("../escaped.json", {})
        run.write_json("inside.json", {})
    assert not (tmp_path / "escaped.json").exists()
    assert (tmp_path / "run" / "inside.json").is_file()


def test_check_location_refuses_before_any_work(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    for out in (afile / "sub", afile / "a" / "b"):
        with pytest.raises(OutputLocationError, match="is a file, not a folder"):
            check_location(out)
    with pytest.raises(OutputLocationError, match="cannot write in /proc"):
        check_location("/proc/x")
    assert check_location(tmp_path / "new" / "deeper") == tmp_path / "new" / "deeper"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # the probe is gone


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_check_location_refuses_a_read_only_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(OutputLocationError, match="cannot write in"):
            check_location(ro / "out")
    finally:
        ro.chmod(0o755)


def _full(*_a, **_k):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_leaves_no_partial_artefact(tmp_path):
    out = tmp_path / "a" / "b" / "campaign"
    with pytest.raises(OSError), artefact_folder(out, overwrite=False, kind="campaign") as tmp:
        (tmp / "part.txt").write_text("partial")
        _full()
    assert list(tmp_path.iterdir()) == []  # neither the folder nor its new parents


def test_a_full_disk_removes_a_new_runs_partial_products(tmp_path):
    out = tmp_path / "new" / "run"
    with pytest.raises(OSError), run_folder(out, command="parknss t", args={},
                                            overwrite=False) as run:
        run.write_text("table.csv", "a,b\n")
        _full()
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_keeps_a_new_runs_result_cache(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(OSError), run_folder(out, command="parknss t", args={},
                                            overwrite=False) as run:
        (out / "cache").mkdir()
        (out / "cache" / "job.json").write_text("{}")
        run.write_text("figure.png", "x")
        _full()
    assert sorted(p.name for p in out.iterdir()) == ["cache", "run.json"]
