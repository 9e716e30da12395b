"""MkDocs hooks: pages generated at build time from the code and from ``benchmarks/results/*.json``.

* ``<!-- polyrob-api -->`` becomes one ``::: module.name`` block per name of
  ``polyrob.__all__`` (the reference follows the package's exports);
* ``<!-- results: NAME -->`` becomes the tables of
  ``benchmarks/results/NAME.json`` (:func:`results_markdown`), so every
  measured figure the docs show comes from a results file.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
_RESULTS_MARK = re.compile(r"^<!-- results: ([\w.-]+)(?: ([\w.-]+))? -->$", re.M)


def api_markdown() -> str:
    """One ``:::`` block per name of ``polyrob.__all__``, at the module that defines it."""
    sys.path.insert(0, str(ROOT / "src"))
    import polyrob

    blocks = []
    for name in polyrob.__all__:
        module = polyrob._LAZY.get(name, "polyrob.errors")
        blocks.append(f"::: {module}.{name}\n    options:\n      heading_level: 2\n")
    return "\n".join(blocks)


def _outside_code(text: str, escape) -> str:
    """``escape`` applied to the parts of ``text`` outside its code spans (inside them Markdown reads text as is)."""
    parts = text.split("`")
    return "`".join(part if k % 2 else escape(part) for k, part in enumerate(parts))


def _cell(value) -> str:
    """A table cell: one line, ``|`` escaped (a code span keeps its pipes: the table does not split there)."""
    text = "" if value is None else str(value).replace("\n", " ")
    return _outside_code(text, lambda part: part.replace("|", "\\|"))


def _text(value) -> str:
    """A plain-text field (title, figure, note): the paper's "K*" is a star, not the start of emphasis."""
    return _outside_code(_cell(value), lambda part: part.replace("*", "\\*"))


def record_markdown(record: dict) -> str:
    """A record as its table (or its figure) followed by one line: command, date, machine, source."""
    out = []
    if record.get("title"):
        out.append(f"**{_text(record['title'])}**\n")
    table = record.get("table")
    if table:
        out.append("| " + " | ".join(_cell(c) for c in table["columns"]) + " |")
        out.append("| " + " | ".join("---" for _ in table["columns"]) + " |")
        out.extend("| " + " | ".join(_cell(c) for c in row) + " |" for row in table["rows"])
        out.append("")
    if record.get("figure") is not None:
        out.append(f"Figure: {_text(record['figure'])}\n")
    where = f"`{record['command']}`, {record['date']}, {record['machine']}"
    if record.get("note"):
        where += f"; {_text(record['note'])}"
    if record.get("transcribed"):
        where += " (transcribed from the earlier docs)"
    out.append(f"*Measured with {where}.*\n")
    return "\n".join(out)


def results_markdown(name: str, record_id: str | None = None) -> str:
    """The records of ``benchmarks/results/NAME.json`` (all, or the one with ``id == record_id``) as Markdown."""
    path = RESULTS / f"{name}.json"
    data = json.loads(path.read_text())
    records = data["records"]
    if record_id is not None:
        records = [r for r in records if r.get("id") == record_id]
        if not records:
            raise KeyError(f"{path}: no record with id '{record_id}'")
    return "\n".join(record_markdown(r) for r in records)


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 (MkDocs' hook signature)
    if "<!-- polyrob-api -->" in markdown:
        markdown = markdown.replace("<!-- polyrob-api -->", api_markdown())
    return _RESULTS_MARK.sub(lambda m: results_markdown(m.group(1), m.group(2)), markdown)
