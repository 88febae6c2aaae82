"""The paper's findings beside what the studies measured: agrees, differs or cannot tell.

Each function reads a study's typed result and returns :class:`Finding` rows for the
report's comparison table. Every effect is read by one rule
(:mod:`parknss.experiments.verdict`, through a :class:`~parknss.experiments.judge.Judge`
on one metric): paired per fold (an option against its baseline on the same fold and
seed), with a paired-bootstrap interval widened to at least the per-fold seed floor, and
the paper's claim (a difference, or no difference within a stated tolerance) read against
that interval: "agrees", "differs" or "cannot tell at this budget (effect, interval)".
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING

from parknss.experiments.ablations import AblationResult
from parknss.experiments.judge import LABELS, Judge
from parknss.experiments.learning_curve import LearningCurveResult
from parknss.experiments.limiter_study import LimiterResult
from parknss.experiments.noise import SeedNoiseResult
from parknss.experiments.results import NOT_MEASURED, Finding
from parknss.experiments.sweep import FoldScore, relative_effect
from parknss.experiments.verdict import Claim, Reading, Verdict

if TYPE_CHECKING:  # cv imports the figures (matplotlib): only its type is needed here
    from parknss.experiments.cv import CVResult

WORSE = Claim("above", 0.0)  # the option's error is higher than its baseline's
BETTER = Claim("below", 0.0)


def _pct(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{100 * x:+.1f} %"


def _lr(lr: float | None) -> str:
    return "" if lr is None else f" (LR {lr:g})"


def _finding(claim: str, v: Verdict, judge: Judge, extra: str = "",
             noise: str | None = None) -> Finding:
    measured = f"{v.text()}{extra}; {noise or judge.describe()}"
    return Finding(claim, measured, v.agrees, v.undecided())


def _axis_missing(claim: str, name: str, res: AblationResult | None = None,
                  needs: str = "") -> Finding:
    """Not measured: the axis ``name`` is unmeasured in ``res`` (its fits are not stored),
    or it (with the option it ``needs``) is not in the ablation config."""
    gap = res.unmeasured_axis(name) if res is not None else None
    why = gap.describe() if gap else (
        f"axis {name!r}{f' ({needs})' if needs else ''} is not in the ablation config")
    return Finding(claim, why, None, NOT_MEASURED)


def _option(ax, word: str):
    """The first option of an axis whose label holds ``word`` (case-insensitive)."""
    return next((o for o in ax.options if word in o.label.lower()), None)


def _by_fold(res: AblationResult, opt) -> dict[int, FoldScore]:
    return dict(zip(res.folds, opt.scores, strict=False))


def _reading(res: AblationResult, judge: Judge, opt, base, channel: str, claim: Claim,
             label: str | None = None) -> Reading:
    eff = judge.cross(_by_fold(res, opt), _by_fold(res, base), channel)
    return Reading(label or f"{opt.label} {channel}", eff, claim)


def ablation_findings(res: AblationResult, judge: Judge) -> list[Finding]:
    """Normalization, residual readout, MAE, cosine schedule, shortest windows, Euler vs
    RK4, capacity."""
    out = [_normalization_finding(res, judge)]
    claim = "The residual yaw readout lowers the moving-region vx error (paper: -27 %)"
    ax = res.axis("yaw readout")
    if ax is None:
        out.append(_axis_missing(claim, "yaw readout", res))
    else:
        base = ax.baseline()
        v = Verdict([_reading(res, judge, o, base, "vx", WORSE)
                     for o in ax.options if not o.deployed])
        out.append(_finding(claim, v, judge, " (vs the residual readout)"))
    claim = "MAE beats MSE and log-cosh, each at its best LR (vx 0.163 vs 0.173 / 0.248)"
    ax = res.axis("loss")
    if ax is None:
        out.append(_axis_missing(claim, "loss", res))
    else:
        base = ax.baseline()
        v = Verdict([_reading(res, judge, o, base, "vx", WORSE, f"{o.label}{_lr(o.lr)} vx")
                     for o in ax.options if not o.deployed])
        out.append(_finding(claim, v, judge, f" (vs MAE{_lr(base.lr)}; LRs chosen on the "
                            "scored folds)"))
    out.append(_schedule_finding(res, judge))
    claim = "The shortest training windows generalize best (vx 0.079 vs 0.103 / 0.092)"
    ax = res.axis("training window")
    if ax is None:
        out.append(_axis_missing(claim, "training window", res))
    else:
        base = ax.baseline()
        v = Verdict([_reading(res, judge, o, base, "vx", WORSE)
                     for o in ax.options if not o.deployed])
        out.append(_finding(claim, v, judge, " (vs shortest)"))
    out.append(_integrator_finding(res, judge))
    out.append(_capacity_finding(res, judge))
    return out


def _normalization_finding(res: AblationResult, judge: Judge) -> Finding:
    claim = ("Clipped min-max ties plain min-max on vx; z-score pays a vx penalty "
             "(vx 0.202 / 0.201 / 0.243)")
    ax = res.axis("normalization")
    plain = _option(ax, "plain") if ax else None
    z = _option(ax, "z-score") if ax else None
    if ax is None or plain is None or z is None:
        return _axis_missing(claim, "normalization", res, "with plain min-max and z-score")
    base, tie = ax.baseline(), Claim("within", judge.cfg.tie_margin)
    v = Verdict([_reading(res, judge, plain, base, "vx", tie),
                 _reading(res, judge, z, base, "vx", WORSE)])
    return _finding(claim, v, judge, f" (vs clipped; tie = within ±{_pct(tie.t)[1:]})")


def _schedule_finding(res: AblationResult, judge: Judge) -> Finding:
    claim = ("Cosine favours vx over the constant schedule (0.196 vs 0.202), its ω_z within "
             "the seed-noise floor")
    ax = res.axis("lr schedule")
    const = _option(ax, "constant") if ax else None
    if ax is None or const is None:
        return _axis_missing(claim, "lr schedule", res, "with a constant option")
    base, tie = ax.baseline(), Claim("within", judge.cfg.tie_margin)
    v = Verdict([_reading(res, judge, const, base, "vx", WORSE),
                 _reading(res, judge, const, base, "yaw", tie)])
    return _finding(claim, v, judge, f" (vs cosine; yaw tie = within ±{_pct(tie.t)[1:]})")


def _capacity_finding(res: AblationResult, judge: Judge) -> Finding:
    claim = "The deployed six-layer state net outperforms the smaller variants"
    ax = res.axis("capacity")
    if ax is None:
        return _axis_missing(claim, "capacity", res)
    base = ax.baseline()
    v = Verdict([_reading(res, judge, o, base, "vx", WORSE)
                 for o in ax.options if not o.deployed])
    return _finding(claim, v, judge, f" (vs {base.label})")


RK4_TIE = 0.01  # the paper's "< 1 %"
LIMITER_TIE = 0.03  # the paper's "vx changes < 3 %"


def _integrator_finding(res: AblationResult, judge: Judge) -> Finding:
    claim = "Euler ties RK4 (< 1 %) at about a third of the cost (RK4 3.1x, midpoint 1.7x)"
    ax = res.axis("integrator")
    labels = [o.label for o in ax.options] if ax else []
    rk4 = next((lbl for lbl in labels if "rk4" in lbl.lower()), None)
    if ax is None or rk4 is None:
        return _axis_missing(claim, "integrator", res, "with an RK4 option")
    eager = next((lbl for lbl in labels if "eager" in lbl.lower()), None)
    # accuracy against the eager Euler when there is one: the same engine and budget
    ref = next(o for o in ax.options if o.label == (eager or ax.baseline().label))
    opt = next(o for o in ax.options if o.label == rk4)
    tie = Claim("within", RK4_TIE)
    ratio = ax.cost_ratio(rk4)
    text = (f" (RK4 vs {ref.label}; tie = within ±1 %); cost x{ratio:.2f} vs fused Euler "
            f"({ax.cost_basis(rk4)} per step)")
    if eager is not None:
        text += (f", x{ax.cost_ratio(rk4, eager):.2f} vs eager Euler "
                 f"({ax.cost_basis(rk4, eager)} per step)")
    if ax.recipe != res.recipe:  # the floor's seeds trained with the budget's recipe
        text += f" ({ax.recipe} recipe; the floor's fits: {res.recipe})"
    v = Verdict([_reading(res, judge, opt, ref, "vx", tie, "RK4 vx"),
                 _reading(res, judge, opt, ref, "yaw", tie, "RK4 yaw")], ratio > 1.5)
    return _finding(claim, v, judge, text)


ERROR_KEYS = {"moving": ("vx_mse_moving_kmh2", "yaw_mse_moving_degs2"),
              "full": ("vx_mse_full_kmh2", "yaw_mse_full_degs2")}
"""The limiter variants' error keys per metric (they are scored against the logged
channels only: no truth_full)."""


def _limiter_effects(res: LimiterResult, variant: str, metric: str, ch: int) -> dict:
    keys = ERROR_KEYS.get(metric)
    base, var = res.get("none").per_fold_errors, res.get(variant).per_fold_errors
    if keys is None or not base:
        return {}
    def get(e: dict) -> float:
        v = e.get(keys[ch])
        return math.nan if v is None else float(v)
    return {k: relative_effect(get(v), get(b)) for k, v, b in zip(res.folds, var, base,
                                                                  strict=True)}


def limiter_findings(res: LimiterResult, judge: Judge) -> list[Finding]:
    """The limiter is redundant; clamping the residual channel diverges. The variants
    score one model per fold (no floor fits score them): the bootstrap over folds alone."""
    m = judge.metric
    rec = [judge.within_values(_limiter_effects(res, "reconstructed", m, c)) for c in (0, 1)]
    v = Verdict([Reading("limiter vx", rec[0], Claim("within", LIMITER_TIE)),
                 Reading("limiter yaw", rec[1], Claim("within", judge.cfg.tie_margin))])
    f1 = Finding(
        "The inference limiter is redundant (vx changes < 3 %, within the seed-noise floor)",
        f"{v.text()} (the limiter on the reconstructed yaw vs none; vx tie ±3 %, yaw "
        f"±{_pct(judge.cfg.tie_margin)[1:]}; bootstrap over folds, one model each); "
        f"{LABELS[m]}",
        v.agrees, v.undecided())
    r = res.get("residual")
    grow = res.divergence_factor - 1
    eff = judge.within_values(_limiter_effects(res, "residual", m, 0))
    clamp = Verdict([Reading("residual clamp vx", eff, Claim("above", grow))])
    agrees = True if not math.isfinite(r.vx) else clamp.agrees
    f2 = Finding(
        "Clamping the residual yaw channel instead makes the rollout diverge",
        f"{clamp.text()}; fold means vx {r.vx:.4g} vs {res.get('none').vx:.4g} (km/h)² on "
        f"the moving region; 'diverges' = vx > {res.divergence_factor:g}x the unlimited "
        f"rollout (effect > {_pct(grow)}); {LABELS[m]}",
        agrees, clamp.undecided())
    return [f1, f2]


def learning_curve_findings(res: LearningCurveResult, judge: Judge) -> list[Finding]:
    """Still descending at the data boundary: every step to the next larger training set
    lowers the vx error (agrees when every step's interval lies below zero, differs when
    one lies above). The sizes' folds are different splits: each step is unpaired."""
    fit = res.fits.get("vx")
    sizes, means = res.sizes(), res.means("vx")
    listed = ", ".join(f"{n}: {m:.4g}" for n, m in zip(sizes, means, strict=True))
    text = f" (fold means on the moving region {listed} (km/h)²"
    if fit is not None:
        text += (f"; fit {fit.a:.3g}·n^-{fit.b:.2f}, all-{res.extrapolate_to} estimate "
                 f"{res.extrapolated('vx'):.4g}")
    v = Verdict([Reading(f"{a.n_train}->{b.n_train} vx",
                         judge.unpaired(a.scores, b.scores, "vx"), BETTER)
                 for a, b in itertools.pairwise(res.points)])
    return [_finding("The vx error falls monotonically from 4 to 12 trials, still descending",
                     v, judge, text + ")")]


