"""Trials, campaigns, log readers/writers, windows and splits."""

from parknss.data.trial import MANEUVER_CLASSES, Campaign, Trial

__all__ = ["MANEUVER_CLASSES", "Campaign", "Trial"]
