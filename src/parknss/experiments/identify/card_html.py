"""The model card as one self-contained HTML page (no scripts, no external resources).

Every piece of text that comes from the data, a path, a trial or a file name goes through
:func:`html.escape`: a hostile campaign name or trial id shows as text, never as markup.
"""

from __future__ import annotations

import html
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from parknss.experiments.identify.card import ModelCard

STYLE = """
body{font-family:system-ui,sans-serif;max-width:64rem;margin:2rem auto;padding:0 1rem;
color:#1b1b1b;line-height:1.4}
h1{font-size:1.6rem}h2{font-size:1.2rem;border-bottom:1px solid #ccc;margin-top:2rem}
table{border-collapse:collapse;margin:.5rem 0}td,th{border:1px solid #ccc;padding:.2rem .5rem}
th{background:#f3f3f3;text-align:left}td.n{text-align:right;font-variant-numeric:tabular-nums}
.warn{background:#fff4e5;border-left:4px solid #e8a33d;padding:.4rem .8rem}
pre{background:#f6f6f6;padding:.5rem;overflow-x:auto}nav a{margin-right:.8rem}
"""


def esc(x: object) -> str:
    """Text as HTML text."""
    return html.escape(str(x), quote=True)


def num(v: object, fmt: str = ".4g") -> str:
    if v is None:
        return "–"
    if isinstance(v, bool | int):
        return esc(v)
    if isinstance(v, float):
        return esc(format(v, fmt))
    return esc(v)


