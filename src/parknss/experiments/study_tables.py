"""Report tables of the studies (:class:`~parknss.experiments.registry.Table`), and a
fixed-width text rendering for the terminal. Errors: moving-region MSE, vx in (km/h)²,
ω_z in (°/s)²; "truth" columns against the noise-free channels of a synthetic campaign."""

from __future__ import annotations

import math
from typing import Any

from parknss.experiments.ablations import AblationResult
from parknss.experiments.convergence import ConvergenceResult
from parknss.experiments.learning_curve import LearningCurveResult
from parknss.experiments.limiter_study import LimiterResult
from parknss.experiments.noise import SeedNoiseResult
from parknss.experiments.results import Table

VX = "vx [(km/h)²]"
YAW = "ω_z [(°/s)²]"
VX_TRUTH = "vx vs truth [(km/h)²]"
REV_VX = "rev. vx [(km/h)²]"


def _r(x: float, digits: int = 4) -> float | str:
    return "n/a" if x is None or not math.isfinite(x) else round(x, digits)


def _yn(b: bool | None) -> str:
    return {True: "yes", False: "no", None: "n/a"}[b]


def learning_curve_tables(res: LearningCurveResult) -> list[Table]:
    rows: list[list[Any]] = []
    for p in res.points:
        rows.append(
            [
                p.n_train,
                p.r,
                ", ".join(f"{v:.4g}" for v in p.values("vx")),
                _r(p.mean("vx")),
                _r(p.mean("yaw")),
                _r(p.mean("vx_truth")),
            ]
        )
    rows.append(
        [
            f"{res.extrapolate_to} (fit)",
            0,
            "",
            _r(res.extrapolated("vx")),
            _r(res.extrapolated("yaw")),
            "",
        ]
    )
    fits = [[ch, _r(f.a), _r(f.b)] for ch, f in res.fits.items()]
    return [
        Table(
            f"Learning curve ({res.epochs} epochs; fold means, power-law extrapolation)",
            ["training trials", "r", "vx per fold [(km/h)²]", f"mean {VX}", f"mean {YAW}",
             f"mean {VX_TRUTH}"],
            rows,
        ),
        Table("Power-law fits e(n) = a·n^-b of the fold means", ["channel", "a", "b"], fits),
    ]


def seed_noise_tables(res: SeedNoiseResult) -> list[Table]:
    rows = [
        [s, _r(sc.vx), _r(sc.yaw), _r(sc.vx_truth), sc.best_epoch, _r(sc.wall_s, 1)]
        for s, sc in zip(res.seeds, res.scores, strict=True)
    ]
    rows.append(
        [
            "CV",
            f"{100 * res.floor.vx:.2f} %",
            f"{100 * res.floor.yaw:.2f} %",
            "",
            "",
            "",
        ]
    )
    return [
        Table(
            f"Seed-noise floor ({res.split} fold {res.index}, {res.epochs} epochs; paper "
            "CV about 2 % vx, 3-4 % yaw)",
            ["seed", VX, YAW, VX_TRUTH, "best epoch", "wall [s]"],
            rows,
        )
    ]


def floor_table(judge) -> Table:
    """The per-fold seed floor (:class:`~parknss.experiments.judge.Judge`): per CV fold its
    floor fits and the seed CV (ddof 1) of vx and ω_z on every metric; n/a below two."""
    from parknss.experiments.judge import METRICS, metric_value

    rows: list[list[Any]] = []
    for k, by_seed in sorted(judge.seeds.fits.items()):
        row: list[Any] = [f"fold {k}", ", ".join(map(str, sorted(by_seed)))]
        for metric in METRICS:
            for ch in ("vx", "yaw"):
                noise = judge.seeds.spread(lambda s, m=metric, c=ch: metric_value(s, c, m), 2,
                                           True)
                v = noise.sd.get(k, math.nan)
                row.append("n/a" if not math.isfinite(v) else f"{100 * v:.1f} %")
        rows.append(row)
    cols = ["fold", "seeds"] + [f"{m} {ch}" for m in METRICS for ch in ("vx", "ω_z")]
    return Table(f"Seed floor per fold (CV, ddof 1; a fold with fewer than "
                 f"{judge.cfg.min_seeds} seeds borrows the pooled floor in the verdicts)",
                 cols, rows)