def _score(res: dict) -> FoldScore:
    return FoldScore.from_json({"wall_s": math.nan, "train": [], **res})


def _ratio(num: str, den: str):
    def q(s: FoldScore) -> float:
        return relative_effect(getattr(s, num), getattr(s, den))
    return q


def table2_findings(res: CVResult, judge: Judge) -> list[Finding]:
    """§V-A on the NSS's cross-validation folds: the reverse segments are tracked as
    closely as the forward bursts, and the segments beyond the training-window horizon
    are predicted no worse than those within it; per fold within one fit, the seed spread
    of the same ratio over the floor fits of that fold (moving-region subsets, so the same
    on every metric); "no worse" = below +tie_margin."""
    fits = {k: _score(r) for k, r in enumerate(res.folds["nss"])}
    no_worse = Claim("below", judge.cfg.tie_margin)
    def noise(*qs) -> str:
        return "; ".join(f"{name}: {judge.seeds.spread(q, judge.cfg.min_seeds, False).describe()}"
                         for name, q in qs) + f"; interval {100 * judge.cfg.level:g} %"

    q = _ratio("vx_reverse", "vx")
    v = Verdict([Reading("reverse vs all moving vx", judge.within(fits, q), no_worse)])
    reverse = _finding(
        "Reverse segments are tracked as closely as the forward bursts (reverse vx "
        "0.057 vs vx 0.108)", v, judge,
        f" (no worse = below {_pct(no_worse.t)})", noise(("ratio", q)))
    known = any(math.isfinite(s.vx_beyond) for s in fits.values())
    if not known:
        horizon = Finding("Beyond the training-window horizon the rollout is predicted no "
                          "worse than within it", "no trial runs past the horizon", None,
                          "no trial runs past the horizon")
        return [reverse, horizon]
    qs = [(f"{ch} ratio", _ratio(f"{ch}_beyond", f"{ch}_within")) for ch in ("vx", "yaw")]
    v = Verdict([Reading(f"beyond vs within {name[:-6]}", judge.within(fits, q), no_worse)
                 for name, q in qs])
    horizon = _finding(
        "Beyond the training-window horizon the rollout is predicted no worse than within it",
        v, judge, f" (no worse = below {_pct(no_worse.t)})", noise(*qs))
    return [reverse, horizon]


