"""The deployed chain and the fidelity ladder (paper Table IV), on all trials.

:func:`build_deployment` refits the selected winners on every trial (as the deployment NSS
is fitted on every trial), fits the co-tuning target (default the 1 s NARX brake), and
co-tunes it inside the assembly on every trial. It scores, on every trial from the logged
commands, the ladder rows that need no retraining: all channels measured; the assembly
with the signal-fitted target; with the co-tuned target; static affine actuator maps
without dynamics (plus the selected assembly itself). The deployed chain carries the
co-tuned target when that lowers the criterion (full + moving vx MSE) of the selected
assembly (strictly: co-tuning that kept its starting weights does not), else the
selected assembly. These are in-sample figures (the paper's Table IV
is on the deployment model too); the study reports the held-out counterparts.

:func:`monolithic_score` is the "monolithic NSS on commands" row: the NSS architecture fed
the commands in place of the actuals (gear, torque_cmd, -decel_cmd, steer_cmd; the sign
flip keeps "more braking" increasing as the pressure does), scaling refitted, warm-started
from the given NSS's weights and trained ``ladder.monolithic_epochs`` epochs with the
paper's loss and windows, then rolled out open loop over every trial.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import torch

from parknss.actuators.config import ActuatorConfig
from parknss.actuators.envelopes import Envelope, identify_envelope
from parknss.actuators.fit import fit_candidate
from parknss.actuators.models import ActuatorModel
from parknss.actuators.spec import CHANNELS, CandidateSpec
from parknss.chain.cotune import cotune
from parknss.chain.model import Chain, NSSProvenance
from parknss.chain.score import ChainScore, chain_score, make_chain
from parknss.chain.selection import nss_states
from parknss.data.normalize import Normalizer
from parknss.data.trial import Trial
from parknss.data.windows import make_windows, window_length
from parknss.errors import ConfigError
from parknss.metrics.errors import open_loop_errors
from parknss.nss.batch import make_batch
from parknss.nss.checkpoint import LoadedModel
from parknss.nss.model import NORMALIZED, NSSModel
from parknss.nss.predict import predict_trials
from parknss.nss.step import epoch_loss
from parknss.nss.train import build_model

Progress = Callable[[str], None]

LADDER_ROWS: tuple[tuple[str, str], ...] = (
    ("all_measured", "All channels measured (reference)"),
    ("signal_target", "Assembled chain, signal-fitted 1 s NARX brake"),
    ("cotuned_target", "Assembled chain, consequence-tuned 1 s NARX brake"),
    ("selected_assembly", "Assembled chain, Phase B winners (no co-tuning)"),
    ("monolithic", "Monolithic NSS on commands, no submodels"),
    ("static_affine", "Static affine actuator maps, no dynamics"),
)
"""Table IV's rows in the paper's order: (key in ``Deployment.rows``, label)."""


@dataclass
class Deployment:
    """The deployed chain, the ladder rows measured here, and what was done."""

    chain: Chain
    env: Envelope
    rows: dict[str, ChainScore]
    selection: dict[str, str]
    deployed: dict[str, str]
    cotune: dict
    wall_s: float
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {
            "rows": {k: v.to_json() for k, v in self.rows.items()},
            "selection": self.selection,
            "deployed": self.deployed,
            "cotune": self.cotune,
            "envelope": self.env.to_json(),
            "wall_s": self.wall_s,
            **self.extra,
        }


def _fit_label(
    label: str, nss: NSSModel, trials: list[Trial], cfg: ActuatorConfig, env: Envelope,
    progress: Progress,
) -> ActuatorModel:
    """Fit a Phase B label (``+nssft``: then the NSS-state fine-tune) on ``trials``."""
    spec = CandidateSpec.parse(label.removesuffix("+nssft"))
    model, rep = fit_candidate(spec, trials, cfg, env)
    progress(f"fitted {spec.name} on {len(trials)} trials ({rep.wall_s:.1f} s)")
    if label.endswith("+nssft") and cfg.select.nss_state_finetune_iters > 0:
        states = nss_states(nss, model, env, trials)
        model, _ = fit_candidate(spec, trials, cfg, env, states=states, init=model,
                                 iters=cfg.select.nss_state_finetune_iters)
    return model


def build_deployment(
    loaded: LoadedModel, trials: Sequence[Trial], cfg: ActuatorConfig,
    winners: dict[str, str], progress: Progress,
) -> Deployment:
    """Fit, co-tune and score the deployment chain on ``trials`` (see the module doc) on
    the NSS ``loaded``; the deployed chain carries that NSS's provenance."""
    t0 = time.perf_counter()
    nss = loaded.model
    prov = NSSProvenance(loaded.config, loaded.training)
    trials = list(trials)
    missing = [c for c in CHANNELS if c not in winners]
    if missing:
        raise ConfigError(f"selection lacks winners for {', '.join(missing)}")
    env = identify_envelope(trials, cfg.envelope)
    models = {ch: _fit_label(winners[ch], nss, trials, cfg, env, progress) for ch in CHANNELS}
    target = CandidateSpec.parse(cfg.cotune.target)
    signal = _fit_label(target.name, nss, trials, cfg, env, progress)
    tuned = copy.deepcopy(signal)
    others = {ch: m for ch, m in models.items() if ch != target.channel}
    rows: dict[str, ChainScore] = {}
    rows["all_measured"] = chain_score(make_chain(nss, {}, env), trials)
    progress(f"all measured: vx full {rows['all_measured'].vx_full:.4f}")
    selected = make_chain(nss, models, env, prov)
    rows["selected_assembly"] = chain_score(selected, trials)
    progress(f"selected assembly: vx full {rows['selected_assembly'].vx_full:.4f}")
    rows["signal_target"] = chain_score(make_chain(nss, {**others, target.channel: signal}, env),
                                        trials)
    progress(f"signal-fitted {target.name}: vx full {rows['signal_target'].vx_full:.4f}")
    tuned_chain = make_chain(nss, {**others, target.channel: tuned}, env, prov)
    rep = cotune(tuned_chain, target.channel, trials, cfg.cotune, progress)
    rows["cotuned_target"] = chain_score(tuned_chain, trials)
    progress(f"co-tuned {target.name}: vx full {rows['cotuned_target'].vx_full:.4f}")
    static = {ch: _fit_label(f"{ch}/static/cmd", nss, trials, cfg, env, progress)
              for ch in CHANNELS}
    rows["static_affine"] = chain_score(make_chain(nss, static, env), trials)
    # strictly lower: co-tuning that kept its start weights deploys the selected assembly
    use_tuned = rows["cotuned_target"].criterion < rows["selected_assembly"].criterion
    chain = tuned_chain if use_tuned else selected
    deployed = {ch: (target.name + "+cotuned" if use_tuned and ch == target.channel
                     else winners[ch]) for ch in CHANNELS}
    return Deployment(chain, env, rows, dict(winners), deployed,
                      {**rep.to_json(), "target": target.name}, time.perf_counter() - t0)


