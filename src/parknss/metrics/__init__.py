"""Open-loop error metrics and the ISO/TS 18571 objective rating."""
