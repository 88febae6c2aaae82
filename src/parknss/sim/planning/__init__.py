"""Parking motion planning: Reeds-Shepp curves, Hybrid A* search and trajectory refinement."""