def command_trial(tr: Trial) -> Trial:
    """A copy of ``tr`` whose actual channels hold the commands (monolithic baseline)."""
    ch = dict(tr.channels)
    ch["torque"] = tr["torque_cmd"].copy()
    ch["brake_pressure"] = -tr["decel_cmd"]
    ch["steer"] = tr["steer_cmd"].copy()
    return Trial(tr.id, tr.maneuver, tr.repetition, ch, tr.vehicle_id, tr.sample_rate_hz,
                 tr.provenance)


def monolithic_score(loaded: LoadedModel, trials: Sequence[Trial], cfg: ActuatorConfig,
                     progress: Progress) -> tuple[ChainScore, dict]:
    """The monolithic-NSS row (see the module doc): (score, how it was trained)."""
    t0 = time.perf_counter()
    ncfg = loaded.config
    cmd = [command_trial(tr) for tr in trials]
    norm = Normalizer.fit(cmd, NORMALIZED, ncfg.data.normalizer, ncfg.data.clip_percentiles)
    model = build_model(ncfg, norm, loaded.geometry)
    model.load_state_dict(loaded.model.state_dict())
    L = window_length([tr.n for tr in cmd], ncfg.data.window)
    batch = make_batch(model, make_windows(cmd, L), ncfg.loss.blind_zone_kmh)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.ladder.monolithic_lr)
    model.train()
    for e in range(cfg.ladder.monolithic_epochs):
        opt.zero_grad(set_to_none=True)
        loss = epoch_loss(model, batch, ncfg).total
        loss.backward()
        opt.step()
        if e % 10 == 0:
            progress(f"monolithic epoch {e + 1}/{cfg.ladder.monolithic_epochs}: "
                     f"loss {float(loss.detach()):.4f}")
    model.eval()
    model.requires_grad_(False)
    pred = predict_trials(model, cmd)
    e = open_loop_errors(pred, trials)
    info = {"epochs": cfg.ladder.monolithic_epochs, "lr": cfg.ladder.monolithic_lr,
            "warm_start": "given NSS weights", "wall_s": time.perf_counter() - t0}
    return ChainScore(e.vx_mse_full_kmh2, e.vx_mse_moving_kmh2, e.yaw_mse_moving_degs2), info


def ladder_text(doc: dict) -> str:
    """Table IV as fixed-width text from a :func:`parknss.chain.build.run_build` document."""
    lines = [f"{'Configuration':52s} {'vx full':>9s} {'vx moving':>10s}  [(km/h)^2]"]
    for key, name in LADDER_ROWS:
        r = doc["rows"].get(key)
        if r is not None:
            lines.append(f"{name:52s} {r['vx_full']:9.4f} {r['vx_moving']:10.4f}")
    lines.append(f"deployed: {doc['deployed']}")
    if "artefact" in doc:
        lines.append(f"wrote {doc['artefact']}")
    return "\n".join(lines)
