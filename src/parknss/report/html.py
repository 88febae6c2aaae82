"""A self-contained HTML report: tables, embedded PNG figures, findings, config, revision."""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import Any

from parknss.outputs import write_text_atomic

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #ccc;padding:3px 8px;
text-align:left;vertical-align:top}th{background:#f3f3f3}td.num{text-align:right}
table.findings td{max-width:34em}
img{max-width:100%;border:1px solid #eee}.yes{color:#060}.no{color:#a00}.na{color:#777}
pre{background:#f7f7f7;padding:1em;overflow:auto;font-size:12px}.note{color:#555}
.smoke{background:#fff3cd;padding:.6em;border:1px solid #e0c36c}
"""


def _cell(v: Any) -> str:
    """One table cell: numbers right-aligned (4 significant digits), text left-aligned."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return f"<td>{html.escape(str(v))}</td>"
    return f"<td class='num'>{v:.4g}</td>" if isinstance(v, float) else f"<td class='num'>{v}</td>"


def _table(t) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in t.columns)
    body = "".join("<tr>" + "".join(_cell(c) for c in row) + "</tr>" for row in t.rows)
    return f"<h3>{html.escape(t.title)}</h3><table><tr>{head}</tr>{body}</table>"


def _figure(path: Path) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode()
    return f'<p><img alt="{html.escape(Path(path).name)}" src="data:image/png;base64,{data}"></p>'


def _finding_row(f, art) -> str:
    """A finding, what was measured, the verdict, and a link to the section it comes from."""
    cls = {True: "yes", False: "no", None: "na"}[f.agrees]
    return (
        f"<tr><td>{html.escape(f.claim)}</td><td>{html.escape(f.measured)}</td>"
        f'<td class="{cls}">{html.escape(f.verdict)}'
        f"{'<br><small>' + html.escape(f.beside) + '</small>' if f.beside else ''}</td>"
        f"<td><a href='#{html.escape(art.name)}'>{html.escape(art.title)}</a></td></tr>"
    )


def write_report(
    path: Path, title: str, sections: list[tuple[Any, Any]], meta: dict[str, Any]
) -> Path:
    """Write the report. ``sections`` is a list of (Artefact, ArtefactResult)."""
    parts = [
        f"<!doctype html><meta charset='utf-8'><title>{html.escape(title)}</title>",
        f"<style>{_CSS}</style><h1>{html.escape(title)}</h1>",
        "<p class='note'>Measured on the synthetic campaign of the parknss reference "
        "vehicle unless the data path below says otherwise; these are not the paper's "
        "field-test numbers.</p>",
    ]
    if meta.get("quick"):
        parts.append(
            "<p class='smoke'><b>Smoke test.</b> This run used the <code>--quick</code> "
            "budget (a few epochs of a tiny net): it shows that every study runs end to "
            "end; its numbers support no verdict on the paper's findings.</p>"
        )
    if meta.get("partial"):
        parts.append(f"<p class='smoke'><b>Partial report.</b> "
                     f"{html.escape(str(meta['partial']))}</p>")
    rows = "".join(_finding_row(f, art) for art, res in sections for f in res.findings)
    if rows:
        parts.append(
            "<h2>The paper's findings beside this run</h2><table class='findings'><tr>"
            "<th>paper</th><th>measured here</th><th>verdict</th><th>section</th></tr>"
            f"{rows}</table>"
        )
    for art, res in sections:
        parts.append(
            f"<h2 id='{art.name}'>{html.escape(art.title)} "
            f"<small>({html.escape(art.paper_ref)}; {res.wall_s:.1f} s)</small></h2>"
        )
        if res.notes:
            parts.append(f"<p class='note'>{html.escape(res.notes)}</p>")
        parts.extend(_table(t) for t in res.tables)
        parts.extend(_figure(p) for p in res.figures)
    parts.append(
        "<h2>Run</h2><pre>" + html.escape(json.dumps(meta, indent=2, default=str)) + "</pre>"
    )
    return write_text_atomic(path, "\n".join(parts))