def ablation_tables(res: AblationResult) -> list[Table]:
    fl = res.floor
    rows: list[list[Any]] = []
    sweeps: list[list[Any]] = []
    for ax in res.axes:
        for o in ax.options:
            e_vx, e_yaw = ax.effect(o.label, "vx"), ax.effect(o.label, "yaw")
            beyond = (
                "deployed"
                if o.deployed
                else (f"vx {_yn(fl.exceeds(e_vx, 'vx'))} / ω_z {_yn(fl.exceeds(e_yaw, 'yaw'))}")
            )
            extra = f"L = {sorted(set(o.windows))}" if o.windows else ""
            if o.lr is not None:
                extra = f"LR {o.lr:g}"
            if ax.recipe != "paper":  # the title's epochs are the paper recipe's
                extra = ", ".join(x for x in (extra, f"{ax.recipe} recipe") if x)
            rows.append(
                [
                    ax.name,
                    o.label + (" †" if o.deployed else ""),
                    _r(o.mean("vx")),
                    _r(o.mean("yaw")),
                    _r(o.mean("vx_truth")),
                    "" if o.deployed else f"{100 * e_vx:+.1f} / {100 * e_yaw:+.1f}",
                    beyond,
                    _r(o.wall_s(), 1),
                    _r(o.wall_per_epoch(), 3),
                    _r(o.cpu_per_epoch(), 3),
                    (f"x{ax.cost_ratio(o.label):.2f} ({ax.cost_basis(o.label)})"
                     if ax.cost else ""),
                    extra,
                ]
            )
            for lr, v in sorted(o.lr_sweep.items()):
                sweeps.append([ax.name, o.label, lr, _r(v)])
    for u in res.unmeasured:  # a --stored-only run: the axes the store cannot build yet
        rows.append([u.name, u.describe(), *[""] * 10])
    tables = [
        Table(
            f"Table III: design ablations on held-out maneuvers ({res.epochs} epochs, CV folds "
            f"{res.folds}; † deployed; {fl.describe()})",
            [
                "axis",
                "option",
                VX,
                YAW,
                VX_TRUTH,
                "effect vx / ω_z [%]",
                "beyond floor",
                "wall per fit [s]",
                "wall s/epoch",
                "CPU s/epoch",
                "cost (CPU, else wall)",
                "setting",
            ],
            rows,
        )
    ]
    if sweeps:
        tables.append(
            Table(
                "LR sweep per option (fold-mean selection metric)",
                ["axis", "option", "LR", "selection metric"],
                sweeps,
            )
        )
    return tables


def limiter_tables(res: LimiterResult) -> list[Table]:
    rows = []
    for v in res.variants:
        rows.append(
            [
                v.variant,
                _r(v.vx),
                _r(v.vx_reverse),
                _r(v.yaw),
                "" if v.variant == "none" else _pct2(res.effect(v.variant, "vx")),
                "" if v.variant == "none" else _yn(res.diverges(v.variant)),
            ]
        )
    return [
        Table(
            f"Inference limiter on the same models (CV folds {res.folds}, {res.epochs} epochs; "
            f"{res.floor.describe()})",
            ["limiter", VX, REV_VX, YAW, "vx change", "diverges"],
            rows,
        )
    ]


def _pct2(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{100 * x:+.1f} %"


def convergence_tables(res: ConvergenceResult) -> list[Table]:
    return [
        Table(
            f"Convergence probe ({res.split} fold {res.index}, cap {res.epoch_cap} epochs)",
            ["optimum epoch", "best smoothed loss", "late variation", VX, YAW],
            [
                [
                    res.best_epoch,
                    _r(min(res.smooth)) if res.smooth else "n/a",
                    f"{100 * res.late_variation():.2f} %" if res.smooth else "n/a",
                    _r(res.score.vx),
                    _r(res.score.yaw),
                ]
            ],
        )
    ]


def text_table(t: Table) -> str:
    """Fixed-width text of a table (title, header, rows)."""
    cells = [[str(c) for c in t.columns]] + [[_fmt(c) for c in row] for row in t.rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(t.columns))]
    lines = [t.title]
    for r in cells:
        lines.append(
            "  ".join(
                c.ljust(w) if i == 0 else c.rjust(w)
                for i, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
    return "\n".join(lines)


def _fmt(c: Any) -> str:
    return f"{c:.4g}" if isinstance(c, float) else str(c)
