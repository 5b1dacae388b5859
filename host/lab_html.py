"""Plain HTML pages for lab documents: one file, no external assets, every text escaped.

A report must open years later on a machine without network and say the
same: styles are inline, plots are PNGs embedded as ``data:`` URIs, and
whatever came from a user or a file (sample names, notes, flag words,
reference names) goes through :func:`esc`, so ``<`` or ``&`` in a name shows
as typed and cannot inject markup.
"""

from __future__ import annotations

import base64
import html
import io
import math
from typing import Any, Iterable, Sequence

__all__ = ["esc", "fmt", "pm", "table", "kv_table", "page", "png_img", "figure_png"]

_STYLE = """
body { font-family: Helvetica, Arial, sans-serif; margin: 2em auto; max-width: 60em; color: #111; }
h1 { font-size: 1.5em; border-bottom: 2px solid #333; padding-bottom: .2em; }
h2 { font-size: 1.15em; margin-top: 1.6em; border-bottom: 1px solid #999; }
table { border-collapse: collapse; margin: .5em 0; font-size: .9em; }
th, td { border: 1px solid #bbb; padding: .25em .5em; text-align: left; vertical-align: top; }
th { background: #eee; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.headline { font-size: 1.2em; font-weight: bold; margin: .6em 0; }
.note { color: #444; font-size: .85em; }
.warn { color: #8a3b00; }
img { max-width: 100%; }
code { font-size: .9em; }
"""


def esc(value: Any) -> str:
    """Text for HTML: ``None`` as an en dash, everything else escaped (quotes too)."""
    if value is None:
        return "–"
    return html.escape(str(value), quote=True)


def fmt(v: float | None, digits: int = 4, scale: float = 1.0) -> str:
    """A number to ``digits`` significant digits (None: en dash)."""
    if v is None or not isinstance(v, (int, float)) or not math.isfinite(v):
        return "–"
    return f"{v * scale:.{digits}g}"


def pm(v: float | None, u: float | None, scale: float = 1.0) -> str:
    """``v ± u`` rounded to two significant digits of ``u`` (the plots' rule, :func:`host.plots._pm`)."""
    from host.plots import _pm  # noqa: PLC0415 - one rounding rule for plots and reports

    return _pm(v, u, scale)


def table(header: Sequence[str], rows: Iterable[Sequence[Any]], *, numeric: Sequence[int] = (),
          raw: Sequence[int] = ()) -> str:
    """An HTML table; cells are escaped except columns in ``raw`` (already HTML); ``numeric`` ones align right."""
    out = ["<table>", "<tr>" + "".join(f"<th>{esc(h)}</th>" for h in header) + "</tr>"]
    for row in rows:
        cells = []
        for i, c in enumerate(row):
            text = c if i in raw else esc(c)
            cells.append(f"<td class=\"num\">{text}</td>" if i in numeric else f"<td>{text}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def kv_table(pairs: Iterable[tuple[str, Any]]) -> str:
    """A two-column table of labels and values (escaped)."""
    return "<table>\n" + "\n".join(f"<tr><th>{esc(k)}</th><td>{esc(v)}</td></tr>" for k, v in pairs) + "\n</table>"


def page(title: str, body: Iterable[str]) -> str:
    """A whole HTML document with the inline style."""
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<title>{esc(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
            + "\n".join(body) + "\n</body>\n</html>\n")


def png_img(png: bytes, alt: str) -> str:
    """An ``<img>`` with the PNG embedded as base64."""
    return f"<img alt=\"{esc(alt)}\" src=\"data:image/png;base64,{base64.b64encode(png).decode('ascii')}\">"


def figure_png(fig: Any, dpi: int = 100) -> bytes:
    """A matplotlib figure as PNG bytes (the figure is closed)."""
    import matplotlib.pyplot as plt  # noqa: PLC0415

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return buf.getvalue()


def pyplot():
    """matplotlib's pyplot on the Agg backend: the touch plots' (:func:`host.plots.pyplot`, one setup)."""
    from host.plots import pyplot as shared  # noqa: PLC0415

    return shared()
