"""Fixtures of the data-layer tests."""

from __future__ import annotations

import pytest

from helpers.kinematic import kinematic_trial
from parknss.data.trial import Trial


@pytest.fixture(scope="module")
def trial() -> Trial:
    """The 30 s kinematic trial (R -> D at standstill, exact eq. 4), one per test module."""
    return kinematic_trial()
