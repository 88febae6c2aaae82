"""The chain's gear channel: the shift-by-wire rule of the reference vehicle.

A requested gear different from the engaged one is engaged only after ``shift_time_s`` of
consecutive samples at |vx| <= ``max_shift_speed_kmh`` (vx: the chain's own predicted
speed, the NSS state x̂(k) of the sample, the same state the submodels' features read);
while |vx| is above it the request is refused and the engaged gear stays. While a request
waits at standstill the drive command is zero ("shifting": the reference's drive target is
0 while it shifts, :class:`parknss.reference.actuators.GearSelector` and
``DriveActuator``); the chain mirrors that on the input side, on the torque command the
drive submodel sees. The numbers are the envelope's (:class:`~parknss.actuators.envelopes.
Envelope`, ``shift_speed_kmh``, ``shift_time_s``; the reference's 0.1 km/h and 0.25 s).

:class:`ShiftByWire` is the rule, one sample per call in plain floats; it is written once
here and used by the real-time chain (:class:`parknss.chain.realtime.RealtimeChain`) and the
batched rollout's interleaved loop (:meth:`parknss.chain.model.Chain.rollout`). The
generated C of the FMU (:mod:`parknss.chain.ccode`) is its third copy, tested against this
one.
"""

from __future__ import annotations

import math

from parknss.signals import DT, kmh_to_ms


def shift_samples(shift_time_s: float, dt: float = DT) -> int:
    """Samples a request must wait at standstill before it is engaged."""
    return round(shift_time_s / dt)


class ShiftByWire:
    """The gear rule (module doc). ``gear`` is the engaged gear, ``shifting`` True while a
    request waits at standstill; ``refused`` counts samples a differing request met
    |vx| above the shift speed, ``waited`` samples it waited at standstill, ``shifts``
    the engagements."""

    def __init__(self, max_shift_speed_kmh: float, shift_time_s: float, dt: float = DT) -> None:
        self.max_speed = kmh_to_ms(max_shift_speed_kmh)
        self.n_shift = shift_samples(shift_time_s, dt)
        self.refused = self.waited = self.shifts = 0
        self.reset()

    def reset(self, gear: float = 0.0) -> None:
        """Engage ``gear`` (NaN: 0) with no request pending; counters keep counting."""
        self.gear = float(gear) if math.isfinite(gear) else 0.0
        self.shifting = False
        self._count = 0

    def step(self, request: float, vx: float) -> float:
        """One sample under the (clean) gear ``request`` at the chain's speed ``vx`` m/s;
        returns the engaged gear."""
        if request == self.gear:
            self.shifting, self._count = False, 0
        elif abs(vx) > self.max_speed:
            self.shifting, self._count = False, 0
            self.refused += 1
        else:
            self.shifting = True
            self.waited += 1
            self._count += 1
            if self._count >= self.n_shift:
                self.gear, self.shifting, self._count = request, False, 0
                self.shifts += 1
        return self.gear
