"""parknss: physics-informed neural state-space plants for automated-parking simulation.

Identifies, from bus logs of a car at parking speeds, a neural state-space (NSS) vehicle
model with per-channel actuator submodels, evaluates it with the protocol of Pan, Tian and
Song (IEEE T-IV, 2026), and runs a production-like parking stack in closed loop through it.
"""

__version__ = "0.1.0"