def seed_spread_finding(cv: CVResult, seeds: SeedNoiseResult | None,
                        same_order: float, judge: Judge | None = None) -> Finding:
    """§V-A: retraining one fold's model under other seeds spreads its vx error about as
    much as the folds spread (paper: 0.089 ± 0.019 over the fold-1 seeds, 0.108 ± 0.038 over
    the folds), so the CV variance is training stochasticity. The ratio of the two sample
    stds with its bootstrap interval (``judge``'s settings; seeds and folds resampled each
    on their own): agrees when the interval lies within [1/``same_order``, ``same_order``],
    differs when it lies wholly outside, else cannot tell."""
    from parknss.experiments.config import VerdictConfig
    from parknss.experiments.cv import mean_std
    from parknss.experiments.verdict import sd_ratio_interval

    claim = ("The seed spread on one fold is of the order of the across-fold spread "
             "(vx 0.089 ± 0.019 vs 0.108 ± 0.038)")
    if seeds is None:
        return Finding(claim, "needs the seed-noise study in the same run", None, NOT_MEASURED)
    s_vals = [s.vx for s in seeds.scores]
    f_vals = cv.column("nss", "vx_mse_moving_kmh2")
    s_mean, s_std = mean_std(s_vals)
    f_mean, f_std = mean_std(f_vals)
    cfg = judge.cfg if judge is not None else VerdictConfig()
    ratio, lo, hi = sd_ratio_interval(s_vals, f_vals, cfg)
    measured = (f"vx over {len(seeds.scores)} seeds ({seeds.split} fold {seeds.index}, "
                f"{seeds.epochs} epochs) {s_mean:.4g} ± {s_std:.3g}; over the folds "
                f"{f_mean:.4g} ± {f_std:.3g} (ratio {ratio:.2f} [{lo:.2f}, {hi:.2f}], "
                f"same order within x{same_order:g}; ddof 1)")
    read = Claim("within", math.log(same_order)).read(
        *(math.log(x) if x > 0 else -math.inf for x in (lo, hi))) \
        if math.isfinite(lo) and math.isfinite(hi) else None
    why = (f"cannot tell at this budget (sd ratio {ratio:.2f}, interval [{lo:.2f}, {hi:.2f}])"
           if math.isfinite(ratio) else "not finite")
    return Finding(claim, measured, read, why)


