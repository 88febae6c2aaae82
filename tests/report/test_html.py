"""The HTML report: the findings table links each finding to its section, text cells are
left-aligned and numbers right-aligned (tests/experiments/test_studies.py checks that
Table III names its units)."""

from __future__ import annotations

from html.parser import HTMLParser
from types import SimpleNamespace

from parknss.experiments.results import Finding, Table
from parknss.report.html import write_report


class _Cells(HTMLParser):
    """(tag, attrs, text) of every td/th and the ids/hrefs of the page."""

    def __init__(self) -> None:
        super().__init__()
        self.cells: list[tuple[str, dict, str]] = []
        self.ids: set[str] = set()
        self.hrefs: list[str] = []
        self._open: tuple[str, dict] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "a":
            self.hrefs.append(a.get("href", ""))
        if tag in ("td", "th"):
            self._open = (tag, a)
            self.cells.append((tag, a, ""))

    def handle_data(self, data):
        if self._open is not None:
            tag, a, text = self.cells[-1]
            self.cells[-1] = (tag, a, text + data)

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._open = None


def test_findings_link_to_sections_and_cells_align_by_type(tmp_path):
    table = Table("Table III", ["axis", "vx [(km/h)²]", "n"], [["loss", 0.12345678, 3]])
    res = SimpleNamespace(
        findings=[Finding("MAE beats MSE", "MSE +32.6 %", True)], tables=[table], figures=[],
        notes="", wall_s=1.0)
    art = SimpleNamespace(name="table3", title="Table III: design ablations",
                          paper_ref="§V-C")
    path = write_report(tmp_path / "r.html", "report", [(art, res)], {"quick": False})
    page = _Cells()
    page.feed(path.read_text())
    assert "#table3" in page.hrefs and "table3" in page.ids
    td = {text: a.get("class") for tag, a, text in page.cells if tag == "td"}
    assert td["0.1235"] == "num" and td["3"] == "num"
    assert td["loss"] is None and td["MAE beats MSE"] is None and td["agrees"] == "yes"
    heads = [text for tag, _, text in page.cells if tag == "th"]
    assert "section" in heads and all(h.strip() for h in heads)



def test_a_findings_verdict_on_the_second_metric_is_shown_under_its_own(tmp_path):
    f = Finding("Windows", "10 % padding -5.6 % [-22.3, +11.0]", None,
                "cannot tell at this budget (10 % padding vx: effect -5.6 %, interval "
                "[-22.3, +11.0] %)", beside="full trajectory: differs")
    res = SimpleNamespace(findings=[f, Finding("MAE", "x", True)], tables=[], figures=[],
                          notes="", wall_s=1.0)
    art = SimpleNamespace(name="table3", title="Table III", paper_ref="§V-C")
    page = _Cells()
    page.feed(write_report(tmp_path / "r.html", "report", [(art, res)], {}).read_text())
    verdicts = [t for tag, a, t in page.cells if tag == "td" and a.get("class") in ("na", "yes")]
    assert verdicts[0].startswith("cannot tell at this budget (10 % padding vx")
    assert verdicts[0].endswith("full trajectory: differs") and verdicts[1] == "agrees"
