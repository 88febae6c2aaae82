"""The SVG writer: a well-formed document whose points are the given ones in pixels,
text escaped whatever it holds, ticks at 1-2-5 steps, the legend below the plot."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from parknss.report.svg import Stroke, SvgAxes, nice_step

NS = {"s": "http://www.w3.org/2000/svg"}


def _points(el) -> np.ndarray:
    return np.array([[float(v) for v in p.split(",")] for p in el.get("points").split()])


def test_a_document_holds_its_shapes_at_their_pixels_and_escapes_text(tmp_path):
    name = 'lot <B> & "C" \x07\u202e'
    ax = SvgAxes((-2.0, 8.0), (-1.0, 4.0), title=name, width_px=500)
    line = np.array([[0.0, 0.0], [3.0, 1.5], [6.0, 3.0]])
    ax.polyline(line, Stroke("#8e44ad", 1.4, "dashed"), cls="path")
    ax.polygon([[0, 0], [1, 0], [1, 1]], fill="#9aa5b1", opacity=0.8, cls='a"b')
    ax.cross(6.0, 3.0, Stroke("#000000", 2.0), cls="cusp")
    ax.legend("<refined & more>", stroke=Stroke("#8e44ad"))
    path = ax.save(tmp_path / "f.svg")
    root = ET.parse(path).getroot()  # well-formed XML
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    title = root.find("s:title", NS).text
    assert title == 'lot <B> & "C" \ufffd\u202e'  # the control character replaced
    assert "<B>" not in path.read_text()
    (pl,) = root.findall(".//s:polyline[@class='path']", NS)
    assert np.allclose(_points(pl), ax.px(line), atol=0.006)
    assert pl.get("stroke-dasharray")
    # metres -> pixels: equal aspect, y up, the plot area 500 px wide
    px = ax.px(np.array([[-2.0, 4.0], [8.0, -1.0]]))
    assert np.allclose(px[1] - px[0], [500.0, 250.0])
    assert root.findall(".//s:polygon[@class='a\"b']", NS)
    texts = [t.text for t in root.iter("{http://www.w3.org/2000/svg}text")]
    assert "<refined & more>" in texts
    legend_y = max(float(t.get("y")) for t in root.iter("{http://www.w3.org/2000/svg}text")
                   if t.text == "<refined & more>")
    assert legend_y > px[1, 1] + 30  # below the plot and its tick labels


@pytest.mark.parametrize(("span", "step"), [(10.0, 2.0), (32.0, 5.0), (0.7, 0.1),
                                            (1000.0, 200.0)])
def test_tick_steps_are_1_2_5(span, step):
    assert nice_step(span) == pytest.approx(step)


def test_a_tall_view_is_limited_in_height():
    ax = SvgAxes((0.0, 1.0), (0.0, 100.0), width_px=900, max_height_px=600)
    assert ax.plot_h == pytest.approx(600.0) and ax.plot_w == pytest.approx(6.0)
