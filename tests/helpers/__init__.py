"""Builders shared by the test modules (importable as ``helpers``: pyproject's pytest
``pythonpath`` puts tests/ on sys.path). A test module imports from here or takes a
fixture of tests/conftest.py, never from another test module.

* ``synth``: gear-pattern kinematic trials and campaigns, tiny NSS configs and models,
  campaigns with channels dropped;
* ``kinematic``: the data tests' 30 s R -> D kinematic trial (exact eq. 4);
* ``actuators``: trials with real actuator lag, a tiny random NSS, a tiny actuator config;
* ``experiments``: a tiny campaign and studies config (seconds per study);
* ``scenes``: hand-made scenes and trajectories for the closed-loop tests;
* ``paths``: the checkout, and the real logs beside it (../shared/realdata).
"""
