"""Configuration of the evaluation studies (``configs/experiments.yaml``).

Budgets (``full``: the paper's; ``quick``: a smoke test), the seed-noise and convergence
splits, the learning-curve grid, the Table III ablation axes and the result store. Each
axis option is a set of NSS config overrides (``{section: {field: value}}``, see
:func:`parknss.nss.config.with_overrides`) and optionally a training-window rule.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, field_validator

from parknss.config import StrictModel, load_config
from parknss.errors import ConfigError
from parknss.nss.config import FUSED_KERNELS

Overrides = dict[str, dict[str, Any]]


class SplitRef(StrictModel):
    """One fold of a split: ``split`` "cv" or "leave" (with ``r``), fold ``index``."""

    split: Literal["cv", "leave"] = "cv"
    index: int = Field(0, ge=0)
    r: int = Field(1, ge=1)


class Budget(StrictModel):
    """How much compute a run of the studies spends."""

    epochs: int = Field(3000, ge=1, description="epoch cap of every study fit")
    convergence_epochs: int = Field(3200, ge=1, description="epoch cap of the Fig. 4 probe")
    folds: list[int] = Field([0, 1, 2, 3], description="folds of each split")
    ablation_folds: list[int] = Field([0, 1, 2, 3], description="CV folds per ablation option")
    seeds: list[int] = Field([0, 1, 2, 3, 4], description="seeds of the noise-floor study")
    floor_seeds: list[int] = Field(
        [0, 1, 2], description="seeds of the per-fold floor on the other folds of `folds`")
    loss_lrs: list[float] = Field([1e-3, 2e-3, 4e-3], description="LR sweep per loss")
    sim_cells: list[int] | None = Field(None, description="Table V cells (None: all 36)")
    sim_scene: int = Field(0, ge=0, description="grid cell drawn in Figs. 8/9")
    sim_plants: list[Literal["kinematic", "chain", "reference"]] = Field(
        ["kinematic", "chain", "reference"], min_length=1,
        description="Table V plants (chain: left out, with a note, when there is none)")
    tta_folds: list[int] = Field([0, 1, 2, 3], description="CV folds of the recipe comparison")
    tta_recipes: list[str] = Field(
        ["fast", "coarse", "coarse+native"], min_length=1,
        description="the recipes the time-to-accuracy comparison holds against the paper's: "
        "fast or coarse, each optionally with the fused kernels it runs, `coarse+native`")
    overrides: Overrides = Field(default_factory=dict, description="NSS overrides, all fits")
    recipe: Literal["paper", "fast", "coarse"] = Field(
        "paper",
        description="training recipe of the seed-noise, learning-curve, limiter and ablation "
        "fits (the floor and what it judges share it); Table II, Fig. 4 and the axes marked "
        "`recipe` keep theirs",
    )

    def study_overrides(self, recipe: str | None = None) -> Overrides:
        """The NSS overrides of a study fit: the budget's, its epoch cap and the recipe
        (``recipe``, else the budget's)."""
        train = {"epochs": self.epochs, "recipe": recipe or self.recipe}
        return merge_overrides(self.overrides, {"train": train})

    def deployment_overrides(self) -> Overrides:
        """The NSS overrides of a fit of the paper's deployment protocol (Table II, Fig. 4,
        the paper side of the time-to-accuracy comparison): the budget's, the deployment
        cap ``convergence_epochs`` and the paper's recipe whatever the NSS config says."""
        train = {"epochs": self.convergence_epochs, "recipe": "paper"}
        return merge_overrides(self.overrides, {"train": train})

    @field_validator("tta_recipes")
    @classmethod
    def _challengers(cls, v: list[str]) -> list[str]:
        for name in v:
            recipe, _, kernels = name.partition("+")
            if recipe not in ("fast", "coarse") or (kernels and kernels not in FUSED_KERNELS):
                raise ValueError(f"tta_recipes: {name!r} is not fast or coarse, optionally "
                                 f"+ fused kernels ({', '.join(FUSED_KERNELS)})")
        if len(set(v)) != len(v):
            raise ValueError("tta_recipes: a challenger is named twice")
        return v

    @field_validator("folds", "ablation_folds", "seeds", "loss_lrs", "tta_folds")
    @classmethod
    def _nonempty(cls, v: list) -> list:
        if not v:
            raise ValueError("must not be empty")
        return v


class AblationOption(StrictModel):
    """One option of an axis: NSS overrides and/or a window rule."""

    label: str
    overrides: Overrides = Field(default_factory=dict)
    quick_overrides: Overrides | None = Field(
        None, description="replace `overrides` under --quick (None: same as full)"
    )
    window: str | None = Field(
        None, description="shortest | longest | padding:F (fraction of padded samples)"
    )
    deployed: bool = Field(False, description="the option carried into the deployed model")

    @field_validator("window")
    @classmethod
    def _window(cls, v: str | None) -> str | None:
        if v is None or v in ("shortest", "longest"):
            return v
        head, _, frac = v.partition(":")
        try:
            ok = head == "padding" and 0.0 < float(frac) < 1.0
        except ValueError:
            ok = False
        if not ok:
            raise ValueError("window must be shortest, longest or padding:F with 0 < F < 1")
        return v


class AblationAxis(StrictModel):
    """One row block of Table III."""

    name: str
    options: list[AblationOption]
    lr_sweep: bool = Field(False, description="each option at its best LR of budget.loss_lrs")
    recipe: Literal["paper", "fast", "coarse"] | None = Field(
        None,
        description="the recipe this axis needs (paper: an axis of the paper's training "
        "protocol, which the fast recipe does not read); None: the budget's",
    )
    cost: bool = Field(False, description="report wall-clock cost ratios")

    @field_validator("options")
    @classmethod
    def _options(cls, v: list[AblationOption]) -> list[AblationOption]:
        if len(v) < 2:
            raise ValueError("an axis needs at least two options")
        if sum(o.deployed for o in v) != 1:
            raise ValueError("exactly one option of an axis must be marked deployed")
        return v


class VerdictConfig(StrictModel):
    """How a finding is decided (:mod:`parknss.experiments.verdict`)."""

    resamples: int = Field(2000, ge=100, description="paired-bootstrap resamples per effect")
    seed: int = Field(0, description="seed of the bootstrap's generator")
    level: float = Field(0.95, gt=0.5, lt=1.0, description="confidence level of the intervals")
    min_seeds: int = Field(
        3, ge=2, description="seeds a fold needs for its own floor (fewer: the pooled floor)")
    tie_margin: float = Field(
        0.05, gt=0.0, description="|effect| of a claim of no effect that gives no tolerance")
    metric: Literal["moving", "full", "truth_full"] = Field(
        "moving", description="the metric verdicts are read on: moving (the paper's, "
        "measured |vx| >= 0.5 km/h), full (every sample), truth_full (every sample, truth)")
    beside: Literal["moving", "full", "truth_full"] | None = Field(
        "full", description="a second metric whose verdicts the report shows beside")


class StoreConfig(StrictModel):
    """The result store (:mod:`parknss.experiments.store`)."""

    dir: str = Field(
        "auto", description="auto: the checkout's results/ (off in an installed wheel); off; "
        "or a folder. --store and $PARKNSS_RESULTS take precedence"
    )
    write_quick: bool = Field(False, description="--quick runs write their fits to the store")


class ExperimentsConfig(StrictModel):
    """Everything the studies need besides the NSS config itself."""

    floor_z: float = Field(2.0, gt=0.0, description="effect beyond floor: |rel| > floor_z·CV")
    max_floor: float = Field(
        0.1, gt=0.0, description="a z·CV wider than this cannot confirm a claim of no effect"
    )
    paper_floor: dict[str, float] = Field(
        default_factory=lambda: {"vx": 0.02, "yaw": 0.035},
        description="the paper's seed CVs; used only where no floor was measured",
    )
    divergence_factor: float = Field(2.0, gt=1.0)
    same_order: float = Field(
        3.0, gt=1.0, description="two spreads are 'of the same order' within this factor"
    )
    learning_curve_rs: list[int] = Field([1, 2, 3])
    extrapolate_to: int = Field(16, ge=1, description="training trials of the all-16 model")
    seed_noise_split: SplitRef = SplitRef(index=1)
    convergence_split: SplitRef = SplitRef(index=0)
    loss_lr_metric: str = "vx_mse_moving_kmh2"
    tta_speedup: float = Field(
        8.0, gt=0.0, description="CPU-time factor a challenger recipe must reach the paper's "
        "error in")
    full: Budget = Budget()
    quick: Budget = Budget(epochs=4, convergence_epochs=8, folds=[0, 1], ablation_folds=[0])
    axes: list[AblationAxis] = Field(default_factory=list)
    verdict: VerdictConfig = VerdictConfig()
    store: StoreConfig = StoreConfig()

    def digest(self) -> str:
        """Stable short hash of the values that decide results (run folders): the ``store``
        section is left out, where fits are kept does not change them."""
        blob = json.dumps(self.model_dump(mode="json", exclude={"store"}), sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:16]

    def budget(self, quick: bool) -> Budget:
        return self.quick if quick else self.full

    def axis(self, name: str) -> AblationAxis | None:
        return next((a for a in self.axes if a.name == name), None)

    def with_axes(self, names: Sequence[str]) -> ExperimentsConfig:
        """This config with only the Table III axes ``names``, in the config's order (so a
        study can be run axis by axis, e.g. across sittings); an unknown name is an error
        that lists the config's axes."""
        known = [a.name for a in self.axes]
        unknown = [n for n in names if n not in known]
        if unknown or not names:
            raise ConfigError(f"no ablation axis {', '.join(map(repr, unknown)) or 'named'}; "
                              f"the config's axes: {', '.join(map(repr, known))}")
        return self.model_copy(update={"axes": [a for a in self.axes if a.name in names]})


def load_experiments_config(path: str | Path | None = None) -> ExperimentsConfig:
    """The studies' config: ``path``, else the shipped configs/experiments.yaml."""
    return load_config(ExperimentsConfig, path, default="experiments.yaml")


def merge_overrides(*layers: Overrides | None) -> Overrides:
    """Section-wise merge, later layers winning field by field."""
    out: Overrides = {}
    for layer in layers:
        for sec, vals in (layer or {}).items():
            out[sec] = {**out.get(sec, {}), **vals}
    return out