def table(head: list[str], rows: list[list[object]], fmt: str = ".4g") -> str:
    """An HTML table; numbers right-aligned, every cell escaped."""
    out = ["<table><tr>" + "".join(f"<th>{esc(h)}</th>" for h in head) + "</tr>"]
    for r in rows:
        cells = []
        for v in r:
            is_num = isinstance(v, int | float) and not isinstance(v, bool)
            cells.append(f"<td class=n>{num(v, fmt)}</td>" if is_num else f"<td>{num(v)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "".join(out) + "</table>"


def _data(card: ModelCard) -> str:
    d = card.data
    sp = d.get("speed_kmh") or {}
    rows = [["campaign", d.get("name")], ["trials", d.get("trials")],
            ["classes", ", ".join(f"{k} × {v}" for k, v in (d.get("classes") or {}).items())],
            ["logged duration [s]", d.get("duration_s")],
            ["synthetic", d.get("synthetic")],
            ["max forward / reverse speed [km/h]",
             f"{num(sp.get('forward_max'), '.2f')} / {num(sp.get('reverse_max'), '.2f')}"],
            ["time in reverse gear", num(d.get("reverse_fraction"), ".1%")],
            ["yaw R² (kinematic check)", d.get("yaw_r2")],
            ["steering-ratio fit", d.get("steer_ratio_fit")],
            ["channels absent", ", ".join(d.get("channels_absent") or []) or "none"],
            ["data hash", d.get("data_hash")],
            ["truth", (d.get("truth") or {}).get("note", "none (not a synthetic campaign of a "
                                                      "reference vehicle found here)")]]
    out = table(["item", "value"], rows)
    cond = d.get("conditions")
    if cond:
        crow = []
        for k, v in cond.items():
            if isinstance(v, dict):
                crow.append([k, v.get("min"), v.get("max")])
            elif k != "trials":
                crow.append([k, ", ".join(map(str, v)), ""])
        out += "<p>Conditions recorded per trial (range over trials):</p>"
        out += table(["condition", "min", "max"], crow)
    else:
        out += "<p>No per-trial conditions recorded.</p>"
    return out


def _open_loop(card: ModelCard) -> str:
    from parknss.experiments.identify.card import OPEN_LOOP_KEYS

    ol = card.open_loop
    if "note" in ol:
        return f"<p>{esc(ol['note'])}</p>"
    rows = []
    for name, label in (("nss_open_loop", "NSS from the logged actuals"),
                        ("chain_open_loop", "chain from the logged commands")):
        for ref in ("logged", "truth"):
            e = (ol.get(name) or {}).get(ref)
            if e:
                rows.append([f"{label}, vs {ref}", *[e.get(k) for k, _ in OPEN_LOOP_KEYS]])
    out = table(["model (every trial, in sample)", *[lab for _, lab in OPEN_LOOP_KEYS]], rows)
    return out + f"<p>Seed spread: {esc(ol.get('seed_spread'))}</p>"


def _table4(card: ModelCard) -> str:
    t = card.table4
    if not t:
        return "<p>chain stage not run</p>"
    labels = {"all_measured": "All channels measured (reference)",
              "selected_assembly": "Assembled chain, Phase B winners",
              "signal_target": "Assembled chain, signal-fitted target",
              "cotuned_target": "Assembled chain, co-tuned target (deployed)",
              "monolithic": "Monolithic NSS on commands", "static_affine": "Static affine maps"}
    rows = [[labels.get(k, k), r.get("vx_full"), r.get("vx_moving"), r.get("yaw_moving")]
            for k, r in t["rows"].items()]
    win = ", ".join(f"{k}: {v}" for k, v in t["winners"].items())
    return (table(["configuration", "vx full [(km/h)²]", "vx moving", "ω_z moving [(°/s)²]"],
                  rows) + f"<p>Actuator winners: {esc(win)}</p>")


def _iso(card: ModelCard) -> str:
    s = card.iso
    if not s:
        return "<p>rating stage not run</p>"
    rows = [[c.get("channel"), c.get("conditioning"), c.get("n_trials"), c.get("corridor"),
             c.get("phase"), c.get("magnitude"), c.get("slope"), c.get("overall"),
             c.get("grade")] for c in s.get("channels", [])]
    return (table(["channel", "conditioning", "trials", "Z", "E_P", "E_M", "E_S", "R", "grade"],
                  rows, ".3f")
            + f"<p>Mean rating: raw {num(s.get('mean_raw'), '.3f')}, 5 Hz filtered "
              f"{num(s.get('mean_filtered'), '.3f')}</p>")


def _closed_loop(card: ModelCard) -> str:
    c = card.closed_loop
    if not c or not c.get("summary"):
        return "<p>grid stage not run</p>"
    plants = list(c["summary"])
    keys = [("completed", "completed"), ("plannable", "plannable"), ("cells", "cells"),
            ("goal_mean_cm", "goal error mean [cm]"), ("goal_median_cm", "median [cm]"),
            ("goal_max_cm", "max [cm]"), ("clearance_mean_cm", "driven clearance mean [cm]"),
            ("under_floor", "cells under the 20 cm floor"),
            ("collisions", "collisions"), ("livelocks", "livelocks"), ("timeouts", "timeouts"),
            ("duration_mean_s", "duration mean [s]")]
    rows = [[lab, *[c["summary"][p].get(k) for p in plants]] for k, lab in keys]
    out = f"<p>Grid {esc(c.get('grid'))} ({esc(c.get('cells'))} cells) of this car's geometry"
    out += f"; interface gains: {esc(c['gains_source'])}.</p>" if c.get("gains") else ".</p>"
    out += table(["Table V", *plants], rows, ".3g")
    if c.get("gains"):
        out += table(["gain", "value"], [[k, v] for k, v in c["gains"].items()])
    return out


def _fidelity(card: ModelCard) -> str:
    f = card.fidelity
    if not f:
        return "<p>fidelity stage not run</p>"
    if f.get("skipped"):
        return f"<p>{esc(f['skipped'])}</p>"
    return f"<pre>{esc(f.get('text', ''))}</pre>"


def _domain(card: ModelCard) -> str:
    d = card.domain
    rows = [[ch, r.get("unit"), r.get("min"), r.get("max"), r.get("p0_5"), r.get("p99_5")]
            for ch, r in d.get("seen", {}).items()]
    out = table(["channel", "unit", "min", "max", "0.5th pct", "99.5th pct"], rows)
    fmu = d.get("fmu")
    if fmu:
        names = fmu["cmd_names"] + fmu["state_names"]
        lo = fmu["cmd_lo"] + fmu["state_lo"]
        hi = fmu["cmd_hi"] + fmu["state_hi"]
        out += ("<p>Identified domain the FMU checks (it reports "
                "<code>outside_domain</code> beyond it):</p>"
                + table(["quantity", "low", "high"],
                        [[n, a, b] for n, a, b in zip(names, lo, hi, strict=True)]))
    return out


def _stages(card: ModelCard) -> str:
    rows = [[s["stage"], s["status"], s.get("wall_s"), s.get("sittings"),
             s.get("reused") or ""] for s in card.stages]
    return table(["stage", "status", "wall [s]", "sittings", "reused (why)"], rows, ".1f")


SECTIONS = (("data", "Identified on", _data), ("open-loop", "Open-loop errors", _open_loop),
            ("table4", "Table IV: the chain", _table4), ("iso", "ISO/TS 18571 rating", _iso),
            ("closed-loop", "Closed loop (Table V)", _closed_loop),
            ("fidelity", "Fidelity against the truth", _fidelity),
            ("domain", "Domain of validity", _domain))


def card_html(card: ModelCard) -> str:
    """The page (module doc)."""
    nav = "".join(f'<a href="#{sid}">{esc(t)}</a>' for sid, t, _ in SECTIONS)
    body = [f"<h1>Model card: {esc(card.data.get('name'))}</h1>",
            f"<p>Chain artefact <code>{esc(card.chain)}</code>; NSS recipe "
            f"{esc(card.recipe)}; generated {esc(card.generated_utc)} by parknss "
            f"{esc(card.parknss_git[:12])}.</p>"]
    if card.data.get("synthetic"):
        body.append('<p class=warn>The campaign is synthetic: every number here was '
                    "measured on the parknss reference vehicle, not on a real car.</p>")
    if card.nss.get("reused"):
        body.append(f"<p class=warn>NSS reused, not fitted here: {esc(card.nss['reused'])}"
                    "</p>")
    body.append(f"<nav>{nav}<a href=\"#not-for\">Must not be used for</a>"
                '<a href="#stages">Stages</a></nav>')
    for sid, title, fn in SECTIONS:
        body.append(f'<h2 id="{sid}">{esc(title)}</h2>{fn(card)}')
    body.append('<h2 id="not-for">Must not be used for</h2><ul>'
                + "".join(f"<li>{esc(x)}</li>" for x in card.not_for) + "</ul>")
    body.append(f'<h2 id="stages">Stages</h2>{_stages(card)}')
    return ("<!DOCTYPE html><html lang=en><head><meta charset=utf-8>"
            f"<title>Model card: {esc(card.data.get('name'))}</title>"
            "<meta http-equiv=Content-Security-Policy content=\"default-src 'none'; "
            "style-src 'unsafe-inline'\">"
            f"<style>{STYLE}</style></head><body>{''.join(body)}</body></html>\n")
