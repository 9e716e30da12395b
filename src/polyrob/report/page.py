"""The page builder of the run report: HTML and Markdown written side by side, and how a figure reads.

:class:`Page` adds headings, paragraphs, tables and figures to both texts;
:func:`cell` turns a value into table text (``None`` or NaN into words, a
spectral radius near 1 with enough digits), so no cell reads ``nan``.
"""

from __future__ import annotations

import html
import math

import numpy as np

__all__ = ["Page", "cell", "is_missing", "CSS"]

CSS = """body{font-family:sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;color:#222;line-height:1.35}
h1{font-size:1.7em;margin:0.3em 0}#verdict{font-size:1.25em}
.scroll{overflow-x:auto;max-width:100%}table{border-collapse:collapse;margin:0.5em 0}
td,th{border:1px solid #bbb;padding:2px 8px;text-align:right;vertical-align:top}
th{background:#eee}td.l,th.l{text-align:left}td.text{min-width:14em;overflow-wrap:anywhere}
.bad{color:#c00}p.bad,tr.bad td.status{font-weight:bold}.ok{color:#070}
figure{margin:1em 0}figcaption{font-size:0.95em;color:#444}
img{max-width:100%;height:auto;border:1px solid #ddd;margin:0.5em 0}
@media (max-width:640px){body{padding:0 0.5em;margin-top:0.8em}h1{font-size:1.3em}h2{font-size:1.15em}
td,th{padding:2px 3px;font-size:0.85em}td.text{min-width:8em}}"""


def is_missing(v) -> bool:
    """``None`` or NaN: a figure that was not computed (or does not apply)."""
    return v is None or (isinstance(v, (float, np.floating)) and math.isnan(float(v)))


def cell(v, missing: str = "not computed") -> str:
    if is_missing(v):
        return missing
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        v = float(v) + 0.0  # -0.0 prints as 0
        # a spectral radius 0.99999997 must not print as 1
        return f"{v:.12g}" if 0 < abs(abs(v) - 1.0) < 1e-4 else f"{v:.5g}"
    if isinstance(v, (list, tuple)) and len(v) > 6:
        return f"[{len(v)} values]"
    return str(v)


class Page:
    """HTML and Markdown built side by side."""

    def __init__(self, title):
        self.h = [
            "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            "<meta name='viewport' content='width=device-width, initial-scale=1'>"
            f"<title>{html.escape(title)}</title>"
            f"<style>{CSS}</style></head><body><h1>{html.escape(title)}</h1>"
        ]
        self.md = [f"# {title}", ""]

    def heading(self, text):
        self.h.append(f"<h2>{html.escape(text)}</h2>")
        self.md += [f"## {text}", ""]

    def para(self, text, bad=False, ident=None):
        attrs = (f" id='{ident}'" if ident else "") + (" class='bad'" if bad else "")
        self.h.append(f"<p{attrs}>{html.escape(text)}</p>")
        self.md += [f"**{text}**" if bad or ident else text, ""]

    def table(self, header, rows, bad_rows=(), ident=None, left=(0,), classes=None):
        """A table in a horizontally scrolling box (a phone's screen); ``classes[i]``: the class of column ``i``."""
        attrs = f" id='{ident}'" if ident else ""
        classes = dict(classes or {})
        cells = "".join(f"<th class='l'>{html.escape(str(c))}</th>" for c in header)
        self.h.append(f"<div class='scroll'><table{attrs}><tr>{cells}</tr>")
        for k, row in enumerate(rows):
            tr = " class='bad'" if k in bad_rows else ""
            tds = []
            for i, c in enumerate(row):
                cls = " ".join(x for x in ("l" if i in left else "", classes.get(i, "")) if x)
                attr = f" class='{cls}'" if cls else ""
                tds.append(f"<td{attr}>{html.escape(cell(c))}</td>")
            self.h.append(f"<tr{tr}>" + "".join(tds) + "</tr>")
        self.h.append("</table></div>")
        self.md += ["| " + " | ".join(map(str, header)) + " |", "|" + "---|" * len(header)]
        self.md += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
        self.md.append("")

    def figure(self, rel, caption):
        self.h.append(
            f"<figure><img src='{html.escape(rel)}' alt='{html.escape(caption)}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )
        self.md += [f"![{caption}]({rel})", ""]

    def text(self):
        return "\n".join(self.h + ["</body></html>"]), "\n".join(self.md)
