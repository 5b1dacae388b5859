"""Lab documents as PDF pages drawn by Matplotlib (``PdfPages``: pure Python, already a dependency).

A document is a list of blocks -- the same pieces the HTML page is built
from (:mod:`host.lab_report`, :mod:`host.lab_certificate`): headings,
paragraphs, label/value tables, tables, PNG figures.  :func:`layout_pages`
sets them on A4 pages (text wrapped, tables split at rows, a figure moved to
the next page when it does not fit); :func:`write_pdf` writes those pages,
and :func:`page_png` renders one page as PNG (the README's pictures are
page 1 of each document, from this same code).

Blocks: ``("h1", text)``, ``("h2", text)``, ``("p", text)``, ``("note", text)``,
``("kv", [(label, value), ...])``, ``("table", header, rows)``, ``("png", bytes)``.
"""

from __future__ import annotations

import io
import textwrap
from pathlib import Path
from typing import Any, Iterable, Sequence

__all__ = ["PAGE_SIZE_in", "layout_pages", "write_pdf", "page_png", "plain", "from_html"]

#: A4 portrait, inches (Matplotlib's figure unit).
PAGE_SIZE_in = (8.27, 11.69)
_MARGIN_in = 0.6
#: Font sizes, points.
_SIZES_pt = {"h1": 15.0, "h2": 11.5, "p": 9.0, "note": 7.5, "table": 7.0}
#: Mean glyph width of the default sans font as a fraction of its size (for wrapping by characters).
_GLYPH_EM = 0.62
_LINE = 1.35  # line height / font size
_PT_PER_in = 72.0


def plain(cell: Any) -> str:
    """A table cell as text (None: en dash); shown as given (a ``<`` in a sample name stays)."""
    return "–" if cell is None else str(cell)


def from_html(cell: Any) -> str:
    """An HTML table cell (escaped text with markup) as plain text: markup removed, entities decoded."""
    import html  # noqa: PLC0415
    import re  # noqa: PLC0415

    return "–" if cell is None else html.unescape(re.sub(r"<[^>]+>", "", str(cell)))


def _chars(width_in: float, size_pt: float) -> int:
    return max(4, int(width_in * _PT_PER_in / (size_pt * _GLYPH_EM)))


def _wrap(text: str, width_in: float, size_pt: float) -> list[str]:
    out: list[str] = []
    for para in str(text).split("\n"):
        out.extend(textwrap.wrap(para, _chars(width_in, size_pt), break_long_words=True) or [""])
    return out


class _Pages:
    """A cursor over A4 pages: ``y_in`` from the top of the current page."""

    def __init__(self, title: str, footer: str) -> None:
        from host.lab_html import pyplot  # noqa: PLC0415

        self.plt = pyplot()
        self.title, self.footer = title, footer
        self.figs: list[Any] = []
        self.width_in = PAGE_SIZE_in[0] - 2 * _MARGIN_in
        self._new()

    def _new(self) -> None:
        fig = self.plt.figure(figsize=PAGE_SIZE_in)
        self.figs.append(fig)
        self.fig = fig
        self.y_in = _MARGIN_in

    def room(self) -> float:
        return PAGE_SIZE_in[1] - _MARGIN_in - 0.3 - self.y_in   # 0.3 in kept for the footer

    def need(self, h_in: float) -> None:
        if h_in > self.room() and self.y_in > _MARGIN_in + 1e-9:
            self._new()

    def text(self, x_in: float, line: str, size_pt: float, **kw: Any) -> None:
        self.fig.text(x_in / PAGE_SIZE_in[0], 1.0 - self.y_in / PAGE_SIZE_in[1], line, fontsize=size_pt,
                      va="top", ha="left", **kw)

    def hline(self, x0_in: float, x1_in: float, y_in: float, lw: float = 0.5, color: str = "0.6") -> None:
        from matplotlib.lines import Line2D  # noqa: PLC0415

        y = 1.0 - y_in / PAGE_SIZE_in[1]
        self.fig.add_artist(Line2D([x0_in / PAGE_SIZE_in[0], x1_in / PAGE_SIZE_in[0]], [y, y], lw=lw, color=color))

    def lines(self, lines: list[str], size_pt: float, x_in: float = _MARGIN_in, **kw: Any) -> None:
        step = size_pt * _LINE / _PT_PER_in
        for ln in lines:
            self.need(step)
            self.text(x_in, ln, size_pt, **kw)
            self.y_in += step

    def finish(self) -> list[Any]:
        n = len(self.figs)
        for i, fig in enumerate(self.figs, 1):
            fig.text(0.5, _MARGIN_in / 2 / PAGE_SIZE_in[1], f"{self.title} — {self.footer} — page {i} of {n}",
                     ha="center", va="center", fontsize=6.5, color="0.35")
        return self.figs


