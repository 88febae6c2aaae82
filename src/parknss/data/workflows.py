"""Which schema channels each workflow of parknss needs: the one table, and its checks.

A campaign may lack any schema channel except ``t`` (a channel mapping may declare
channels ``absent``: a real car's log often has no command channels, sometimes no brake
pressure), but every trial of one campaign has the same channel set. What a campaign can
be used for follows from that set and the table below:

* ``nss``: gear, torque, brake_pressure, steer (the NSS inputs), vx, yaw_rate (its
  states), ax, ay (its outputs). Used by train, cv, evaluate --model, rate --model, study.
* ``actuators``: the nss channels plus torque_cmd, decel_cmd, steer_cmd (each submodel
  maps a command onto its actual). Used by actuators study, ladder, build, stress.
* ``rate``: rolling a chain out from the logged commands: gear and the three commands
  (its inputs), the actuals (the chain starts its submodels from the measured actuals at
  k = 0 and replays a channel it leaves measured), vx and yaw_rate (initial state, rated),
  ax and ay (rated). Used by rate --chain and evaluate --chain. Today this is the same set
  as ``actuators``.
* ``closed_loop``: parking this car through its learned chain: what ``actuators`` needs,
  since the chain must be identified from the campaign.

Sources of the sets: ``parknss.nss.model.INPUTS/STATES/OUTPUTS`` and
``parknss.data.windows`` (NSS), ``parknss.actuators.spec`` (command -> actual per
channel), ``parknss.chain.trial_batch`` (what a chain rollout reads) and
``parknss.metrics.rating_report.RATED_CHANNELS`` (what the rating compares).
"""

from __future__ import annotations

from dataclasses import dataclass

from parknss.data.trial import Campaign
from parknss.errors import DataError
from parknss.signals import (
    ACTUAL_CHANNELS,
    COMMAND_CHANNELS,
    OUTPUT_CHANNELS,
    REQUIRED_CHANNELS,
    STATE_CHANNELS,
)

ABSENT_HINT = "the mapping declares them absent; log them, or use a campaign that has them"


def schema_order(names: set[str] | frozenset[str] | tuple[str, ...]) -> tuple[str, ...]:
    """``names`` restricted to schema channels, in schema order (signals.CHANNELS)."""
    return tuple(c for c in REQUIRED_CHANNELS if c in set(names))


@dataclass(frozen=True)
class Workflow:
    """One workflow and the schema channels it reads.

    Attributes:
        name: the key (``nss``, ``actuators``, ``rate``, ``closed_loop``).
        purpose: the workflow in words, as it reads in "..., which <purpose> needs".
        channels: the schema channels it needs, in schema order.
        commands: the ``parknss`` commands that run it (for messages and docs).
    """

    name: str
    purpose: str
    channels: tuple[str, ...]
    commands: tuple[str, ...]


NSS = Workflow(
    "nss",
    "identifying the NSS (inputs, states, outputs)",
    schema_order((*ACTUAL_CHANNELS, *STATE_CHANNELS, *OUTPUT_CHANNELS)),
    ("train", "cv", "evaluate --model", "rate --model", "study"),
)
ACTUATORS = Workflow(
    "actuators",
    "identifying the actuator chain (commands -> actuals -> NSS)",
    schema_order((*NSS.channels, *COMMAND_CHANNELS)),
    ("actuators study", "actuators ladder", "actuators build", "actuators stress"),
)
RATE = Workflow(
    "rate",
    "rolling a chain out from the logged commands (its rating and open-loop errors)",
    schema_order((*COMMAND_CHANNELS, *ACTUAL_CHANNELS, *STATE_CHANNELS, *OUTPUT_CHANNELS)),
    ("rate --chain", "evaluate --chain"),
)
CLOSED_LOOP = Workflow(
    "closed_loop",
    "parking this car through its learned chain (identified from the campaign)",
    ACTUATORS.channels,
    ("actuators build, then simulate/grid/web --plant chain",),
)
WORKFLOWS: dict[str, Workflow] = {w.name: w for w in (NSS, ACTUATORS, RATE, CLOSED_LOOP)}


