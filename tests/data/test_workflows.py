"""The workflow table of parknss.data.workflows: its sets are what the code reads, and
support/require/campaign_channels judge campaigns lacking channels in one line."""

from __future__ import annotations

import pytest

from helpers.synth import drop, keep, make_campaign
from parknss.actuators.spec import ACTUAL_OF, COMMAND_OF
from parknss.chain import trial_batch
from parknss.data.trial import Campaign, Trial
from parknss.data.windows import make_windows, whole_trials
from parknss.data.workflows import (
    ABSENT_HINT,
    ACTUATORS,
    CLOSED_LOOP,
    NSS,
    RATE,
    WORKFLOWS,
    absent_channels,
    campaign_channels,
    require,
    require_channels,
    support,
)
from parknss.errors import DataError
from parknss.metrics.rating_report import RATED_CHANNELS
from parknss.nss.model import INPUTS, OUTPUTS, STATES
from parknss.signals import REQUIRED_CHANNELS

COMMANDS = ("torque_cmd", "decel_cmd", "steer_cmd")


CAMP = make_campaign(60, reps=2)


def test_nss_set_is_the_models_inputs_states_outputs():
    assert set(NSS.channels) == {*INPUTS, *STATES, *OUTPUTS}
    assert NSS.channels == (
        "gear", "torque", "brake_pressure", "steer", "vx", "yaw_rate", "ax", "ay"
    )  # fmt: skip
    assert set(RATED_CHANNELS) <= set(NSS.channels)


def test_actuator_sets_add_every_command_and_actual():
    for wf in (ACTUATORS, RATE, CLOSED_LOOP):
        assert set(NSS.channels) <= set(wf.channels)
        assert {*COMMAND_OF.values(), *ACTUAL_OF.values(), "gear"} <= set(wf.channels)
        assert "t" not in wf.channels
    assert CLOSED_LOOP.channels == ACTUATORS.channels
    assert list(WORKFLOWS) == ["nss", "actuators", "rate", "closed_loop"]


@pytest.mark.parametrize(
    ("wf", "reader"),
    [
        (NSS, lambda trs: make_windows(trs, 20)),
        (NSS, whole_trials),
        # a chain rollout from the logged commands, compared with the rated channels
        (RATE, lambda trs: (trial_batch(trs), [tr.array(RATED_CHANNELS) for tr in trs])),
    ],
)
def test_sets_are_sufficient_and_necessary_for_their_readers(wf, reader):
    trials = [keep(tr, wf.channels) for tr in CAMP.trials[:3]]
    reader(trials)  # everything the reader needs is in the set
    for ch in wf.channels:  # and each channel of the set is read
        with pytest.raises(DataError, match=ch):
            reader([keep(tr, set(wf.channels) - {ch}) for tr in trials])


def test_full_campaign_supports_everything():
    s = support(CAMP)
    assert list(s) == list(WORKFLOWS)
    assert all(w.ok and w.missing == () for w in s.values())
    assert campaign_channels(CAMP) == REQUIRED_CHANNELS and absent_channels(CAMP) == ()
    require(CAMP, "actuators", "here")  # no error


def test_campaign_without_commands_supports_only_nss():
    camp = drop(CAMP, COMMANDS)
    s = support(camp)
    assert s["nss"].ok
    for name in ("actuators", "rate", "closed_loop"):
        assert not s[name].ok and s[name].missing == COMMANDS
        assert s[name].reason == "lacks torque_cmd, decel_cmd, steer_cmd"
    assert absent_channels(camp) == COMMANDS
    doc = s["actuators"].to_json()
    assert doc["missing"] == list(COMMANDS) and doc["needs"] == list(ACTUATORS.channels)


def test_campaign_without_brake_pressure_supports_nothing():
    s = support(drop(CAMP, ("brake_pressure",)))
    assert not any(w.ok for w in s.values())
    assert all(w.missing == ("brake_pressure",) for w in s.values())


def test_require_is_one_line_naming_campaign_workflow_channels_and_remedy():
    camp = drop(CAMP, ("torque_cmd", "brake_pressure"), name="mycar")
    with pytest.raises(DataError) as exc:
        require(camp, "actuators", "parknss actuators build --data campaigns/mycar")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("parknss actuators build --data campaigns/mycar: campaign 'mycar'")
    assert "lacks torque_cmd, brake_pressure," in msg  # schema order
    assert ACTUATORS.purpose in msg and msg.endswith(ABSENT_HINT)
    require(drop(CAMP, COMMANDS), "nss", "x")  # NSS needs no command
    with pytest.raises(DataError, match="lacks ax, which rating"):
        require_channels(drop(CAMP, ("ax",)), RATED_CHANNELS, "rating", "x")


def test_inconsistent_campaign_names_the_first_differing_trial():
    trials = list(CAMP.trials)
    trials[2] = keep(trials[2], set(REQUIRED_CHANNELS) - {"steer_cmd"})
    trials[3] = keep(trials[3], set(REQUIRED_CHANNELS) - {"ay"})
    camp = Campaign(trials, name="mixed")
    for call in (
        lambda: campaign_channels(camp),
        lambda: support(camp),
        lambda: require(camp, "nss", "parknss train"),
    ):
        with pytest.raises(DataError) as exc:
            call()
        msg = str(exc.value)
        assert "\n" not in msg and "inconsistent" in msg
        assert f"trial {trials[2].id!r} lacks steer_cmd" in msg and trials[0].id in msg
    extra = Campaign([keep(CAMP[0], NSS.channels), CAMP[1]], name="extra")
    with pytest.raises(DataError, match="has torque_cmd, decel_cmd, steer_cmd in addition"):
        campaign_channels(extra)


def test_truth_channels_do_not_count_and_empty_campaign_is_refused():
    tr = CAMP[0]
    with_truth = Trial(tr.id, tr.maneuver, 1, {**tr.channels, "truth_vx": tr["vx"]})
    assert campaign_channels(Campaign([with_truth, CAMP[1]])) == REQUIRED_CHANNELS
    with pytest.raises(DataError, match="has no trials"):
        support(Campaign([], name="void"))
