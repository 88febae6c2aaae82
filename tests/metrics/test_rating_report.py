"""Rating table, Fig. 7 box plot and the ``parknss rate`` command."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from parknss.cli import main
from parknss.data.trial import Campaign
from parknss.errors import DataError
from parknss.metrics.iso18571 import lowpass, rate
from parknss.metrics.rating_report import RATED_CHANNELS, RateConfig, rate_campaign
from parknss.report.iso_figure import draw_iso_boxplot

DT = 0.01


def _pairs(n_trials: int = 3, n: int = 300, seed: int = 0) -> dict:
    """Synthetic trial -> channel -> (measured, predicted): noisy lagged predictions."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    out = {}
    for k in range(n_trials):
        chans = {}
        for j, ch in enumerate(RATED_CHANNELS):
            truth = np.sin(2 * np.pi * (0.3 + 0.1 * j) * t + k) + 0.2 * np.cos(3.1 * t)
            meas = truth + (0.02 + 0.03 * j) * rng.standard_normal(n)
            pred = 0.95 * np.concatenate([np.full(k + j, truth[0]), truth[: n - k - j]])
            chans[ch] = (meas, pred)
        out[f"trial_{k}"] = chans
    return out


@pytest.fixture(scope="module")
def table():
    return rate_campaign(_pairs(), DT)


def test_rows_are_the_ratings_of_raw_and_filtered_pairs(table):
    pairs = _pairs()
    assert len(table.rows) == 3 * 4 * 2
    assert table.trial_ids() == ["trial_0", "trial_1", "trial_2"]
    row = {(r.trial_id, r.channel, r.conditioning): r for r in table.rows}
    m, p = pairs["trial_2"]["ay"]
    raw, filt = row[("trial_2", "ay", "raw")], row[("trial_2", "ay", "filtered")]
    assert raw.overall == rate(m, p, DT).overall
    ref = rate(lowpass(m, DT), lowpass(p, DT), DT)
    assert (filt.overall, filt.slope, filt.shift_samples) == (
        ref.overall,
        ref.slope,
        ref.shift_samples,
    )
    # the predictions lag by k + j samples (k trial, j channel)
    assert row[("trial_2", "ax", "raw")].shift_samples == 2 + 2


def test_summary_means(table):
    s = table.summary()
    assert len(s.channels) == 8
    for cond in ("raw", "filtered"):
        per = []
        for ch in RATED_CHANNELS:
            c = s.get(ch, cond)
            vals = [r for r in table.rows if r.channel == ch and r.conditioning == cond]
            assert c.n_trials == 3
            assert c.slope == pytest.approx(np.mean([r.slope for r in vals]), abs=1e-15)
            assert c.overall == pytest.approx(np.mean([r.overall for r in vals]), abs=1e-15)
            per.append(c.overall)
        mean = s.mean_raw if cond == "raw" else s.mean_filtered
        assert mean == pytest.approx(np.mean(per), abs=1e-15)
    # the noise is smoothed away by the identical 5 Hz conditioning
    assert s.get("ay", "filtered").slope > s.get("ay", "raw").slope


def test_csv_and_json(table, tmp_path):
    path = table.to_csv(tmp_path / "sub" / "r.csv")
    with path.open() as fh:
        lines = list(csv.DictReader(fh))
    assert len(lines) == len(table.rows)
    first = lines[0]
    assert set(first) == {
        "trial_id", "channel", "conditioning", "corridor", "phase", "magnitude",
        "slope", "overall", "grade", "shift_samples",
    }  # fmt: skip
    assert float(first["overall"]) == pytest.approx(table.rows[0].overall, abs=1e-6)
    doc = json.loads(json.dumps(table.to_json()))
    assert doc["standard"] == "ISO/TS 18571:2014"
    assert doc["config"]["lowpass"]["cutoff_hz"] == 5.0
    assert doc["summary"]["mean_raw"] == pytest.approx(table.summary().mean_raw)
    assert "mean over channels: raw" in table.table()


