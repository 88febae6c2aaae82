"""The common interface of every actuator candidate, and the factory.

Every candidate maps a scalar command history (and, in the state-aware variants, state
features) to the channel's actual, in physical units:

* ``rollout(cmd (B, T), feat (B, T, F), y0 (B,)) -> (B, T)``: batched, differentiable,
  over whole histories (used by fitting, selection, co-tuning and the chain);
* ``init_state(cmd0 (B,), y0 (B,))`` and ``step(state, cmd (B,), feat (B, F))
  -> (y (B,), state)``: the same recurrence one sample at a time (the chain's interleaved
  loop when submodels read NSS-predicted states);
* ``stepper()``: a NumPy float64 real-time twin with a ring buffer
  (:mod:`parknss.actuators.steppers`; each class names its twin in ``stepper_cls``),
  equal to ``rollout`` to rounding (tests/actuators/test_models.py).

The architectures are implemented in :mod:`parknss.actuators.lags` and
:mod:`parknss.actuators.neural`; :mod:`parknss.actuators.candidates` holds the one table
from an architecture name to its class and builds candidates.

Timing: y[k] may depend on cmd[0..k] and feat[0..k]. The lag family (lag1, lag2,
hammerstein) starts from the measured actual y[0] = y0 and y[k] depends on inputs up to
k-1; NARX sees the command window ending at k (history before k = 0 is the first command
repeated); GRU/LSTM start from a zero hidden state and ignore y0. Inside, commands,
features and actuals are min-max scaled to [-1, 1] with statistics fitted on the training
trials (:class:`Scaling`), stored as buffers so the artefact carries them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch
from torch import Tensor, nn

from parknss.actuators.config import ArchConfig
from parknss.actuators.spec import CandidateSpec
from parknss.actuators.steppers import Stepper
from parknss.signals import DT


@dataclass(frozen=True)
class Scaling:
    """Affine scalings x̃ = (x - off) / sc of command, features (F,) and actual."""

    c_off: float
    c_sc: float
    f_off: tuple[float, ...]
    f_sc: tuple[float, ...]
    y_off: float
    y_sc: float

    @staticmethod
    def _minmax(x: np.ndarray) -> tuple[float, float]:
        lo, hi = float(np.min(x)), float(np.max(x))
        sc = 0.5 * (hi - lo)
        return 0.5 * (lo + hi), sc if sc > 1e-9 else 1.0

    @classmethod
    def fit(cls, cmd: np.ndarray, feat: np.ndarray, y: np.ndarray, names) -> Scaling:
        """Min-max statistics of concatenated training samples (gear kept as is)."""
        c_off, c_sc = cls._minmax(cmd)
        y_off, y_sc = cls._minmax(y)
        f_off, f_sc = [], []
        for i, n in enumerate(names):
            o, s = (0.0, 1.0) if n == "gear" else cls._minmax(feat[:, i])
            f_off.append(o)
            f_sc.append(s)
        return cls(c_off, c_sc, tuple(f_off), tuple(f_sc), y_off, y_sc)

    def to_json(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in self.__dict__.items()}

    @classmethod
    def from_json(cls, d: dict) -> Scaling:
        return cls(
            float(d["c_off"]), float(d["c_sc"]), tuple(map(float, d["f_off"])),
            tuple(map(float, d["f_sc"])), float(d["y_off"]), float(d["y_sc"]),
        )


class ActuatorModel(nn.Module):
    """Base class: the scaling buffers and the shared helpers (see the module doc).

    Class attributes: ``stepper_cls``, the NumPy real-time twin; ``fit_family``, which
    optimiser budget of :class:`~parknss.actuators.config.FitConfig` fits it ("linear":
    iters_linear/lr_linear, "neural": iters_neural/lr_neural).
    """

    stepper_cls: ClassVar[type[Stepper]]
    fit_family: ClassVar[str] = "neural"

    def __init__(self, spec: CandidateSpec, scaling: Scaling, cfg: ArchConfig) -> None:
        super().__init__()
        self.spec = spec
        self.scaling = scaling
        self.cfg = cfg
        self.dt = DT
        self.n_feat = len(spec.features)
        f64 = torch.float64
        self.register_buffer("c_off", torch.tensor(scaling.c_off, dtype=f64))
        self.register_buffer("c_sc", torch.tensor(scaling.c_sc, dtype=f64))
        self.register_buffer("f_off", torch.tensor(scaling.f_off, dtype=f64).reshape(-1))
        self.register_buffer("f_sc", torch.tensor(scaling.f_sc, dtype=f64).reshape(-1))
        self.register_buffer("y_off", torch.tensor(scaling.y_off, dtype=f64))
        self.register_buffer("y_sc", torch.tensor(scaling.y_sc, dtype=f64))

    # scaling helpers (any leading shape)
    def sc_cmd(self, c: Tensor) -> Tensor:
        return (c - self.c_off) / self.c_sc

    def sc_feat(self, f: Tensor) -> Tensor:
        return (f - self.f_off) / self.f_sc

    def sc_y(self, y: Tensor) -> Tensor:
        return (y - self.y_off) / self.y_sc

    def unsc_y(self, y: Tensor) -> Tensor:
        return y * self.y_sc + self.y_off

    def features_or_empty(self, feat: Tensor | None, shape: tuple[int, ...]) -> Tensor:
        if feat is None or self.n_feat == 0:
            return torch.zeros(*shape, self.n_feat, dtype=self.c_off.dtype)
        return self.sc_feat(feat)

    def init_affine(self, k: float, b: float, w: np.ndarray) -> None:
        """Start from the static least-squares map ỹ = k·c̃ + b + w·f̃ (scaled units)."""

    def init_samples(self, cs: np.ndarray, fs: np.ndarray, ys: np.ndarray) -> None:
        """Refine the start from the scaled training samples (command (N,), features (N, F),
        actual (N,)) after :meth:`init_affine`; nothing by default."""

    # interface (subclasses implement)
    def rollout(self, cmd: Tensor, feat: Tensor | None, y0: Tensor) -> Tensor:
        raise NotImplementedError

    def init_state(self, cmd0: Tensor, y0: Tensor) -> tuple[Tensor, ...]:
        raise NotImplementedError

    def step(self, state, cmd: Tensor, feat: Tensor | None) -> tuple[Tensor, tuple]:
        raise NotImplementedError

    def numpy_params(self) -> dict[str, np.ndarray]:
        """Every parameter and buffer as a float64 NumPy array (for the real-time twin)."""
        items = [*self.named_parameters(), *self.named_buffers()]
        return {k: v.detach().to(torch.float64).numpy().copy() for k, v in items}

    def stepper(self) -> Stepper:
        """The NumPy float64 real-time twin of this candidate (weights copied now)."""
        return self.stepper_cls(self)


def parameter_count(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))
