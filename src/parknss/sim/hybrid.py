"""Hybrid plants for diagnosing the chain's closed-loop error (issue 44): half chain, half truth.

The chain is commands -> actuators -> NSS vehicle; the truth (the reference vehicle) is
commands -> its actuators -> its body. Swapping one half tells which half makes the
chain's closed-loop error (``parknss fidelity --candidate nss|actuators``):

* :class:`TruthActuatorsNSS` (candidate ``nss``): the reference vehicle's own actuators
  (gear selector, drive torque with creep, auto-hold, brake hydraulics, steering; noise
  free, bus quantisation not applied) read the NSS's speed and feed the chain's NSS
  vehicle u = [gear, torque N·m, pressure bar, steer deg]. Its error against the truth is
  the NSS's. The controller sees the NSS's outputs, as under the chain plant, and the
  chain's brake latches act (``latch``, default True) as in the chain.
* :class:`ChainActuatorsTruth` (candidate ``actuators``): the chain's input envelope, gear
  rule, actuator submodels and output envelope (exactly :class:`~parknss.chain.realtime.
  RealtimeChain`'s arithmetic, state features read from the truth's state) feed the
  reference vehicle's body (longitudinal with stiction, yaw, IMU points) and its sensors.
  Its error against the truth is the actuator submodels'. The controller sees the truth's
  bus (blind zone, noise), as under the reference plant.

Both are :class:`~parknss.plant.Plant` objects (dt = 0.01 s); :func:`make_hybrid` wraps
them as closed-loop plants (:class:`~parknss.sim.plants.SimPlant`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from parknss.config import SHIPPED_PLANT
from parknss.errors import ConfigError
from parknss.plant import Commands, PlantOutput
from parknss.sim.plants import ChainPlant, ReferencePlant, SimPlant, _TruthPlant

HYBRIDS: tuple[str, ...] = ("nss", "actuators")


class TruthActuatorsNSS:
    """The truth's actuators driving the chain's NSS vehicle (module doc).

    Args:
        chain: a loaded :class:`~parknss.chain.deployed.DeployedChain` (its NSS, its
            envelope's brake-hold latch).
        vehicle: a :class:`~parknss.reference.vehicle.ReferenceVehicle` (its actuators).
        latch: apply the chain's brake-hold latch to the NSS state.
    """

    def __init__(self, chain, vehicle, latch: bool = True) -> None:
        self.nss = chain.rt.nss
        self.envelope = chain.rt.env.env
        self.vehicle = vehicle
        self.latch = bool(latch)
        self.dt = float(vehicle.dt)
        self.reset()

    def reset(
        self, vx: float = 0.0, yaw_rate: float = 0.0, steer: float = 0.0, gear: int = 0
    ) -> PlantOutput:
        v = self.vehicle
        v.reset(vx, yaw_rate, steer, gear)
        self.x = None
        self._x0 = np.array([vx, yaw_rate], dtype=np.float64)
        self.vx_now = float(vx)
        self.gear = int(gear)
        return PlantOutput(int(gear), v.drive.torque, 0.0, float(steer), float(vx),
                           float(yaw_rate), 0.0, 0.0)  # fmt: skip

    def step(self, cmd: Commands) -> PlantOutput:
        """One 10 ms step: truth actuators from the NSS's vx, then the NSS on their output."""
        v = self.vehicle
        gear_req = v._check_gear(cmd.gear, "command")
        tq, dc, st = v._clamp(float(cmd.torque_cmd), float(cmd.decel_cmd), float(cmd.steer_cmd))
        v0 = self.vx_now
        gear = v.gearbox.step(gear_req, v0)
        torque = v.drive.step(tq, gear, v.gearbox.shifting, v0)
        floor = v.autohold.step(v0, v.brake.pressure, torque, gear)
        pressure = v.brake.step(dc, floor)
        steer = v.steering.step(st)
        u = np.array([float(gear), torque, pressure, steer])
        nss = self.nss
        us = nss.scale_u(u)
        if self.x is None:
            self.x = nss.initial_state(self._x0, u)
        vx, yaw, ax, ay = nss.readout(self.x, us)
        self.x = nss.advance(self.x, us)
        self.vx_now = nss.vx(self.x)
        env = self.envelope
        if self.latch and (env.held(pressure, self.vx_now)
                           or env.stops(pressure, gear, self.vx_now)):
            self.x = nss.initial_state(np.zeros(2), u)
            self.vx_now = nss.vx(self.x)
        self.gear = int(gear)
        return PlantOutput(int(gear), torque, pressure, steer, vx, yaw, ax, ay)


class ChainActuatorsTruth:
    """The chain's actuator side driving the truth's body and sensors (module doc).

    Args:
        chain: a loaded :class:`~parknss.chain.deployed.DeployedChain` (its envelopes,
            gear rule and actuator steppers; its NSS is not used).
        vehicle: a :class:`~parknss.reference.vehicle.ReferenceVehicle` (body, sensors).
    """

    def __init__(self, chain, vehicle) -> None:
        if not chain.rt.full:
            raise ConfigError("the actuators hybrid needs a chain with all three submodels")
        self.rt = chain.rt
        self.vehicle = vehicle
        self.dt = float(vehicle.dt)
        self.reset()

    def reset(
        self, vx: float = 0.0, yaw_rate: float = 0.0, steer: float = 0.0, gear: int = 0
    ) -> PlantOutput:
        out = self.vehicle.reset(vx, yaw_rate, steer, gear)
        rt = self.rt
        rt.start([vx, yaw_rate], [0.0, 0.0, steer], [gear, 0.0, 0.0, steer])
        self.gear = int(gear)
        return out

    def step(self, cmd: Commands) -> PlantOutput:
        """One 10 ms step: chain actuals from the truth's state, then the truth's body."""
        from parknss.actuators.spec import CHANNELS, feature_values

        rt, v = self.rt, self.vehicle
        request, c = rt.env.command(float(cmd.gear), [float(cmd.torque_cmd),
                                                       float(cmd.decel_cmd),
                                                       float(cmd.steer_cmd)])  # fmt: skip
        vx, yaw = v.long.vx, v.lat.yaw_rate
        g = request
        if rt.shift is not None:
            g = rt.shift.step(request, vx)
            if rt.shift.shifting:
                c[0] = 0.0
        ys = []
        for i, ch in enumerate(CHANNELS):
            spec = rt.specs[ch]
            f = np.array(feature_values(spec.features, vx, yaw, g)) if spec.features else None
            ys.append(rt.steppers[ch].step(c[i], f))
        torque, pressure, steer = rt.env.output(*ys)
        gear = int(g)
        vx_new = v.long.step(torque, gear, pressure * v.force_per_bar)
        v.lat.step(vx_new, steer)
        self.gear = gear
        return v._emit(gear, torque, pressure, steer)


class _HybridPlant(_TruthPlant):
    """A hybrid as a closed-loop plant; the pose moves with ``truth_of`` (module doc)."""

    def __init__(self, plant, name: str, geom, truth_of=None) -> None:
        self.name = name
        self.geom = geom
        self._truth_of = truth_of
        super().__init__(plant)

    def truth(self, out: PlantOutput) -> PlantOutput:
        return out if self._truth_of is None else (self._truth_of() or out)


def make_hybrid(
    kind: str,
    *,
    chain_path: str | Path | None = None,
    vehicle_yaml: str | Path | None = None,
    seed: int | None = None,
    geom=None,
    latch: bool = True,
) -> SimPlant:
    """The hybrid plant ``kind`` ("nss": truth actuators + chain NSS; "actuators": chain
    actuators + truth body) from the chain artefact ``chain_path`` (default models/plant)
    and the reference vehicle file ``vehicle_yaml`` with noise seed ``seed``."""
    if kind not in HYBRIDS:
        raise ConfigError(f"unknown hybrid plant {kind!r}; one of {', '.join(HYBRIDS)}")
    chain = ChainPlant(chain_path or SHIPPED_PLANT, geom).plant
    ref = ReferencePlant(vehicle_yaml, seed)
    veh = ref.vehicle
    if kind == "nss":
        return _HybridPlant(TruthActuatorsNSS(chain, veh, latch), "nss-hybrid", ref.geom)
    return _HybridPlant(ChainActuatorsTruth(chain, veh), "actuators-hybrid", ref.geom,
                        lambda: veh.last_truth)  # fmt: skip