def seed_noise_findings(res: SeedNoiseResult, judge: Judge | None = None) -> list[Finding]:
    """The floor itself, for reference (a measurement, not a claim to test)."""
    text = (f"CV vx {100 * res.floor.vx:.1f} %, yaw {100 * res.floor.yaw:.1f} % over "
            f"{res.floor.n_seeds} seeds ({res.split} fold {res.index}, {res.epochs} epochs)")
    if judge is not None:
        text += f"; every fold: {judge.describe()}"
    return [Finding("Seed-induced CV about 2 % (vx) and 3-4 % (yaw)", text, None,
                    "reference value")]


def with_beside(main: list[Finding], beside: list[Finding], metric: str) -> list[Finding]:
    """``main`` with each finding's verdict on a second metric (``beside``, the same
    findings in the same order) noted beside its own."""
    for f, b in zip(main, beside, strict=True):
        if f.agrees is None and b.agrees is None and f.undecided == b.undecided:
            continue  # not measured, reference values
        f.beside = f"{LABELS[metric]}: {b.verdict}"
    return main


def judged(judge: Judge, make) -> list[Finding]:
    """``make(judge)``'s findings, each with its verdict on the config's ``beside`` metric
    (``make`` called again with the judge on that metric)."""
    out = make(judge)
    alt = judge.cfg.beside
    if alt and alt != judge.metric:
        with_beside(out, make(judge.with_metric(alt)), alt)
    return out


