"""The FMU: FMPy's validation, FMPy's simulation of the bundled trials against the
real-time chain at 1e-9 in every output, communication steps of several 10 ms, and the
refusals (overwrite, file name)."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from parknss.chain import load_chain
from parknss.errors import ParknssError
from parknss.export.fmu import export_fmu
from parknss.export.verify import CHAIN_OUTPUTS, fmu_trial_errors, realtime_reference
from parknss.nss.campaigns import default_campaign
from parknss.outputs import OutputExistsError


def test_fmpy_validation_and_layout(shipped_fmu):
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(shipped_fmu.path)) == []
    names = set(zipfile.ZipFile(shipped_fmu.path).namelist())
    assert {"modelDescription.xml", "sources/pk_chain.c", "sources/pk_chain.h",
            "sources/fmi2_chain.c", "binaries/linux64/parknss_chain.so"} <= names


def test_fmu_matches_the_realtime_chain(shipped_fmu):
    """One trial of each class through FMPy (the command --verify does all 16)."""
    trials = [t for t in default_campaign() if t.repetition == 1]
    errs = fmu_trial_errors(shipped_fmu.path, load_chain(shipped_fmu_chain()), trials)
    assert len(errs) == 4
    for e in errs:
        assert set(e.max_abs) == set(CHAIN_OUTPUTS)
        assert e.worst <= 1e-9, (e.trial, e.max_abs)


def shipped_fmu_chain():
    from parknss.config import SHIPPED_PLANT

    return SHIPPED_PLANT  # what `parknss export fmu` packs by default


def test_communication_step_of_several_samples(shipped_fmu):
    """A 50 ms communication step gives every fifth sample of the 10 ms run."""
    from fmpy import simulate_fmu

    tr = next(iter(default_campaign()))
    n = 600
    cm = tr.array(("gear", "torque_cmd", "decel_cmd", "steer_cmd"))[:n:5]
    sig = np.zeros(len(cm), dtype=[("time", float), ("gear", float), ("torque_cmd", float),
                                   ("decel_cmd", float), ("steer_cmd", float)])
    sig["time"] = np.arange(len(cm)) * 0.05
    for i, name in enumerate(("gear", "torque_cmd", "decel_cmd", "steer_cmd")):
        sig[name] = cm[:, i]
    res = simulate_fmu(str(shipped_fmu.path), input=sig, output_interval=0.05,
                       stop_time=n * 0.01, output=["vx", "steer"])
    held = tr.channels.copy()
    for name in ("gear", "torque_cmd", "decel_cmd", "steer_cmd"):
        held[name] = np.repeat(tr[name][:n:5], 5)
    for name in ("vx", "yaw_rate", "torque", "brake_pressure", "steer"):
        held[name] = np.zeros(n)
    from parknss.data.trial import Trial

    ref = realtime_reference(load_chain(shipped_fmu_chain()),
                             Trial(tr.id, tr.maneuver, tr.repetition,
                                   {k: np.asarray(v)[:n] for k, v in held.items()}))
    assert np.max(np.abs(res["vx"][1:] - ref[4::5, CHAIN_OUTPUTS.index("vx")])) <= 1e-9
    assert np.max(np.abs(res["steer"][1:] - ref[4::5, CHAIN_OUTPUTS.index("steer")])) <= 1e-9


def test_refusals(shipped_fmu, tmp_path):
    with pytest.raises(OutputExistsError):
        export_fmu(shipped_fmu.path)
    with pytest.raises(ParknssError, match=r"ends in \.fmu"):
        export_fmu(tmp_path / "chain.zip")


def test_model_description_units_types_and_experiment(shipped_fmu):
    """FMI units on every Real with a unit (FMPy reads them), Integer gears, the generation
    date and a default experiment with a stop time."""
    from fmpy import read_model_description

    md = read_model_description(str(shipped_fmu.path))
    by = {v.name: v for v in md.modelVariables}
    assert by["vx"].unit == "m/s" and by["brake_pressure"].unit == "bar"
    assert by["steer_cmd"].unit == "deg" and by["torque"].unit == "N.m"
    assert by["gear"].type == "Integer" and by["gear"].variability == "discrete"
    assert by["gear_engaged"].type == "Integer" and by["in_domain"].type == "Integer"
    assert {u.name for u in md.unitDefinitions} >= {"m/s", "bar", "deg", "N.m", "rad/s"}
    assert md.generationDateAndTime and md.generationDateAndTime.endswith("Z")
    assert float(md.defaultExperiment.stopTime) > 0
    assert float(md.defaultExperiment.stepSize) == 0.01


def test_leaving_the_identified_domain_is_reported(shipped_fmu):
    """A -1 m/s² deceleration request (the domain is [-0.8, 0]) is clamped, and the FMU
    says so: in_domain drops to 0, domain_exits counts the samples, one warning line per
    excursion names the variable, its value and the range."""
    from fmpy import simulate_fmu

    n = 300
    t = np.arange(n) * 0.01
    sig = np.zeros(n, dtype=[("time", float), ("gear", np.int32), ("torque_cmd", float),
                             ("decel_cmd", float), ("steer_cmd", float)])
    sig["time"], sig["gear"] = t, 1
    sig["decel_cmd"] = np.where((t >= 1.0) & (t < 1.5), -1.0, 0.0)
    lines: list[str] = []

    def logger(_env, _name, status, category, message):
        lines.append(f"{status} {category.decode()} {message.decode()}")

    res = simulate_fmu(str(shipped_fmu.path), input=sig, output_interval=0.01,
                       stop_time=n * 0.01, output=["in_domain", "domain_exits", "vx"],
                       logger=logger)
    inside = res["in_domain"]
    assert inside[:90].min() == 1 and inside[-50:].min() == 1
    assert inside.min() == 0
    assert res["domain_exits"][-1] == pytest.approx(50, abs=1)
    warn = [ln for ln in lines if "decel_cmd" in ln and "outside the identified domain" in ln]
    assert len(warn) == 1 and "clamped" in warn[0] and "[-0.8, 0]" in warn[0], lines


def test_verify_reports_progress_per_trial(shipped_fmu):
    """--verify's replay takes seconds per trial: each finished trial is reported."""
    trials = [t for t in default_campaign() if t.repetition == 1][:2]
    seen = []
    errs = fmu_trial_errors(shipped_fmu.path, load_chain(shipped_fmu_chain()), trials,
                            lambda i, n, e: seen.append((i, n, e.trial)))
    assert seen == [(1, 2, trials[0].id), (2, 2, trials[1].id)]
    assert [e.trial for e in errs] == [t.id for t in trials]
