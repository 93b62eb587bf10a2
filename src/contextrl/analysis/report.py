"""A self-contained HTML report: sections with text, tables and figures embedded as data URIs.

One file, no external resources, so a report can be mailed, archived next to its run or opened offline.
Every figure is an ``<img class="figure" data-figure=NAME>`` so a browser test can find them all.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import json
from collections.abc import Mapping, Sequence
from typing import Any

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }
h1 { border-bottom: 2px solid #446; } h2 { margin-top: 2em; color: #335; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; display: block;
        max-width: 100%; overflow-x: auto; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }
th { background: #eef; } td:first-child, th:first-child { text-align: left; }
figure { display: inline-block; margin: 0.5em; vertical-align: top; }
figcaption { font-size: 0.85em; color: #555; max-width: 560px; }
img.figure { max-width: 100%; border: 1px solid #ddd; }
pre { background: #f6f6f8; padding: 1em; white-space: pre-wrap; overflow-wrap: anywhere;
      font-size: 0.85em; }
.failed { color: #a00; }
.warning { border: 2px solid #a00; background: #fee; color: #700; padding: 0.6em 1em; }
"""


@dataclasses.dataclass
class Figure:
    """A PNG figure with a name (unique in the report) and a caption."""

    name: str
    png: bytes
    caption: str = ""


@dataclasses.dataclass
class Section:
    """A heading, paragraphs, tables (lists of row dicts) and figures."""

    title: str
    text: Sequence[str] = ()
    tables: Sequence[tuple[str, Sequence[Mapping[str, Any]]]] = ()
    figures: Sequence[Figure] = ()
    code: str = ""
    warnings: Sequence[str] = ()  # shown first, in a red box: results a reader must not trust


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return html.escape(str(value))


def table_html(rows: Sequence[Mapping[str, Any]], caption: str = "") -> str:
    """An HTML table from row dicts (columns from the first row)."""
    if not rows:
        return f"<p><em>{html.escape(caption)}: no rows</em></p>"
    columns = list(rows[0])
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{_cell(row.get(c, ''))}</td>" for c in columns) + "</tr>"
        for row in rows
    )
    title = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    return f"<table>{title}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def figure_html(figure: Figure) -> str:
    data = base64.b64encode(figure.png).decode("ascii")
    caption = html.escape(figure.caption or figure.name)
    return (
        f'<figure><img class="figure" data-figure="{html.escape(figure.name)}" '
        f'alt="{caption}" src="data:image/png;base64,{data}"><figcaption>{caption}</figcaption>'
        "</figure>"
    )


def render(title: str, sections: Sequence[Section], metadata: Mapping[str, Any]) -> str:
    """The whole report as one HTML string."""
    names = [f.name for s in sections for f in s.figures]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(f"figure names must be unique in a report; repeated: {duplicates}")
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
    ]
    for section in sections:
        slug = "".join(ch if ch.isalnum() else "-" for ch in section.title.lower())
        parts.append(f"<section id='{slug}'><h2>{html.escape(section.title)}</h2>")
        parts.extend(
            f"<p class='warning'>WARNING: {html.escape(warning)}</p>"
            for warning in section.warnings
        )
        parts.extend(f"<p>{html.escape(paragraph)}</p>" for paragraph in section.text)
        parts.extend(table_html(rows, caption) for caption, rows in section.tables)
        parts.extend(figure_html(figure) for figure in section.figures)
        if section.code:
            parts.append(f"<pre>{html.escape(section.code)}</pre>")
        parts.append("</section>")
    meta = json.dumps(metadata, indent=2, sort_keys=True, default=str)
    parts.append(f"<section id='metadata'><h2>Run metadata</h2><pre>{html.escape(meta)}</pre>")
    parts.append("</section></body></html>")
    return "".join(parts)
