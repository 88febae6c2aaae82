"""What ``parknss identify`` may take over instead of computing, and the checks that say so.

* **A fitted NSS** (``--nss DIR``, :func:`check_nss`): reused for the ``nss`` stage only
  when the campaign's data hash equals the one recorded in the model and every training
  setting recorded in the model equals this run's resolved NSS config (a setting the model
  does not record is accepted only when it belongs to a recipe the fit did not use: the
  ``fast`` or ``coarse`` section of a fit made with another recipe, and ``train.recipe:
  paper`` for a model from before recipes existed). ``model.fused_kernels`` is not
  compared: the kernels decide only the float32 rounding of a fit, not what is fitted (a
  model trained with the reference kernels serves a run that would train with the native
  ones). A mismatch is refused in one line naming the field; nothing is reused then. The
  training-code version is checked too: the model's recorded ``code_version``, else the
  version of the code at its recorded git revision (from the checkout's git history); it
  must be the current version or one the canary lineage (``results/lineage``) records as
  computing the same numbers. A version that is not shown equal is refused unless
  ``allow_code_change`` (``--allow-code-change``), and the model card then says so.
* **An actuator selection** (``--selection``, :func:`selection_winners`): the winners of a
  study's ``selection.json`` or of a chain artefact's build record.
* **The truth** (:func:`truth_vehicle`): a synthetic campaign of the reference vehicle
  names the vehicle YAML it was generated with and the digest of its parameters; the
  truth exists here when that YAML is found and its parameters' digest matches.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from parknss.config import CONFIG_DIR, REPO_ROOT, read_json
from parknss.errors import ConfigError, ParknssError
from parknss.experiments.lineage import accepted_versions
from parknss.experiments.store import code_version, revision_code_version
from parknss.nss.config import RECIPE_SECTIONS

ROUNDING_ONLY: tuple[str, ...] = ("model.fused_kernels",)
"""Training settings that decide only a fit's rounding, not compared for reuse."""


class ReuseRefusedError(ParknssError):
    """A product given for reuse does not match this run's inputs (one line)."""


