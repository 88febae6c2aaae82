"""The co-tuning finding reads Table IV's rows: agrees only when co-tuning lowers the
signal-fitted brake's chain error and the result is at least as good as Phase B."""

from parknss.experiments.findings import cotuning_finding


def _rows(sig: float, tuned: float, ref: float) -> dict:
    return {
        "signal_target": {"vx_full": sig},
        "cotuned_target": {"vx_full": tuned},
        "selected_assembly": {"vx_full": ref},
    }


def test_reversal_agrees_when_cotuned_beats_both():
    f = cotuning_finding(_rows(0.069, 0.055, 0.059))
    assert f.agrees is True and f.verdict == "agrees"


def test_lowered_but_phase_b_better_differs_and_says_so():
    f = cotuning_finding(_rows(0.20, 0.065, 0.030))
    assert f.agrees is False and "Phase B assembly stays better" in f.measured


def test_no_rows_is_not_measured():
    f = cotuning_finding(None)
    assert f.agrees is None and f.verdict == "not measured"
