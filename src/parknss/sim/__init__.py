"""The closed-loop parking simulator: scenes, planning, control, plants, closed loop."""
