"""Tracking and the command interface: predictive steering tracker, gear/longitudinal logic."""