def _table(pg: _Pages, header: Sequence[str] | None, rows: Sequence[Sequence[Any]], size_pt: float) -> None:
    cols = max(len(header or ()), *(len(r) for r in rows)) if rows else len(header or ())
    if not cols:
        return
    texts = [[plain(c) for c in r] + [""] * (cols - len(r)) for r in rows]
    head = [plain(h) for h in header] if header else None
    # Each column gets its longest word (no word is split where the page allows), then the rest of the
    # width in proportion to how much more its longest cell (capped at 40 characters) would take.
    base, more = [], []
    for j in range(cols):
        cells = [r[j] for r in texts] + ([head[j]] if head else [])
        word = max((len(w) for c in cells for w in c.split()), default=1) + 1
        base.append(word)
        more.append(max(0, min(max((len(c) for c in cells), default=1), 40) + 1 - word))
    avail = pg.width_in * _PT_PER_in / (size_pt * _GLYPH_EM)
    if sum(base) >= avail or not sum(more):
        widths_in = [pg.width_in * b / sum(base) for b in base]
    else:
        extra = min(1.0, (avail - sum(base)) / sum(more))
        chars = [b + m * extra for b, m in zip(base, more)]
        widths_in = [pg.width_in * c / sum(chars) for c in chars]
    step = size_pt * _LINE / _PT_PER_in
    pad = 0.03

    def row(cells: list[str], bold: bool) -> None:
        wrapped = [_wrap(c, w - 2 * pad, size_pt) for c, w in zip(cells, widths_in)]
        h = max(len(w) for w in wrapped) * step + 2 * pad
        pg.need(h)
        x, y0 = _MARGIN_in, pg.y_in
        for lines, w in zip(wrapped, widths_in):
            pg.y_in = y0 + pad
            for ln in lines:
                pg.text(x + pad, ln, size_pt, fontweight="bold" if bold else "normal")
                pg.y_in += step
            x += w
        pg.y_in = y0 + h
        pg.hline(_MARGIN_in, _MARGIN_in + pg.width_in, pg.y_in, lw=0.8 if bold else 0.4)

    if head:
        row(head, True)
    for r in texts:
        row(r, False)
    pg.y_in += 0.08


def _png(pg: _Pages, png: bytes) -> None:
    import matplotlib.image as mpimg  # noqa: PLC0415

    img = mpimg.imread(io.BytesIO(png), format="png")
    h_px, w_px = img.shape[:2]
    w_in = pg.width_in
    h_in = w_in * h_px / w_px
    full = PAGE_SIZE_in[1] - 2 * _MARGIN_in - 0.3
    if h_in > full:  # taller than a page: scaled to one
        w_in, h_in = w_in * full / h_in, full
    pg.need(h_in)
    ax = pg.fig.add_axes([_MARGIN_in / PAGE_SIZE_in[0], 1.0 - (pg.y_in + h_in) / PAGE_SIZE_in[1],
                          w_in / PAGE_SIZE_in[0], h_in / PAGE_SIZE_in[1]])
    ax.imshow(img, interpolation="antialiased")
    ax.set_axis_off()
    pg.y_in += h_in + 0.1


def layout_pages(title: str, blocks: Iterable[tuple], footer: str = "") -> list[Any]:
    """The document's A4 pages as Matplotlib figures (close them, or :func:`write_pdf` does)."""
    pg = _Pages(title, footer)
    for b in blocks:
        kind = b[0]
        if kind in ("h1", "h2"):
            size = _SIZES_pt[kind]
            pg.y_in += 0.12 if kind == "h2" else 0.0
            pg.need(size * _LINE * 3 / _PT_PER_in)  # a heading is not left alone at a page's foot
            pg.lines(_wrap(b[1], pg.width_in, size), size, fontweight="bold")
            pg.hline(_MARGIN_in, _MARGIN_in + pg.width_in, pg.y_in, lw=1.2 if kind == "h1" else 0.6, color="0.3")
            pg.y_in += 0.06
        elif kind in ("p", "note"):
            size = _SIZES_pt[kind]
            pg.lines(_wrap(b[1], pg.width_in, size), size, color="0.25" if kind == "note" else "black")
            pg.y_in += 0.05
        elif kind == "kv":
            _table(pg, None, [(k, v) for k, v in b[1]], _SIZES_pt["table"] + 0.5)
        elif kind == "table":
            _table(pg, b[1], b[2], _SIZES_pt["table"])
        elif kind == "png":
            _png(pg, b[1])
        else:
            raise ValueError(f"unknown block {kind!r}")
    return pg.finish()


def write_pdf(path: str | Path, pages: list[Any], *, title: str, compress: bool = True) -> Path:
    """Write ``pages`` (closed after) as one PDF, atomically; ``compress=False`` leaves the text readable in
    the file's bytes (the tests search it)."""
    import matplotlib  # noqa: PLC0415
    from matplotlib.backends.backend_pdf import PdfPages  # noqa: PLC0415

    from host.atomic import atomic_path  # noqa: PLC0415

    out = Path(path)
    try:
        with matplotlib.rc_context({"pdf.compression": 6 if compress else 0}), atomic_path(out) as tmp:
            with PdfPages(tmp, metadata={"Title": title, "Creator": "thermotouch"}) as pdf:
                for fig in pages:
                    pdf.savefig(fig)
    finally:
        import matplotlib.pyplot as plt  # noqa: PLC0415

        for fig in pages:
            plt.close(fig)
    return out


def page_png(fig: Any, dpi: int = 80) -> bytes:
    """One page as PNG bytes (the figure stays open)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()
