"""A tiny campaign and a tiny studies config for the experiment tests (seconds per study)."""

from __future__ import annotations

from pathlib import Path

import yaml

from helpers.synth import make_campaign
from parknss.data.io import write_campaign

TINY_NET = {
    "model": {"state_layers": 1, "state_units": 4, "output_layers": 1, "output_units": 4},
    "train": {"val_every": 1, "smooth_window": 1},
    "fast": {"window": 40, "batch": 4, "updates": 6, "val_every": 2, "finish_epochs": 2},
    "coarse": {"factor": 4, "epochs": 6, "val_every": 2, "finish_epochs": 2},
}

TINY_CONFIG = {
    "floor_z": 2.0,
    "full": {
        "epochs": 2,
        "convergence_epochs": 3,
        "folds": [0, 1],
        "ablation_folds": [0],
        "seeds": [0, 1, 2],
        "loss_lrs": [1.0e-3, 2.0e-3],
        "tta_folds": [0, 1],
        "overrides": TINY_NET,
    },
    "quick": {
        "epochs": 1,
        "convergence_epochs": 2,
        "folds": [0],
        "ablation_folds": [0],
        "seeds": [0, 1],
        "loss_lrs": [2.0e-3],
        "overrides": TINY_NET,
    },
    "axes": [
        {
            "name": "loss",
            "lr_sweep": True,
            "options": [
                {"label": "MAE", "overrides": {"loss": {"kind": "mae"}}, "deployed": True},
                {"label": "MSE", "overrides": {"loss": {"kind": "mse"}}},
            ],
        },
        {
            "name": "training window",
            "options": [
                {"label": "shortest", "window": "shortest", "deployed": True},
                {"label": "longest", "window": "longest"},
            ],
        },
        {
            "name": "yaw readout",
            "options": [
                {
                    "label": "residual",
                    "overrides": {"model": {"residual_yaw": True}},
                    "deployed": True,
                },
                {"label": "direct", "overrides": {"model": {"residual_yaw": False}}},
            ],
        },
    ],
}


def tiny_setup(tmp_path: Path) -> tuple[Path, Path]:
    """(campaign folder, experiments YAML) under tmp_path: 16 trials of ~400-470 samples."""
    data = write_campaign(make_campaign(n=400), tmp_path / "campaign")
    cfg = tmp_path / "experiments.yaml"
    cfg.write_text(yaml.safe_dump(TINY_CONFIG))
    return data, cfg
