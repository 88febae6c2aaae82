"""A small SVG writer for plan-view figures in metres: filled and outlined polygons,
polylines (solid, dashed, dotted), x markers, axes with ticks, a title and a legend below
the plot, without matplotlib (whose import and PNG rendering cost ``parknss plan`` about
a second of CPU; this writes a plan in milliseconds).

:class:`SvgAxes` maps a view box in metres (equal aspect, y up) onto pixels; every drawn
element is clipped to the plot area and may carry a ``class`` (the figure's layers:
``obstacle``, ``path-coarse``, ...). Text is escaped for XML and characters XML 1.0
forbids are replaced, so any scene name can be a title. :meth:`SvgAxes.save` writes the
file atomically (:func:`parknss.outputs.write_text_atomic`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from parknss.outputs import write_text_atomic

DASHES = {"solid": None, "dashed": "7,4", "dotted": "1.5,3"}
"""Stroke dash patterns (px) by name."""
FONT = "font-family='DejaVu Sans, Arial, sans-serif'"
CHAR_PX = 6.6
"""Estimated width of one character of the 12 px legend font (layout only)."""
_NOT_XML = re.compile("[^\t\n\r\u0020-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def text(value: str) -> str:
    """``value`` as XML character data or attribute text: ``& < > " '`` escaped,
    characters XML 1.0 forbids as U+FFFD (xml.sax.saxutils would import urllib: 0.1 s)."""
    out = _NOT_XML.sub("\ufffd", str(value)).replace("&", "&amp;").replace("<", "&lt;")
    return out.replace(">", "&gt;").replace('"', "&quot;").replace("'", "&apos;")


def attr(value: str) -> str:
    """``value`` as a quoted XML attribute value (escaped as :func:`text`)."""
    return f'"{text(value)}"'


def nice_step(span: float, target: int = 8) -> float:
    """A tick step of 1, 2 or 5 x 10^k giving about ``target`` ticks over ``span``."""
    raw = max(span, 1e-9) / target
    mag = 10.0 ** math.floor(math.log10(raw))
    return next(m * mag for m in (1.0, 2.0, 5.0, 10.0) if m * mag >= raw)


@dataclass(frozen=True)
class Stroke:
    """How a line is drawn: colour, width (px), dash (:data:`DASHES` key), opacity."""

    colour: str
    width: float = 1.0
    dash: str = "solid"
    opacity: float = 1.0

    def attrs(self) -> str:
        a = f"stroke='{self.colour}' stroke-width='{self.width:g}'"
        if DASHES[self.dash]:
            a += f" stroke-dasharray='{DASHES[self.dash]}'"
        if self.opacity < 1.0:
            a += f" stroke-opacity='{self.opacity:g}'"
        return a


@dataclass
class SvgAxes:
    """Axes over the view box ``xlim`` x ``ylim`` (m) at equal aspect, the plot area at
    most ``width_px`` wide and ``max_height_px`` high, with ``title`` above it and the
    legend (entries added by :meth:`legend`) below the axis labels."""

    xlim: tuple[float, float]
    ylim: tuple[float, float]
    title: str = ""
    width_px: float = 960.0
    max_height_px: float = 720.0
    xlabel: str = "x [m]"
    ylabel: str = "y [m]"
    _body: list[str] = field(default_factory=list)
    _legend: list[tuple] = field(default_factory=list)

    LEFT, RIGHT, TOP, BOTTOM = 58.0, 18.0, 34.0, 46.0

    def __post_init__(self) -> None:
        (x0, x1), (y0, y1) = self.xlim, self.ylim
        self.scale = min(self.width_px / max(x1 - x0, 1e-9),
                         self.max_height_px / max(y1 - y0, 1e-9))
        self.plot_w, self.plot_h = self.scale * (x1 - x0), self.scale * (y1 - y0)

    def px(self, pts) -> np.ndarray:
        """Pixel coordinates (N, 2) of points (N, 2+) in metres (y up in the figure)."""
        p = np.atleast_2d(np.asarray(pts, dtype=float))[:, :2]
        return np.column_stack([self.LEFT + (p[:, 0] - self.xlim[0]) * self.scale,
                                self.TOP + (self.ylim[1] - p[:, 1]) * self.scale])

    def _points(self, pts) -> str:
        return " ".join(f"{x:.2f},{y:.2f}" for x, y in self.px(pts).tolist())

    @staticmethod
    def _cls(cls: str | None) -> str:
        return f" class={attr(cls)}" if cls else ""

    def polygon(self, pts, *, fill: str | None = None, opacity: float = 1.0,
                stroke: Stroke | None = None, cls: str | None = None) -> None:
        """A closed polygon (N, 2) m, filled with ``fill`` and/or outlined by ``stroke``."""
        paint = f"fill='{fill}'" + (f" fill-opacity='{opacity:g}'" if opacity < 1 else "") \
            if fill else "fill='none'"
        line = stroke.attrs() if stroke else "stroke='none'"
        self._body.append(f"<polygon{self._cls(cls)} points='{self._points(pts)}' "
                          f"{paint} {line}/>")

    def polyline(self, pts, stroke: Stroke, cls: str | None = None) -> None:
        """An open line through points (N, 2) m."""
        self._body.append(f"<polyline{self._cls(cls)} points='{self._points(pts)}' "
                          f"fill='none' {stroke.attrs()} stroke-linejoin='round'/>")

    def cross(self, x: float, y: float, stroke: Stroke, size_px: float = 5.0,
              cls: str | None = None) -> None:
        """An x marker at (x, y) m, ``size_px`` from its centre to each tip."""
        (cx, cy), = self.px([[x, y]]).tolist()
        s = size_px
        self._body.append(f"<path{self._cls(cls)} d='M{cx - s:.2f},{cy - s:.2f}L{cx + s:.2f},"
                          f"{cy + s:.2f}M{cx - s:.2f},{cy + s:.2f}L{cx + s:.2f},{cy - s:.2f}' "
                          f"fill='none' {stroke.attrs()}/>")

    def legend(self, label: str, *, stroke: Stroke | None = None, fill: str | None = None,
               marker: bool = False) -> None:
        """A legend entry: a line sample (``stroke``), a patch (``fill``) or an x marker."""
        self._legend.append((label, stroke, fill, marker))

    def _ticks(self) -> list[str]:
        out = []
        (x0, x1), (y0, y1) = self.xlim, self.ylim
        bottom = self.TOP + self.plot_h
        for axis, lo, hi in (("x", x0, x1), ("y", y0, y1)):
            step = nice_step(hi - lo, 8 if axis == "x" else 6)
            v = math.ceil(lo / step) * step
            while v <= hi + 1e-9:
                lab = f"{v:.10g}" if abs(v) > 1e-9 else "0"
                if axis == "x":
                    (px, _), = self.px([[v, y0]]).tolist()
                    out.append(f"<line x1='{px:.2f}' y1='{bottom:.2f}' x2='{px:.2f}' "
                               f"y2='{bottom + 4:.2f}' stroke='#333'/><text x='{px:.2f}' "
                               f"y='{bottom + 16:.2f}' text-anchor='middle'>{lab}</text>")
                else:
                    (_, py), = self.px([[x0, v]]).tolist()
                    out.append(f"<line x1='{self.LEFT - 4:.2f}' y1='{py:.2f}' "
                               f"x2='{self.LEFT:.2f}' y2='{py:.2f}' stroke='#333'/><text "
                               f"x='{self.LEFT - 6:.2f}' y='{py + 4:.2f}' "
                               f"text-anchor='end'>{lab}</text>")
                v += step
        return out

    def _legend_rows(self, top: float, width: float) -> tuple[list[str], float]:
        """The legend's elements laid out in rows from ``top``; their height."""
        out, x, y = [], self.LEFT, top + 10
        for label, stroke, fill, marker in self._legend:
            w = 34 + CHAR_PX * len(label) + 18
            if x > self.LEFT and x + w > self.LEFT + width:
                x, y = self.LEFT, y + 18
            if fill:
                out.append(f"<rect x='{x:.1f}' y='{y - 6:.1f}' width='24' height='12' "
                           f"fill='{fill}'/>")
            if stroke:
                out.append(f"<line x1='{x:.1f}' y1='{y:.1f}' x2='{x + 24:.1f}' y2='{y:.1f}' "
                           f"{stroke.attrs()}/>")
            if marker:
                out.append(f"<path d='M{x + 7:.1f},{y - 5:.1f}L{x + 17:.1f},{y + 5:.1f}"
                           f"M{x + 7:.1f},{y + 5:.1f}L{x + 17:.1f},{y - 5:.1f}' stroke='#000'"
                           " stroke-width='2'/>")
            out.append(f"<text x='{x + 30:.1f}' y='{y + 4:.1f}'>{text(label)}</text>")
            x += w
        return out, (y - top + 12 if self._legend else 0.0)

    def to_string(self) -> str:
        """The whole SVG document."""
        w = self.LEFT + self.plot_w + self.RIGHT
        top, bottom = self.TOP, self.TOP + self.plot_h
        legend, legend_h = self._legend_rows(bottom + self.BOTTOM - 6, self.plot_w)
        h = bottom + self.BOTTOM + legend_h + 4
        frame = (f"x='{self.LEFT:.2f}' y='{top:.2f}' width='{self.plot_w:.2f}' "
                 f"height='{self.plot_h:.2f}'")
        return "\n".join([
            "<?xml version='1.0' encoding='UTF-8'?>",
            f"<svg xmlns='http://www.w3.org/2000/svg' width='{w:.0f}' height='{h:.0f}' "
            f"viewBox='0 0 {w:.2f} {h:.2f}' {FONT} font-size='12'>",
            f"<title>{text(self.title)}</title>",
            f"<rect width='{w:.2f}' height='{h:.2f}' fill='white'/>",
            f"<clipPath id='plot'><rect {frame}/></clipPath>",
            "<g clip-path='url(#plot)'>", *self._body, "</g>",
            f"<rect {frame} fill='none' stroke='#333'/>",
            *self._ticks(),
            f"<text x='{self.LEFT + self.plot_w / 2:.2f}' y='{top - 12:.2f}' "
            f"text-anchor='middle' font-size='14'>{text(self.title)}</text>",
            f"<text x='{self.LEFT + self.plot_w / 2:.2f}' y='{bottom + 34:.2f}' "
            f"text-anchor='middle'>{text(self.xlabel)}</text>",
            f"<text transform='translate(16 {(top + bottom) / 2:.2f}) rotate(-90)' "
            f"text-anchor='middle'>{text(self.ylabel)}</text>",
            *legend, "</svg>", ""])

    def save(self, path: str | Path) -> Path:
        """Write the SVG to ``path`` atomically; ``path``."""
        return write_text_atomic(path, self.to_string())
