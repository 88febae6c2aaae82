"""Every command that identifies, evaluates or rates refuses, in one line and with exit
status 2, a campaign that lacks a channel its workflow needs (parknss.data.workflows),
before any model is loaded or fitted."""

from __future__ import annotations

import json

import pytest

from helpers.synth import drop, make_campaign
from parknss.cli import main
from parknss.data.io import write_campaign
from parknss.data.workflows import ABSENT_HINT, ACTUATORS, NSS, RATE
from parknss.nss.campaigns import load_campaign

DATA = "campaigns/partial"  # never read: the reader is replaced by the in-memory campaign
NO_COMMANDS = ("torque_cmd", "decel_cmd", "steer_cmd")


@pytest.fixture
def serve(monkeypatch):
    """serve(channels_to_drop): every campaign read returns the tiny campaign without them."""

    def _serve(absent: tuple[str, ...]):
        camp = drop(make_campaign(60, reps=2), absent, name="partial")
        monkeypatch.setattr("parknss.data.io.read_campaign", lambda path: camp)
        return camp

    return _serve


def _refused(capsys, args: list[str]) -> str:
    """Run the CLI; assert exit status 2 and one error line; return that line."""
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = [ln for ln in err.splitlines() if ln.startswith("parknss: error:")]
    assert len(lines) == 1 and err.rstrip().endswith(lines[0]), err
    return lines[0]


def _assert_names(line: str, command: str, missing: str, purpose: str) -> None:
    assert line.startswith(f"parknss: error: {command} --data {DATA}: campaign 'partial' ")
    assert f"lacks {missing}, which {purpose} needs" in line
    assert line.endswith(ABSENT_HINT)


@pytest.mark.parametrize(
    "args",
    [
        ["train", "--data", DATA, "--epochs", "1"],
        ["cv", "--data", DATA, "--variants", "linear", "--workers", "1"],
        ["evaluate", "--data", DATA],
    ],
)
def test_nss_commands_refuse_a_campaign_without_brake_pressure(serve, capsys, tmp_path, args):
    serve(("brake_pressure",))
    line = _refused(capsys, [*args, "--out", str(tmp_path / "run")])
    _assert_names(line, f"parknss {args[0]}", "brake_pressure", NSS.purpose)
    assert not (tmp_path / "run").exists()  # refused before anything was written


def test_evaluate_chain_needs_the_commands_a_model_does_not(serve, capsys, tmp_path):
    serve(NO_COMMANDS)
    out = str(tmp_path / "run")
    line = _refused(capsys, ["evaluate", "--chain", "models/chain", "--data", DATA, "--out", out])
    _assert_names(line, "parknss evaluate", ", ".join(NO_COMMANDS), RATE.purpose)
    # the same campaign passes the NSS check (what evaluate --model and train need)
    assert len(load_campaign(DATA, "nss", "parknss train")) == 8


@pytest.mark.parametrize(
    ("sub", "extra"),
    [
        ("study", ["--out", "OUT"]),
        ("ladder", []),
        ("build", ["--nss", "models/nss", "--out", "OUT"]),
        ("stress", []),
    ],
)
def test_actuator_commands_refuse_a_campaign_without_torque_cmd(
    serve, capsys, tmp_path, sub, extra
):
    serve(("torque_cmd",))
    extra = [str(tmp_path / "out") if a == "OUT" else a for a in extra]
    line = _refused(capsys, ["actuators", sub, "--data", DATA, *extra])
    _assert_names(line, f"parknss actuators {sub}", "torque_cmd", ACTUATORS.purpose)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("mode", "absent", "missing", "purpose"),
    [
        (["--chain", "models/chain"], ("decel_cmd",), "decel_cmd", RATE.purpose),
        (["--model", "models/nss"], ("steer",), "steer", NSS.purpose),
        (["--replay-truth"], ("ay",), "ay", "rating the truth replay"),
    ],
)
def test_rate_refuses_per_mode(serve, capsys, tmp_path, mode, absent, missing, purpose):
    serve(absent)
    line = _refused(capsys, ["rate", *mode, "--data", DATA, "--out", str(tmp_path / "r")])
    _assert_names(line, "parknss rate", missing, purpose)


@pytest.mark.parametrize(
    "args", [["learning-curve", "--quick"], ["seed-noise"], ["estimate", "--sec-per-epoch", "1"]]
)
def test_studies_refuse_a_campaign_without_yaw_rate(serve, capsys, tmp_path, args):
    serve(("yaw_rate",))
    more = [] if args[0] == "estimate" else ["--out", str(tmp_path / "s")]
    line = _refused(capsys, ["study", *args, "--data", DATA, *more])
    _assert_names(line, f"parknss study {args[0]}", "yaw_rate", NSS.purpose)
    assert not (tmp_path / "s").exists()


def test_a_written_campaign_without_torque_cmd_end_to_end(tmp_path, capsys):
    """Through a real campaign folder (the reader keeps the channel set it was written with)."""
    folder = write_campaign(drop(make_campaign(400, reps=2), ("torque_cmd",)), tmp_path / "c")
    line = _refused(capsys, ["actuators", "stress", "--data", str(folder)])
    assert f"parknss actuators stress --data {folder}: campaign 'partial' lacks torque_cmd" in line
    assert main(["campaign", "describe", str(folder), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["absent_channels"] == ["torque_cmd"] and doc["workflows"]["nss"]["ok"]
    assert doc["workflows"]["actuators"]["missing"] == ["torque_cmd"]
