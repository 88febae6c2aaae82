"""The closed-loop parking simulator.

Modules, each importing only those before it: ``geometry`` (footprints, exact collision
and clearance, dense checks), ``scenarios`` (scenes, the grids), ``trajectory``,
``planning/`` (Hybrid A*, Reeds-Shepp, refinement), ``control/`` (tracker, MPC, command
interface), ``plants`` (every plant a :class:`parknss.plant.Plant`), ``closed_loop`` (the
100 Hz loop and its config), ``planner`` (the one ``plan_scene``), ``session`` (one
scene: plan once, drive under each plant), ``grid`` (grids through the executor, Table V)
and ``tuning`` (the interface-gain descent).
"""