def flat(doc: dict, prefix: str = "") -> dict[str, object]:
    """``{"train": {"lr": 1}}`` -> ``{"train.lr": 1}``."""
    out: dict[str, object] = {}
    for k, v in doc.items():
        if isinstance(v, dict):
            out.update(flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def config_mismatch(recorded: dict, wanted: dict) -> str | None:
    """The first difference between a model's recorded NSS config and the wanted one, in
    words, or None (see the module doc for the settings a model may leave unrecorded)."""
    rec, want = flat(recorded), flat(wanted)
    recipe = rec.get("train.recipe", "paper")
    for key in sorted(set(rec) | set(want)):
        if key in ROUNDING_ONLY:
            continue
        if key in rec and key in want:
            if rec[key] != want[key]:
                return f"{key} is {rec[key]!r} in the model, {want[key]!r} here"
        elif key in want:
            inert = (key == "train.recipe" and want[key] == "paper") or any(
                key.startswith(f"{section}.") and recipe != section
                for section in RECIPE_SECTIONS)
            if not inert:
                return f"{key} is not recorded in the model ({want[key]!r} here)"
        else:
            return f"{key} is recorded in the model but unknown here"
    return None


@dataclass(frozen=True)
class NssCheck:
    """The verdict on a given NSS: ``reason`` is the one line the log and the card show;
    ``code`` "current", "accepted by the lineage", "not shown equal" or "unknown"."""

    path: str
    code: str
    fitted_code_version: str | None
    reason: str


def check_nss(folder: Path, data_hash: str, wanted: dict, *, allow_code_change: bool,
              store_root: Path | None) -> NssCheck:
    """Check a fitted NSS for reuse (module doc); ReuseRefusedError (one line) on a mismatch."""
    from parknss.nss.checkpoint import load_model

    loaded = load_model(folder)  # verifies SHA256SUMS and the format
    doc = read_json(Path(folder) / "model.json")
    training = doc.get("training") or {}
    recorded_hash = training.get("data_hash")
    if recorded_hash != data_hash:
        raise ReuseRefusedError(
            f"--nss {folder}: fitted on data {str(recorded_hash)[:12]}..., this campaign is "
            f"{data_hash[:12]}...; not reused (drop --nss to fit it here)")
    if training.get("val_trials"):
        raise ReuseRefusedError(f"--nss {folder}: held out {len(training['val_trials'])} trials; "
                           "identify fits on every trial; not reused")
    why = config_mismatch(doc.get("config") or {}, wanted)
    if why is not None:
        raise ReuseRefusedError(f"--nss {folder}: training config differs ({why}); not reused "
                           "(drop --nss, or give the --recipe/--set it was fitted with)")
    current = code_version()
    fitted = training.get("code_version")
    rev = training.get("git_revision")
    if fitted is None and rev:
        fitted = revision_code_version(str(rev))
    if fitted == current:
        code = "current"
    elif fitted is not None and store_root is not None and fitted in accepted_versions(
            store_root, current):
        code = "accepted by the lineage"
    else:
        code = "unknown" if fitted is None else "not shown equal"
    head = (f"{folder}: data hash {data_hash[:12]}... and the training config "
            f"({'recipe ' + str(wanted.get('train', {}).get('recipe', 'paper'))}, "
            f"{training.get('epochs')} epochs) match")
    if code in ("current", "accepted by the lineage"):
        return NssCheck(str(loaded.path), code, fitted,
                        f"{head}; training code {fitted} {code}")
    what = ("its training-code version is unknown (no code_version recorded, git revision "
            f"{rev!r} not in this checkout)" if fitted is None else
            f"its training code {fitted} (git {str(rev)[:9]}) is not shown equal to the "
            f"current {current} by the canary lineage")
    if not allow_code_change:
        raise ReuseRefusedError(f"--nss {folder}: {what}; not reused (--allow-code-change reuses "
                           "it anyway and the model card says so)")
    return NssCheck(str(loaded.path), code, fitted,
                    f"{head}; {what}: reused on --allow-code-change")


def selection_winners(path: Path) -> tuple[dict[str, str], str]:
    """(channel -> candidate label, where from) of a ``selection.json`` or of a chain
    artefact folder (its build record's selection); one-line ConfigError otherwise."""
    from parknss.chain.build import selection_winners as from_json

    if Path(path).is_dir():
        doc = read_json(Path(path) / "chain.json")
        sel = (doc.get("build") or {}).get("selection") if isinstance(doc, dict) else None
        if not isinstance(sel, dict) or not sel:
            raise ConfigError(f"--selection {path}: the chain records no selection")
        return {str(k): str(v) for k, v in sel.items()}, f"the selection of chain {path}"
    return from_json(Path(path)), f"{path}"


def truth_vehicle(meta: dict) -> tuple[Path | None, str] | None:
    """(reference-vehicle YAML or None for the shipped one, a note) when the campaign is
    a synthetic one of the reference vehicle whose parameters are found here, else None."""
    from parknss.reference.params import load_vehicle_params

    if not meta.get("synthetic") or "vehicle_params_digest" not in meta:
        return None
    recorded = meta.get("vehicle_yaml")
    if recorded is None:
        candidates: list[Path | None] = [None]
    else:
        p = Path(recorded)
        candidates = [p, REPO_ROOT / p, CONFIG_DIR / p.name]
    for cand in candidates:
        if cand is not None and not cand.is_file():
            continue
        try:
            params = load_vehicle_params(cand)
        except ParknssError:
            continue
        if params.digest() == meta["vehicle_params_digest"]:
            name = "the shipped reference vehicle" if cand is None else str(cand)
            return cand, f"{name} (parameters digest {params.digest()})"
    return None

