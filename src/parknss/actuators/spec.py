"""What an actuator candidate is: channel, architecture, input variant, and its features.

Three channels (paper §III-A), each a scalar command -> scalar actual:

* drive: ``torque_cmd`` (N·m) -> ``torque`` (N·m);
* brake: ``decel_cmd`` (m/s², <= 0) -> ``brake_pressure`` (bar);
* steering: ``steer_cmd`` (deg) -> ``steer`` (deg).

Three input variants: ``cmd`` (command history only), ``phys`` (plus the physically
motivated state features: drive |vx| and gear, brake |vx|, steering |vx|) and ``uniform``
(plus the uniform state interface [vx, ω_z, gear] shared by all channels).

Feature timing (the one rule, used in fitting and in the chain): the features of sample k
are the vehicle state of sample k. At identification they are the measured vx, yaw rate
and gear; in the chain the NSS state x̂(k) (which depends on inputs up to k-1) and the
yaw rate reconstructed with the previous actual steering angle, so no algebraic loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parknss.data.trial import Trial
from parknss.errors import ConfigError

CHANNELS: tuple[str, ...] = ("drive", "brake", "steering")
COMMAND_OF: dict[str, str] = {"drive": "torque_cmd", "brake": "decel_cmd", "steering": "steer_cmd"}
ACTUAL_OF: dict[str, str] = {"drive": "torque", "brake": "brake_pressure", "steering": "steer"}
CHANNEL_INDEX: dict[str, int] = {c: i for i, c in enumerate(CHANNELS)}

VARIANTS: tuple[str, ...] = ("cmd", "phys", "uniform")
CORE_ARCHS: tuple[str, ...] = ("lag1", "lag2", "hammerstein", "narx", "gru")
LONG_ARCHS: tuple[str, ...] = ("narx1s", "lstm")  # long-memory brake candidates
# Opt-in structured candidates: never fitted by Phase A unless named in select.archs
# (so the study's stored results stay valid); ``monolag`` is the monotone brake.
STRUCTURED_ARCHS: tuple[str, ...] = ("monolag",)
ALL_ARCHS: tuple[str, ...] = (*CORE_ARCHS, *LONG_ARCHS, "static", *STRUCTURED_ARCHS)

# State-feature names per (channel, variant); "speed" is |vx|.
FEATURES: dict[tuple[str, str], tuple[str, ...]] = {
    **{(c, "cmd"): () for c in CHANNELS},
    ("drive", "phys"): ("speed", "gear"),
    ("brake", "phys"): ("speed",),
    ("steering", "phys"): ("speed",),
    **{(c, "uniform"): ("vx", "yaw_rate", "gear") for c in CHANNELS},
}
STATE_NAMES: tuple[str, ...] = ("vx", "yaw_rate", "gear")  # the raw state a feature reads


@dataclass(frozen=True)
class CandidateSpec:
    """One channel x architecture x variant combination."""

    channel: str
    arch: str
    variant: str = "cmd"

    def __post_init__(self) -> None:
        if self.channel not in CHANNELS:
            raise ConfigError(f"unknown actuator channel {self.channel!r}; one of {CHANNELS}")
        if self.arch not in ALL_ARCHS:
            raise ConfigError(f"unknown actuator architecture {self.arch!r}; one of {ALL_ARCHS}")
        if self.variant not in VARIANTS:
            raise ConfigError(f"unknown input variant {self.variant!r}; one of {VARIANTS}")

    @property
    def name(self) -> str:
        return f"{self.channel}/{self.arch}/{self.variant}"

    @property
    def features(self) -> tuple[str, ...]:
        return FEATURES[(self.channel, self.variant)]

    @property
    def state_aware(self) -> bool:
        return bool(self.features)

    @classmethod
    def parse(cls, name: str) -> CandidateSpec:
        """'brake/narx1s/cmd' -> CandidateSpec."""
        parts = name.split("/")
        if len(parts) != 3:
            raise ConfigError(f"candidate {name!r}: expected channel/arch/variant")
        return cls(*parts)


def feature_values(names: tuple[str, ...], vx, yaw_rate, gear) -> list:
    """The state features ``names`` of vx (m/s), yaw rate (rad/s) and gear, each a float, a
    NumPy array or a torch tensor alike ("speed" is |vx|): the one definition the fitting
    (:func:`feature_matrix`), the chain's rollout and its real-time twin stack."""
    vals = {"vx": vx, "yaw_rate": yaw_rate, "gear": gear}
    return [abs(vx) if n == "speed" else vals[n] for n in names]


def feature_matrix(names: tuple[str, ...], vx, yaw_rate, gear) -> np.ndarray:
    """State features (..., F) from vx (m/s), yaw rate (rad/s), gear arrays of shape (...)."""
    if not names:
        return np.zeros((*np.shape(vx), 0))
    cols = feature_values(names, np.asarray(vx), np.asarray(yaw_rate), np.asarray(gear))
    return np.stack([np.asarray(c, dtype=np.float64) for c in cols], axis=-1)


def trial_features(spec: CandidateSpec, tr: Trial) -> np.ndarray:
    """Measured-state features (T, F) of a trial for ``spec`` (identification only)."""
    return feature_matrix(spec.features, tr["vx"], tr["yaw_rate"], tr["gear"])
