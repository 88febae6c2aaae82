"""One car end to end (issue 17): the run's geometry comes from --vehicle, else the chain's
artefact; a chain identified on another car is refused with one line; the grids, the
planner and the plants take that one geometry."""

from __future__ import annotations

import json

import pytest

from parknss.cli import main
from parknss.config import CONFIG_DIR, SHIPPED_CHAIN, SHIPPED_PLANT
from parknss.errors import ParknssError
from parknss.sim.closed_loop import SimConfigFiles
from parknss.sim.plants import make_plant
from parknss.sim.scenarios import grid_scene
from parknss.sim.vehicles import chain_geometry, resolve_vehicle
from parknss.vehicle import VehicleGeometry, load_vehicle_geometry

TPCAP_CAR = CONFIG_DIR / "tpcap_vehicle.yaml"


def test_the_run_geometry_comes_from_the_file_else_the_chain():
    assert chain_geometry(SHIPPED_CHAIN) == VehicleGeometry()  # the shipped chain's car
    assert chain_geometry(SHIPPED_PLANT) == VehicleGeometry()  # and the deployed plant's
    assert resolve_vehicle() == VehicleGeometry()
    assert resolve_vehicle(TPCAP_CAR).wheelbase == 2.8
    assert SimConfigFiles(vehicle=TPCAP_CAR).vehicle_geometry().width == 1.942


def test_a_chain_of_another_car_is_refused_with_one_line():
    tpcap = load_vehicle_geometry(TPCAP_CAR)
    with pytest.raises(ParknssError, match="identified on another car") as err:
        make_plant("chain", geom=tpcap)
    assert "\n" not in str(err.value) and "wheelbase 3 vs 2.8" in str(err.value)
    with pytest.raises(ParknssError, match="another car"):
        make_plant("reference", geom=tpcap)
    assert make_plant("kinematic", geom=tpcap).geom is tpcap


def test_grid_slots_scale_with_the_car():
    small = load_vehicle_geometry(TPCAP_CAR)
    for cell, size in ((0, lambda g: 1.5 * g.length), (14, lambda g: g.width + 0.7)):
        assert grid_scene(cell, geom=small).meta.slot_size_m == pytest.approx(size(small))
        assert grid_scene(cell).meta.slot_size_m == pytest.approx(size(VehicleGeometry()))


def test_plan_a_tpcap_case_for_the_tpcap_car_and_write_its_scene(tmp_path, capsys):
    from helpers.paths import TPCAP

    if not TPCAP.is_dir():
        pytest.skip("../shared/planning/tpcap missing")
    args = [
        "plan",
        "--scene",
        str(TPCAP / "Case1.csv"),
        "--vehicle",
        str(TPCAP_CAR),
        "--json",
        "--no-refine",
        "--out",
        str(tmp_path),
    ]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["plannable"] and out["vehicle"]["wheelbase"] == 2.8
    scene = json.loads((tmp_path / "scene_tpcap-case1.json").read_text())
    assert scene["format"] == "parknss.scene" and len(scene["obstacles"]) == 3
    assert (
        main(
            [
                "simulate",
                "--scene",
                str(TPCAP / "Case1.csv"),
                "--vehicle",
                str(TPCAP_CAR),
                "--plant",
                "chain",
                "--out",
                str(tmp_path / "s"),
            ]
        )
        == 2
    )
    assert "identified on another car" in capsys.readouterr().err
