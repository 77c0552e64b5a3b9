"""Self-contained HTML pages for the reports (``bench report --html``, ``audit --html``).

A page carries everything it shows: its CSS and the few lines of JavaScript that sort a table by
the column clicked, and its figures as inline SVG (a figure without an SVG twin is embedded as a
PNG ``data:`` URL). Nothing is fetched, so a page opens from disk, from an archive or as a CI
artefact and looks the same.
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Sequence
from pathlib import Path

CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#222}
header{background:#24364b;color:#fff;padding:.6em 1.2em}
header a{color:#cfe3ff;margin-right:1em}
main{max-width:1200px;margin:0 auto;padding:.5em 1.2em 3em}
h1{font-size:1.5em}h2{font-size:1.25em;border-bottom:1px solid #ddd;padding-bottom:.2em}
h3{font-size:1.05em}
table{border-collapse:collapse;margin:.6em 0;font-size:13px}
th,td{border:1px solid #d8d8d8;padding:.2em .5em;text-align:left;vertical-align:top}
th{background:#f1f4f8}
table.sortable th{cursor:pointer;user-select:none}
table.sortable th[aria-sort=ascending]::after{content:" \\25B2"}
table.sortable th[aria-sort=descending]::after{content:" \\25BC"}
td.num{text-align:right;font-variant-numeric:tabular-nums}
tr.flagged td{background:#fff4e5}
pre{background:#f6f8fa;padding:.6em;overflow-x:auto;font-size:12px}
code{background:#f3f3f3;padding:0 .2em}
figure{margin:1em 0}figure svg,figure img{max-width:100%;height:auto}
figcaption{font-size:12px;color:#555}
.bar{display:inline-block;height:.7em;background:#4c78a8;vertical-align:middle}
"""

#: Click a header to sort by it; a cell's data-v (a number) sorts before its text.
SORT_JS = """
document.querySelectorAll("table.sortable").forEach(function (table) {
  table.querySelectorAll("th").forEach(function (th, col) {
    th.addEventListener("click", function () {
      var asc = th.getAttribute("aria-sort") !== "ascending";
      table.querySelectorAll("th").forEach(function (h) { h.removeAttribute("aria-sort"); });
      th.setAttribute("aria-sort", asc ? "ascending" : "descending");
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      function key(row) {
        var cell = row.cells[col];
        if (!cell) { return ""; }
        var v = cell.getAttribute("data-v");
        if (v !== null && v !== "" && !isNaN(Number(v))) { return Number(v); }
        var n = Number(cell.textContent.replace(/[%,\\s]|\\u00d7/g, "").replace("\\u2212", "-"));
        return isNaN(n) || cell.textContent.trim() === "" ? cell.textContent.trim() : n;
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        var c = typeof x === typeof y ? (x < y ? -1 : x > y ? 1 : 0) : (typeof x === "number" ? -1 : 1);
        return asc ? c : -c;
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
"""

Cell = str | int | float | None


def esc(text: object) -> str:
    return html.escape(str(text), quote=True)


def document(title: str, body: str, *, nav: Sequence[tuple[str, str]] = ()) -> str:
    """A whole page: ``nav`` is (label, href) links shown in the header."""
    links = "".join(f'<a href="{esc(href)}">{esc(label)}</a>' for label, href in nav)
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{esc(title)}</title><style>{CSS}</style></head><body>"
        f"<header>{links}</header><main>{body}</main>"
        f"<script>{SORT_JS}</script></body></html>\n"
    )


def table(
    headers: Sequence[str],
    rows: Sequence[Sequence[Cell]],
    *,
    raw: Sequence[int] = (),
    row_class: Sequence[str] | None = None,
    digits: int = 2,
) -> str:
    """A sortable table. Numbers are right-aligned, shown with ``digits`` decimals and sort as
    numbers; columns in ``raw`` hold HTML already (links), every other cell is escaped."""
    head = "".join(f"<th>{esc(h)}</th>" for h in headers)
    body = []
    for i, row in enumerate(rows):
        cells = []
        for j, value in enumerate(row):
            if value is None:
                cells.append("<td>–</td>")
            elif isinstance(value, int | float) and not isinstance(value, bool):
                shown = f"{value:.{digits}f}" if isinstance(value, float) else str(value)
                cells.append(f'<td class="num" data-v="{value!r}">{shown}</td>')
            else:
                cells.append(f"<td>{value if j in raw else esc(value)}</td>")
        cls = f' class="{esc(row_class[i])}"' if row_class and row_class[i] else ""
        body.append(f"<tr{cls}>{''.join(cells)}</tr>")
    return (
        f'<table class="sortable"><thead><tr>{head}</tr></thead>'
        f"<tbody>{''.join(body)}</tbody></table>"
    )


_XML_PROLOGUE = re.compile(r"^\s*(<\?xml[^>]*\?>\s*)?(<!DOCTYPE[^>]*>\s*)?", re.S)


def figure(image: Path, caption: str = "") -> str:
    """``image`` inline: its SVG twin (``x.svg`` beside ``x.png``) as markup, else the PNG as a
    data URL. The SVG keeps its own width and height; CSS scales it to the page."""
    svg = image.with_suffix(".svg")
    label = esc(caption or image.stem)
    if svg.is_file():
        markup = _XML_PROLOGUE.sub("", svg.read_text(encoding="utf-8"), count=1)
        markup = markup.replace("<svg ", f'<svg role="img" aria-label="{label}" ', 1)
    else:
        data = base64.b64encode(image.read_bytes()).decode("ascii")
        markup = f'<img alt="{label}" src="data:image/png;base64,{data}">'
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    return f"<figure>{markup}{cap}</figure>"


_IMG = re.compile(r'<img src="([^"]+)" alt="([^"]*)"\s*/?>')


def markdown(text: str, base: Path) -> str:
    """The Markdown the reports write, as HTML: tables sortable, images (relative to ``base``)
    inlined by :func:`figure`."""
    from markdown_it import MarkdownIt

    rendered = MarkdownIt("commonmark", {"html": False}).enable("table").render(text)
    rendered = rendered.replace("<table>", '<table class="sortable">')

    def inline(m: re.Match[str]) -> str:
        path = base / html.unescape(m.group(1))
        return figure(path, html.unescape(m.group(2))) if path.is_file() else m.group(0)

    # A paragraph holding only an image would wrap a <figure>: unwrap it.
    rendered = re.sub(r"<p>(<img [^>]*>)</p>", r"\1", rendered)
    return _IMG.sub(inline, rendered)


def bar(value: float, scale: float = 120.0) -> str:
    """A value in [0, 1] as a small horizontal bar (relation values in the audit's tables)."""
    width = max(0.0, min(1.0, value)) * scale
    return f'<span class="bar" style="width:{width:.0f}px"></span>'


__all__ = ["bar", "document", "esc", "figure", "markdown", "table"]