def test_missing_channel_and_bad_prediction_name_the_trial():
    pairs = _pairs(1)
    del pairs["trial_0"]["yaw_rate"]
    with pytest.raises(DataError, match="trial trial_0: channel 'yaw_rate' missing"):
        rate_campaign(pairs, DT)
    pairs = _pairs(1)
    m, p = pairs["trial_0"]["vx"]
    pairs["trial_0"]["vx"] = (m, np.r_[p[:-1], np.nan])
    with pytest.raises(DataError, match="trial trial_0 channel vx"):
        rate_campaign(pairs, DT)


def test_channel_subset_config():
    tab = rate_campaign(_pairs(2), DT, RateConfig(channels=("vx",)))
    assert {r.channel for r in tab.rows} == {"vx"}
    assert len(tab.summary().channels) == 2


def test_box_plot_png(table, tmp_path):
    path = draw_iso_boxplot(table, tmp_path / "fig.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 10_000


# --- the command ------------------------------------------------------------------


@pytest.fixture(scope="module")
def campaign_dir(tmp_path_factory):
    """Two short synthetic trials (with truth channels) written as a campaign folder."""
    from parknss.data.io import write_campaign
    from parknss.reference.campaign import generate_trial

    trials = [generate_trial("park_out_left", 1).slice(0, 700)]
    trials.append(generate_trial("park_out_right", 1).slice(200, 900))
    folder = tmp_path_factory.mktemp("campaign")
    write_campaign(Campaign(trials, name="tiny"), folder)
    return folder


def test_rate_replay_truth_json(campaign_dir, tmp_path, capsys):
    out = tmp_path / "rate"
    code = main(
        ["rate", "--replay-truth", "--data", str(campaign_dir), "--json", "--out", str(out)]
    )
    assert code == 0
    doc = json.loads(capsys.readouterr().out)  # exactly one JSON document
    assert doc["source"]["mode"] == "replay-truth"
    assert len(doc["rows"]) == 2 * 4 * 2
    for key in ("csv", "json", "figure"):
        assert (out / doc["files"][key].split("/")[-1]).is_file()
    # the truth of a synthetic campaign is close to its logs: high, valid ratings
    for r in doc["rows"]:
        assert 0.0 <= r["overall"] <= 1.0
    assert doc["summary"]["mean_filtered"] > 0.7


def test_rate_model_through_a_predictor(campaign_dir, tmp_path, monkeypatch, capsys):
    """A stand-in predictor (the truth, lagged 3 samples) exercises the --model path."""
    from parknss.data.io import read_campaign

    def predict_campaign(model_path, campaign):
        assert str(model_path).endswith("model.json")
        return {
            tr.id: {ch: np.r_[np.repeat(tr.truth(ch)[0], 3), tr.truth(ch)[:-3]]
                    for ch in RATED_CHANNELS}
            for tr in campaign
        }  # fmt: skip

    import parknss.chain.rating

    monkeypatch.setattr(parknss.chain.rating, "predict_campaign", predict_campaign)
    model = tmp_path / "model.json"
    model.write_text("{}")
    out = tmp_path / "r"
    code = main(["rate", "--model", str(model), "--data", str(campaign_dir), "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "mean over channels" in text
    rows = list(csv.DictReader((out / "ratings.csv").open()))
    camp = read_campaign(campaign_dir)
    tr = camp[0]
    vx = [r for r in rows if r["trial_id"] == tr.id and r["channel"] == "vx"]
    pred = predict_campaign(model, camp)[tr.id]["vx"]
    assert float(vx[0]["overall"]) == pytest.approx(rate(tr["vx"], pred, DT).overall, abs=1e-6)


def test_rate_needs_exactly_one_source(campaign_dir, capsys):
    assert main(["rate", "--data", str(campaign_dir)]) == 2
    assert "exactly one of --model" in capsys.readouterr().err


def test_a_table_reads_back_from_its_json(table):
    """What the result store keeps of a rating (Fig. 7 from the store) is the whole table."""
    from parknss.metrics.rating_report import RatingTable

    doc = json.loads(json.dumps(table.to_json()))
    back = RatingTable.from_json(doc)
    assert back.rows == table.rows and back.channels == table.channels
    assert back.config == table.config and back.to_json() == doc