@dataclass(frozen=True)
class WorkflowSupport:
    """Whether a campaign supports one workflow.

    Attributes:
        workflow: the workflow's name.
        ok: every channel it needs is present.
        missing: the needed channels the campaign lacks, schema order (empty when ok).
        reason: one line, e.g. ``"lacks torque_cmd, decel_cmd, steer_cmd"``.
    """

    workflow: str
    ok: bool
    missing: tuple[str, ...]
    reason: str

    def to_json(self) -> dict:
        return {
            "ok": self.ok,
            "missing": list(self.missing),
            "needs": list(WORKFLOWS[self.workflow].channels),
            "reason": self.reason,
        }


def _trial_set(channels) -> frozenset[str]:
    return frozenset(c for c in channels if c in REQUIRED_CHANNELS)


def campaign_channels(campaign: Campaign) -> tuple[str, ...]:
    """The schema channels every trial of ``campaign`` has, in schema order.

    Raises DataError (one line) for an empty campaign or one whose trials differ in their
    schema channels, naming the first trial that differs from the first trial.
    """
    if len(campaign) == 0:
        raise DataError(f"campaign {campaign.name!r} has no trials")
    first = campaign[0]
    ref = _trial_set(first.channels)
    for tr in campaign.trials[1:]:
        have = _trial_set(tr.channels)
        if have != ref:
            parts = []
            if ref - have:
                parts.append(f"lacks {', '.join(schema_order(ref - have))}")
            if have - ref:
                parts.append(f"has {', '.join(schema_order(have - ref))} in addition")
            raise DataError(
                f"campaign {campaign.name!r} is inconsistent: trial {tr.id!r} "
                f"{' and '.join(parts)} compared with trial {first.id!r}; all trials of a "
                "campaign must have the same channels (re-import them with one mapping)"
            )
    return schema_order(ref)


def absent_channels(campaign: Campaign) -> tuple[str, ...]:
    """Schema channels the campaign lacks (schema order); DataError if inconsistent."""
    have = set(campaign_channels(campaign))
    return tuple(c for c in REQUIRED_CHANNELS if c not in have)


def _support(workflow: Workflow, have: set[str]) -> WorkflowSupport:
    missing = tuple(c for c in workflow.channels if c not in have)
    reason = (
        f"all {len(workflow.channels)} channels it needs are present"
        if not missing
        else f"lacks {', '.join(missing)}"
    )
    return WorkflowSupport(workflow.name, not missing, missing, reason)


def support(campaign: Campaign) -> dict[str, WorkflowSupport]:
    """workflow name -> :class:`WorkflowSupport`, in the order of :data:`WORKFLOWS`.

    Raises DataError if the campaign is empty or its trials differ in their channels.
    """
    have = set(campaign_channels(campaign))
    return {name: _support(wf, have) for name, wf in WORKFLOWS.items()}


def require_channels(
    campaign: Campaign, channels: tuple[str, ...], purpose: str, where: str
) -> None:
    """DataError (one line) unless every trial has ``channels``.

    Args:
        campaign: the campaign to check (its trials must agree on their channels).
        channels: schema channel names needed.
        purpose: what needs them, in words ("identifying the NSS ...").
        where: who asks, e.g. ``"parknss train --data campaigns/mine"``.
    """
    have = set(campaign_channels(campaign))
    missing = tuple(c for c in schema_order(tuple(channels)) if c not in have)
    if missing:
        raise DataError(
            f"{where}: campaign {campaign.name!r} lacks {', '.join(missing)}, which "
            f"{purpose} needs; {ABSENT_HINT}"
        )


def require(campaign: Campaign, workflow: str, where: str) -> None:
    """DataError (one line) unless ``campaign`` has every channel ``workflow`` needs.

    The message names ``where`` (the command and its campaign), the campaign, the
    workflow in words, the missing channels and what to do. An unknown workflow name is a
    programming error (KeyError).
    """
    wf = WORKFLOWS[workflow]
    require_channels(campaign, wf.channels, wf.purpose, where)
