"""Which car a simulator run plans and drives: the vehicle geometry travels with the data.

The geometry of a run is, in this order:

1. the vehicle YAML the user names (``--vehicle FILE.yaml``, ``vehicle`` of the web
   config; :func:`parknss.vehicle.load_vehicle_geometry`), its values within the
   physical ranges of :mod:`parknss.vehicle_ranges`;
2. else the geometry stored in the chain artefact the closed-loop config names (the car
   whose campaign the NSS and the chain were identified on; ``nss/model.json`` of the
   chain folder, read without loading a network);
3. else parknss's default car (:class:`~parknss.vehicle.VehicleGeometry`).

Planner, refinement, tracker, command interface (its steering clamp), the kinematic
plant, the grids (slots scale with the car) and the web page all take that one geometry.
A learned chain identified on another car cannot drive the requested one:
:func:`check_chain_vehicle` refuses it with one line.
"""

from __future__ import annotations

import json
from pathlib import Path

from parknss.config import SHIPPED_PLANT
from parknss.errors import CheckpointError
from parknss.vehicle import VehicleGeometry, load_vehicle_geometry, same_geometry
from parknss.vehicle_ranges import check_vehicle


def chain_geometry(path: str | Path | None = None) -> VehicleGeometry | None:
    """The vehicle geometry stored with a chain artefact (default: the deployed plant), or
    None when the folder holds none (or cannot be read)."""
    folder = Path(path) if path else SHIPPED_PLANT
    meta = folder / "nss" / "model.json"
    try:
        geometry = json.loads(meta.read_text()).get("geometry")
    except (OSError, ValueError, AttributeError):
        return None
    return VehicleGeometry.from_dict(geometry) if isinstance(geometry, dict) else None


def resolve_vehicle(
    vehicle: str | Path | None = None, chain_path: str | Path | None = None
) -> VehicleGeometry:
    """The geometry of a run (module docstring): ``vehicle`` YAML, else the chain's, else
    the default car."""
    if vehicle is not None:
        geom = load_vehicle_geometry(vehicle)
        check_vehicle(geom.to_dict(), str(vehicle))  # physical ranges, one line
        return geom
    return chain_geometry(chain_path) or VehicleGeometry()


def check_chain_vehicle(
    chain: VehicleGeometry | None, requested: VehicleGeometry, where: str = "chain"
) -> None:
    """One-line error when a chain identified on ``chain``'s car is asked to drive another
    car ``requested``."""
    if chain is None:
        return
    diff = same_geometry(chain, requested)
    if diff:
        field = diff[0]
        raise CheckpointError(
            f"{where} was identified on another car ({field} {getattr(chain, field):g} vs "
            f"{getattr(requested, field):g} requested{' and more' if len(diff) > 1 else ''}): "
            "identify a chain on this car or drop --vehicle"
        )
