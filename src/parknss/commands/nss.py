"""``parknss cv``, ``parknss train`` and ``parknss evaluate``: the NSS model's jobs (§IV-B, §V-A).

* ``cv``: Table II, the stratified 4-fold cross-validation, with the linear and direct-yaw
  baselines on the same folds in the same run; Fig. 4 (fold 0's held-out convergence) and
  Fig. 5 (fold 0's model on two of its held-out maneuvers).
* ``train``: the all-trials deployment fit, resumable (``--resume``), with its loss history.
* ``evaluate``: open-loop errors of any model (default: the shipped one) on any campaign
  (default: the bundled one), against the logged channels and, for a synthetic campaign,
  against the noise-free truth; Fig. 5 for a park-in and a park-out.

Config: ``--config YAML`` (default: the paper's values, configs/nss.yaml lists them) plus
``--epochs``, ``--seed`` and any ``--set section.field=value``.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer
import yaml

from parknss.errors import ConfigError


def _log(msg: str) -> None:
    typer.echo(f"[nss] {msg}", err=True)


def parse_overrides(sets: list[str] | None, epochs: int | None, seed: int | None) -> dict:
    """``["train.lr=1e-3", ...]`` plus --epochs/--seed -> {section: {field: value}}."""
    out: dict[str, dict] = {}
    for item in sets or []:
        key, sep, raw = item.partition("=")
        sec, dot, name = key.strip().partition(".")
        if not sep or not dot or not sec or not name:
            raise ConfigError(f"--set {item!r}: expected section.field=value, e.g. train.lr=1e-3")
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError as exc:
            raise ConfigError(f"--set {item!r}: value is not valid YAML") from exc
        out.setdefault(sec, {})[name] = value
    if epochs is not None:
        out.setdefault("train", {})["epochs"] = epochs
    if seed is not None:
        out.setdefault("train", {})["seed"] = seed
    return out


def _emit(doc: dict, as_json: bool, text: str) -> None:
    typer.echo(json.dumps(doc, indent=2) if as_json else text)


def _fmt_errors(title: str, e: dict) -> str:
    def f(key: str) -> str:
        v = e.get(key)
        return "   n/a" if v is None else f"{v:8.4f}"

    return (
        f"{title}\n"
        f"  vx moving {f('vx_mse_moving_kmh2')} (km/h)²   reverse {f('vx_mse_reverse_kmh2')}"
        f"   full {f('vx_mse_full_kmh2')}\n"
        f"  yaw moving {f('yaw_mse_moving_degs2')} (°/s)²   full {f('yaw_mse_full_degs2')}\n"
        f"  vx within horizon {f('vx_mse_within_kmh2')}   beyond {f('vx_mse_beyond_kmh2')}\n"
        f"  ax moving {f('ax_mse_moving_ms2')} (m/s²)²   ay moving {f('ay_mse_moving_ms2')}"
    )


def _cv_figures(res, campaign, out: Path) -> list[str]:
    """Fig. 4 and Fig. 5 from the NSS fold 0 (if its model was saved)."""
    from parknss.nss.checkpoint import load_model
    from parknss.nss.predict import predict_trials
    from parknss.report.nss_figures import draw_history, draw_rollouts, pick_maneuvers

    figs = []
    f0 = (res.folds.get("nss") or [None])[0]
    if not f0:
        return figs
    h = f0.get("history") or {}
    if h.get("epochs"):
        figs.append(
            str(
                draw_history(
                    h["epochs"],
                    h["raw"],
                    h["smooth"],
                    out / "fig4_convergence.png",
                    output=h.get("output"),
                    best_epoch=f0.get("best_epoch"),
                )
            )
        )
    if f0.get("model_dir"):
        model = load_model(f0["model_dir"]).model
        trials = pick_maneuvers([campaign[i] for i in f0["val"]])
        pred = predict_trials(model, trials)
        figs.append(
            str(draw_rollouts(trials, pred, out / "fig5_rollouts.png", f0.get("window_length")))
        )
    return figs


def register(app: typer.Typer) -> None:
    @app.command("cv")
    def cv(
        data: Path | None = typer.Option(
            None, "--data", help="Campaign folder (default: bundled)."
        ),
        config: Path | None = typer.Option(None, "--config", help="NSS config YAML."),
        epochs: int | None = typer.Option(None, "--epochs", help="Override train.epochs."),
        seed: int | None = typer.Option(None, "--seed", help="Override train.seed."),
        set_: list[str] = typer.Option(None, "--set", help="section.field=value (repeatable)."),
        variants: str = typer.Option(
            "nss,nss_direct_yaw,linear", "--variants", help="Comma-separated models to run."
        ),
        executor: str = typer.Option("local", "--executor", help="local | ray"),
        workers: int | None = typer.Option(None, "--workers", help="Parallel workers."),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address."),
        out: Path = typer.Option(Path("runs/cv"), "--out", help="Run folder."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
    ) -> None:
        """Table II: stratified 4-fold CV of the NSS and two baselines on the same folds
        (plain 4-fold, with a note, when the campaign is not stratifiable)."""
        from parknss.data.splits import cv_plan
        from parknss.experiments.cv import run_cv
        from parknss.nss.campaigns import load_campaign

        overrides = parse_overrides(set_, epochs, seed)
        # validates the folder and its channels before any job starts
        campaign = load_campaign(data, "nss", "parknss cv")
        plan = cv_plan(campaign)  # stratified, or plain k-fold (says why in plan.note)
        _log(plan.note)
        out.mkdir(parents=True, exist_ok=True)
        res = run_cv(
            data=str(data) if data else None,
            config=str(config) if config else None,
            overrides=overrides,
            variants=[v.strip() for v in variants.split(",") if v.strip()],
            executor=executor,
            workers=workers,
            address=address,
            cache_dir=out / "cache",
            save_dir=out / "models",
            plan=plan,
        )
        doc = res.to_json()
        doc["figures"] = _cv_figures(res, campaign, out)
        (out / "cv.json").write_text(json.dumps(doc, indent=2))
        (out / "table2.txt").write_text(res.table() + "\n")
        _log(f"wrote {out / 'cv.json'}, {out / 'table2.txt'} and {len(doc['figures'])} figures")
        _emit(doc, as_json, res.table())

    @app.command("train")
    def train(
        data: Path | None = typer.Option(
            None, "--data", help="Campaign folder (default: bundled)."
        ),
        config: Path | None = typer.Option(None, "--config", help="NSS config YAML."),
        epochs: int | None = typer.Option(None, "--epochs", help="Override train.epochs."),
        seed: int | None = typer.Option(None, "--seed", help="Override train.seed."),
        set_: list[str] = typer.Option(None, "--set", help="section.field=value (repeatable)."),
        out: Path = typer.Option(Path("runs/train"), "--out", help="Run folder."),
        resume: bool = typer.Option(False, "--resume", help="Continue from out/state."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
    ) -> None:
        """The deployment fit on every trial (paper config); writes out/model."""
        from parknss.experiments.folds import fold_config
        from parknss.nss.campaigns import load_campaign
        from parknss.nss.checkpoint import save_model
        from parknss.nss.train import fit, geometry_of
        from parknss.report.nss_figures import draw_history

        cfg = fold_config(str(config) if config else None, parse_overrides(set_, epochs, seed))
        campaign = load_campaign(data, "nss", "parknss train")
        out.mkdir(parents=True, exist_ok=True)
        (out / "config.json").write_text(json.dumps(cfg.model_dump(mode="json"), indent=2))
        res = fit(
            list(campaign), [], cfg, geometry_of(campaign), out_dir=out / "state", resume=resume
        )
        model_dir = save_model(out / "model", res.model, cfg, res.training_meta())
        h = res.history
        (out / "history.json").write_text(json.dumps(h.to_json()))
        fig = draw_history(
            h.crit_epochs,
            h.crit_raw,
            h.crit_smooth,
            out / "fig4_training.png",
            best_epoch=res.best_epoch,
            criterion="training loss",
        )
        doc = {
            "model": str(model_dir),
            "figure": str(fig),
            **res.training_meta(),
        }
        text = (
            f"trained {res.epochs_run} epochs on {len(campaign)} trials "
            f"({res.n_windows} windows of {res.window_length}) in {res.wall_s:.0f} s; "
            f"best epoch {res.best_epoch} (smoothed {h.criterion} {res.best_value:.5f}); "
            f"model in {model_dir}"
        )
        _emit(doc, as_json, text)

    @app.command("evaluate")
    def evaluate(
        model: Path | None = typer.Option(
            None, "--model", help="NSS model folder (default: shipped)."
        ),
        chain: Path | None = typer.Option(
            None, "--chain", help="Evaluate a command-to-vehicle chain folder instead."
        ),
        data: Path | None = typer.Option(
            None, "--data", help="Campaign folder (default: bundled)."
        ),
        limiter: bool = typer.Option(False, "--limiter", help="Apply the inference limiter."),
        out: Path = typer.Option(Path("runs/evaluate"), "--out", help="Run folder."),
        as_json: bool = typer.Option(False, "--json", help="Print one JSON document."),
    ) -> None:
        """Open-loop errors of a model over whole trials (Fig. 5 for two maneuvers)."""
        from parknss.config import SHIPPED_NSS
        from parknss.metrics.errors import logged_and_truth_errors
        from parknss.nss.campaigns import load_campaign
        from parknss.nss.checkpoint import load_model
        from parknss.nss.config import LimiterConfig
        from parknss.nss.predict import predict_trials
        from parknss.report.nss_figures import draw_rollouts, pick_maneuvers

        if chain is not None and (model is not None or limiter):
            raise ConfigError("--chain cannot be combined with --model or --limiter")
        # a chain rolls out from the logged commands; a model from the logged actuals
        campaign = load_campaign(data, "rate" if chain is not None else "nss", "parknss evaluate")
        trials = list(campaign)
        if chain is not None:
            from parknss.chain import load_chain

            source = str(chain)
            predictions = load_chain(chain).predict_trials(trials)
            horizon = None
        else:
            loaded = load_model(model or SHIPPED_NSS)
            source = str(loaded.path)
            lim = LimiterConfig(enabled=True) if limiter else None
            predictions = predict_trials(loaded.model, trials, lim)
            horizon = loaded.training.get("window_length")
        logged, truth = logged_and_truth_errors(predictions, trials, horizon)
        out.mkdir(parents=True, exist_ok=True)
        fig = draw_rollouts(
            pick_maneuvers(trials),
            predictions,
            out / "fig5_rollouts.png",
            horizon,
            title=f"Open-loop rollout of {Path(source).name}",
        )
        doc = {**logged, "source": source, "truth": truth, "figure": str(fig)}
        (out / "evaluate.json").write_text(json.dumps(doc, indent=2))
        text = _fmt_errors(f"{source} on {len(trials)} trials vs logged channels", logged)
        if truth is not None:
            text += "\n" + _fmt_errors("vs noise-free truth channels (synthetic campaign)", truth)
        _emit(doc, as_json, text)
