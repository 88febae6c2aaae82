"""Validation of one trial, run on every load: never repair, fail with one clear line.

Every rule (docs/data.md lists them) raises :class:`TrialDataError`, a
:class:`~parknss.errors.DataError` whose message names the source file, the channel and
the problem, e.g. ``logs/t3.csv: channel 'vx': 12 NaN values (first at t=3.21 s)``.
The tolerances are named config values (:class:`ValidationConfig`, configs/data.yaml).
"""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

import numpy as np
from pydantic import Field, ValidationError, field_validator

from parknss.config import CONFIG_DIR, StrictModel, read_yaml_mapping, shipped_config
from parknss.data.trial import Trial
from parknss.errors import ConfigError, DataError
from parknss.signals import (
    CHANNEL_BY_NAME,
    DT,
    REQUIRED_CHANNELS,
    SAMPLE_RATE_HZ,
)

DATA_CONFIG_NAME = "data.yaml"
DATA_CONFIG_YAML = CONFIG_DIR / DATA_CONFIG_NAME
GEAR_VALUES: tuple[float, ...] = (-1.0, 0.0, 1.0)

M = TypeVar("M", bound=StrictModel)


class ValidationConfig(StrictModel):
    """Tolerances of :func:`validate_trial`.

    Attributes:
        min_samples: shortest accepted trial, samples (100 = 1 s at 100 Hz).
        dt_tolerance_s: every time step must lie within DT ± this, s.
        ranges: plausible [lo, hi] per schema channel, schema units: wide enough for
            any car on any road, narrow enough to catch a unit error (configs/data.yaml
            is the one place they are written).
    """

    min_samples: int = Field(100, ge=2)
    dt_tolerance_s: float = Field(1.0e-3, gt=0.0, lt=DT / 2)
    ranges: dict[str, tuple[float, float]] = Field(default_factory=dict)

    @field_validator("ranges")
    @classmethod
    def _schema_ranges(cls, v: dict[str, tuple[float, float]]):
        unknown = sorted(set(v) - set(CHANNEL_BY_NAME))
        if unknown:
            raise ValueError(f"not schema channels: {', '.join(unknown)}")
        bad = [k for k, (lo, hi) in v.items() if not lo < hi]
        if bad:
            raise ValueError(f"range of {bad[0]!r} needs lo < hi")
        return v

    def range_of(self, name: str) -> tuple[float, float]:
        """The plausible [lo, hi] of a schema channel in schema units (configs/data.yaml)."""
        if name not in self.ranges:
            raise ConfigError(
                f"{DATA_CONFIG_YAML}: validation.ranges has no plausible range for {name!r}"
            )
        return self.ranges[name]


def load_data_section(cls: type[M], section: str, path: str | Path | None = None) -> M:
    """Read section ``section`` of the data config YAML (default configs/data.yaml) as cls.

    A missing file (the shipped one included), bad YAML, unknown keys or wrong types give
    a one-line ConfigError.
    """
    p = Path(path) if path is not None else shipped_config(DATA_CONFIG_NAME)
    doc = read_yaml_mapping(p)
    if not set(doc) <= {"validation", "describe"}:
        raise ConfigError(f"{p}: expected a mapping with sections 'validation' and 'describe'")
    try:
        return cls.model_validate(doc.get(section) or {})
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"])
        raise ConfigError(f"{p}: field {section}.{loc}: {err['msg']}") from exc


def load_validation_config(path: str | Path | None = None) -> ValidationConfig:
    """The ``validation`` section of configs/data.yaml (or of ``path``)."""
    return load_data_section(ValidationConfig, "validation", path)


class TrialDataError(DataError):
    """A trial failed validation: ``source: channel 'name': problem`` in one line."""

    def __init__(self, source: str, problem: str, channel: str | None = None):
        self.source, self.problem, self.channel = source, problem, channel
        where = f"channel {channel!r}: " if channel is not None else ""
        super().__init__(f"{source}: {where}{problem}")


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def _at(t: np.ndarray | None, i: int) -> str:
    """Location of sample i: its time stamp when t is usable, else its row (1-based)."""
    if t is not None and np.isfinite(t[i]):
        return f"t={t[i]:.2f} s"
    return f"row {i + 1}"


def _check_metadata(trial: Trial, source: str) -> None:
    if not isinstance(trial.id, str) or not trial.id.strip():
        raise TrialDataError(source, "trial id is empty")
    if not isinstance(trial.maneuver, str) or not trial.maneuver.strip():
        raise TrialDataError(source, "maneuver class is empty")
    if isinstance(trial.repetition, bool) or not isinstance(trial.repetition, int | np.integer):
        raise TrialDataError(source, f"repetition {trial.repetition!r} is not an integer")
    if trial.repetition < 1:
        raise TrialDataError(source, f"repetition {trial.repetition} must be >= 1")
    if abs(float(trial.sample_rate_hz) - SAMPLE_RATE_HZ) > 1e-9:
        raise TrialDataError(
            source,
            f"sample rate {_fmt(trial.sample_rate_hz)} Hz in the metadata, expected "
            f"{_fmt(SAMPLE_RATE_HZ)} Hz",
        )


def _as_vectors(trial: Trial, source: str, required) -> dict[str, np.ndarray]:
    """Required channels present; every channel 1-D and numeric; returned as float64."""
    if "t" not in required:
        raise TrialDataError(source, "the time channel is always required", "t")
    missing = [c for c in required if c not in trial.channels]
    if missing:
        more = f" ({len(missing)} required channels missing: {', '.join(missing)})"
        raise TrialDataError(source, "missing" + (more if len(missing) > 1 else ""), missing[0])
    out: dict[str, np.ndarray] = {}
    for name, values in trial.channels.items():
        arr = np.asarray(values)
        if arr.ndim != 1:
            raise TrialDataError(source, f"expected a 1-D vector, got shape {arr.shape}", name)
        if arr.dtype.kind not in "biuf":
            raise TrialDataError(source, f"not numeric (dtype {arr.dtype})", name)
        out[name] = np.ascontiguousarray(arr, dtype=np.float64)
    return out


