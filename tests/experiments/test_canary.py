"""The canary (parknss.experiments.canary): deterministic, and sensitive to a change of
the training code's numbers, which the lineage then refuses to bridge."""

from __future__ import annotations

import pytest

from parknss.experiments import canary
from parknss.experiments.canary import CASES, run_canary, spec_digest
from parknss.experiments.lineage import canary_record, migrate, read_lineage
from parknss.experiments.store import REPO_ROOT, Machine, code_version

CASE = ["paper_fused_mae"]


def test_a_canary_case_is_deterministic_and_a_numeric_change_is_not_accepted(tmp_path,
                                                                             monkeypatch):
    here = Machine.here()
    first = run_canary(CASE)
    assert run_canary(CASE).digest == first.digest  # bit-identical on a rerun
    assert first.spec == spec_digest(CASE) != spec_digest()
    migrate(tmp_path, "v0", canary_record(first, here))
    from parknss.nss import losses

    pointwise = losses.pointwise
    monkeypatch.setattr(losses, "pointwise", lambda e, kind: pointwise(e, kind) * 1.0001)
    changed = run_canary(CASE)
    assert changed.digest != first.digest
    m = migrate(tmp_path, "v1", canary_record(changed, here))
    assert m.equivalent == [] and m.differs == {"v0": first.digest}
    assert m.accepted == ["v1"]
    monkeypatch.undo()
    m = migrate(tmp_path, "v2", canary_record(run_canary(CASE), here))
    assert m.equivalent == ["v0"] and m.accepted == ["v2", "v0"]
    assert read_lineage(tmp_path)["v2"].equivalent_to[0].cpu == here.cpu


def test_the_canary_covers_the_stored_fits_code_paths():
    specs = [c.get("overrides", {}) for c in CASES.values()]
    seen = lambda sec, key: {s.get(sec, {}).get(key) for s in specs}  # noqa: E731
    assert {"eager"} <= seen("model", "engine")
    assert {"midpoint", "rk4"} <= seen("model", "integrator")
    assert {False} <= seen("model", "residual_yaw")
    assert {"mse", "logcosh"} <= seen("loss", "kind")
    assert {"minmax", "zscore"} <= seen("data", "normalizer")
    assert {"constant"} <= seen("train", "schedule")
    assert {"fast"} <= seen("train", "recipe")
    kinds = {c.get("job", "fold") for c in CASES.values()}
    assert kinds == {"fold", "limiter", "resume"}
    assert {"linear"} <= {c.get("model") for c in CASES.values()}
    assert {"leave"} <= {c.get("split") for c in CASES.values()}


def test_the_committed_canary_of_this_code_matches_a_fresh_run():
    """The canary recorded in results/lineage/ for this code version on this CPU model is
    what the code computes now (skipped where none is recorded: run
    ``parknss results migrate``)."""
    here = Machine.here()
    recs = read_lineage(REPO_ROOT / "results").get(code_version())
    mine = [c for c in (recs.canaries if recs else []) if c.cpu == here.cpu
            and c.spec == spec_digest()]
    if not mine:
        pytest.skip(f"no canary of code {code_version()} recorded on {here.cpu}")
    res = run_canary()
    assert res.digest in {c.digest for c in mine}, (res.cases, mine[-1].cases)
    assert res.details["resumed"]["same_as_uninterrupted"]
    assert res.seconds < 60
    assert canary.CANARY_FORMAT == 1
