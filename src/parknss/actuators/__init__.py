"""Per-channel actuator submodels (paper §III, layer L6): what one candidate needs.

* :mod:`~parknss.actuators.spec`: what a candidate is (channel, architecture, variant,
  state features); :mod:`~parknss.actuators.candidates`: the one table from an
  architecture to its class and the factory;
* :mod:`~parknss.actuators.models`, :mod:`~parknss.actuators.lags`,
  :mod:`~parknss.actuators.neural`: the candidates (batched rollout and per-sample step),
  :mod:`~parknss.actuators.steppers`: their NumPy real-time twins,
  :mod:`~parknss.actuators.scan`: the parallel scans of the lags;
* :mod:`~parknss.actuators.envelopes`: the input and output envelopes;
* :mod:`~parknss.actuators.data`, :mod:`~parknss.actuators.fit`: identification data,
  fitting and scoring one candidate; :mod:`~parknss.actuators.phase_a`: Phase A of the
  selection, every candidate as a job of the one executor.

Everything that needs the assembled chain (Phase B, co-tuning, Table IV, the build, the
stress study) is :mod:`parknss.chain`, one layer up.
"""