NO_VERDICT_TO_REVERSE = "no verdict to reverse"


def _lowered(before: float, after: float) -> str:
    return f"{100 * (before - after) / before:.0f} %" if before > 0 else "n/a"


def cotuning_finding(doc: dict | None = None) -> Finding:
    """§V-D: the signal-fitted 1 s NARX brake degrades the chain against the Phase B
    assembly, and consequence-level co-tuning turns it into one that beats that assembly;
    measured on the rows of a chain build (``doc``: its ``rows``, and where recorded the
    Phase B ``selection`` and the ``cotune`` report with its ``target`` and ``best_step``)."""
    claim = "Co-tuning reverses the brake verdict (§V-D)"
    rows = (doc or {}).get("rows")
    if not rows or "signal_target" not in rows or "cotuned_target" not in rows:
        return Finding(claim, "Table IV rows not available", None, NOT_MEASURED)
    sig, tuned = rows["signal_target"]["vx_full"], rows["cotuned_target"]["vx_full"]
    ref = rows.get("selected_assembly", {}).get("vx_full")
    measured = (
        f"1 s NARX brake in the chain: vx full {sig:.4f} signal-fitted -> {tuned:.4f} co-tuned"
    )
    if ref is None:  # no Phase B assembly to reverse a verdict against
        return Finding(claim, measured, tuned < sig)
    measured += f" (Phase B assembly {ref:.4f})"
    co = doc.get("cotune") or {}
    target, channel = co.get("target"), co.get("channel")
    if target is not None and (doc.get("selection") or {}).get(channel) == target:
        # the paper's premise (the signal-fitted target loses to Phase B's pick) cannot
        # arise: neither "agrees" nor "differs", whatever co-tuning did
        measured += f"; {target} is Phase B's own {channel} winner here: no verdict to reverse"
        measured += ("; co-tuning kept its starting weights (no step lowered its loss)"
                     if co.get("best_step") == 0 else
                     f"; co-tuning lowers the chain's vx full {_lowered(sig, tuned)}")
        return Finding(claim, measured, None, NO_VERDICT_TO_REVERSE)
    if sig <= ref:
        measured += "; the signal-fitted target does not degrade the chain here"
    elif tuned >= ref:
        measured += "; lowered, but the Phase B assembly stays better" if tuned < sig else ""
    if co.get("best_step") == 0:
        measured += "; co-tuning kept its starting weights (no step lowered its loss)"
    return Finding(claim, measured, sig > ref and tuned < ref)