def _check_lengths(ch: dict[str, np.ndarray], source: str, cfg: ValidationConfig) -> None:
    n = len(ch["t"])
    for name, arr in ch.items():
        if len(arr) != n:
            raise TrialDataError(
                source, f"{len(arr)} samples, but channel 't' has {n} (unequal lengths)", name
            )
    if n < cfg.min_samples:
        raise TrialDataError(
            source,
            f"only {n} samples ({n * DT:.2f} s), at least {cfg.min_samples} required",
            "t",
        )


def _check_finite(name: str, arr: np.ndarray, t: np.ndarray | None, source: str) -> None:
    bad = ~np.isfinite(arr)
    if not bad.any():
        return
    nan = np.isnan(arr)
    kind = "NaN" if nan.any() else "infinite"
    idx = np.flatnonzero(nan if nan.any() else bad)
    raise TrialDataError(source, f"{len(idx)} {kind} values (first at {_at(t, int(idx[0]))})", name)


def _check_time(t: np.ndarray, source: str, cfg: ValidationConfig) -> None:
    """t strictly increasing, at 100 Hz within tolerance, without gaps."""
    _check_finite("t", t, None, source)
    dt = np.diff(t)
    dup = np.flatnonzero(dt == 0.0)
    if len(dup):
        raise TrialDataError(
            source, f"{len(dup)} duplicate timestamps (first at {_at(t, int(dup[0]))})", "t"
        )
    back = np.flatnonzero(dt < 0.0)
    if len(back):
        k = int(back[0])
        raise TrialDataError(
            source,
            f"time goes backwards at {len(back)} steps (first from t={t[k]:.2f} s to "
            f"t={t[k + 1]:.2f} s)",
            "t",
        )
    tol = cfg.dt_tolerance_s
    med = float(np.median(dt))
    if abs(med - DT) > tol:
        raise TrialDataError(
            source,
            f"sample rate {_fmt(1.0 / med)} Hz (median dt {_fmt(med)} s), expected "
            f"{_fmt(SAMPLE_RATE_HZ)} Hz (dt {DT} s ± {tol} s)",
            "t",
        )
    gaps = np.flatnonzero(dt > DT + tol)
    short = np.flatnonzero(dt < DT - tol)
    if len(gaps) or len(short):
        k = int(min(gaps[:1].tolist() + short[:1].tolist()))
        what = (
            f"{len(gaps)} gaps in time (first of {_fmt(dt[k])} s"
            if dt[k] > DT
            else f"irregular sampling: {len(short)} steps too short (first of {_fmt(dt[k])} s"
        )
        raise TrialDataError(
            source, f"{what} after t={t[k]:.2f} s; expected dt {DT} s ± {tol} s)", "t"
        )


def _check_gear(g: np.ndarray, t: np.ndarray, source: str) -> None:
    bad = np.flatnonzero(~np.isin(g, GEAR_VALUES))
    if len(bad):
        k = int(bad[0])
        raise TrialDataError(
            source,
            f"value {_fmt(g[k])} at {_at(t, k)} not in {{-1, 0, 1}} ({len(bad)} samples outside)",
            "gear",
        )


def _check_range(
    name: str, arr: np.ndarray, t: np.ndarray, source: str, cfg: ValidationConfig
) -> None:
    ch = CHANNEL_BY_NAME[name]
    lo, hi = cfg.range_of(name)
    bad = np.flatnonzero((arr < lo) | (arr > hi))
    if not len(bad):
        return
    k = int(bad[np.argmax(np.abs(arr[bad]))])
    hint = ""
    if name == "t":
        hint = "; time must count from the trial start (see time.start_at_zero in a mapping)"
    raise TrialDataError(
        source,
        f"{len(bad)} values outside the plausible range [{_fmt(lo)}, {_fmt(hi)}] "
        f"{ch.unit} (worst {_fmt(arr[k])} at {_at(t, k)}){hint}",
        name,
    )


def validate_trial(
    trial: Trial,
    source: str,
    config: ValidationConfig | None = None,
    required: tuple[str, ...] | list[str] = REQUIRED_CHANNELS,
) -> Trial:
    """Check one trial against the schema; return it with float64 channels, or raise.

    Args:
        trial: the trial to check (not modified).
        source: the file it came from, named in every error.
        config: tolerances (default: configs/data.yaml ``validation``).
        required: the schema channels the trial must have (default all twelve; a
            campaign whose mapping declares channels absent passes its own set).

    Returns:
        A Trial with the same metadata and every channel as a contiguous float64 (T,) array.

    Raises:
        TrialDataError: the first rule violated, as ``source: channel 'x': problem``.
    """
    cfg = config or load_validation_config()
    _check_metadata(trial, source)
    ch = _as_vectors(trial, source, required)
    _check_lengths(ch, source, cfg)
    t = ch["t"]
    _check_time(t, source, cfg)
    for name, arr in ch.items():
        _check_finite(name, arr, t, source)
    if "gear" in ch:
        _check_gear(ch["gear"], t, source)
    for name in REQUIRED_CHANNELS:
        if name in ch:
            _check_range(name, ch[name], t, source, cfg)
    return Trial(
        id=trial.id,
        maneuver=trial.maneuver,
        repetition=int(trial.repetition),
        channels=ch,
        vehicle_id=trial.vehicle_id,
        sample_rate_hz=float(trial.sample_rate_hz),
        provenance=trial.provenance,
    )
