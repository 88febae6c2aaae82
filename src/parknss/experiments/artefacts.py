"""The registered artefacts of ``parknss reproduce``: one function per paper table/figure.

Each function is small: it calls the study or evaluation code that does the work and turns
its typed result into report tables, figures and findings.
"""

from __future__ import annotations

from parknss.experiments.registry import ArtefactResult, RunContext, Table, register


@register("campaign", "Field-test campaign summary (synthetic)", "§IV-A")
def campaign_summary(ctx: RunContext) -> ArtefactResult:
    from parknss.data.describe import describe_campaign
    from parknss.report.trial_figure import draw_trial

    s = describe_campaign(ctx.campaign()).to_json()
    rows = [
        [
            t["id"],
            t["class"],
            t["length_s"],
            t["direction_changes"],
            t["blind_zone_fraction"],
            t["max_speed_kmh"],
        ]
        for t in s["trials"]
    ]
    table = Table(
        "Trials",
        [
            "id",
            "class",
            "length [s]",
            "direction changes",
            "blind-zone fraction",
            "max |vx| [km/h]",
        ],
        rows,
    )
    checks = Table(
        "Campaign checks (paper: yaw R² 0.997, ratio fit 12.0, 72 changes)",
        ["yaw R² (moving)", "steering-ratio fit", "direction changes"],
        [[s["yaw_r2"], s["steer_ratio_fit"], s["direction_changes"]]],
    )
    fig = draw_trial(ctx.campaign()[0], ctx.out_dir / "campaign_trial.png")
    return ArtefactResult(tables=[checks, table], figures=[fig])
