"""One measured figure as a record in ``benchmarks/results/NAME.json``: the figure, its command, date, machine, commit.

The docs' tables are generated from these files (``docs/hooks.py``), so a
benchmark script that measures a figure appends it here (``--results
PATH``) instead of a person copying it into prose.  A file is
``{"benchmark": NAME, "script": ..., "records": [...]}``; a record has
``id``, ``title``, ``command``, ``date`` (UTC, ISO), ``machine``,
``commit`` (``git rev-parse --short HEAD`` of the measured tree, ``+dirty``
when it had changes outside ``benchmarks/results/``), ``figure`` (a short text) and optionally ``table``
(``{"columns": [...], "rows": [[...]]}``) and ``data`` (the script's own
JSON).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def machine() -> str:
    """``"2-core x86_64, Python 3.11.7"``: what a figure was measured on."""
    return f"{os.cpu_count()}-core {platform.machine()}, Python {platform.python_version()}"


def commit() -> str | None:
    """The short commit of the tree being measured (``+dirty`` with uncommitted changes), or None outside git."""
    try:
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            # a results file appended by an earlier run is not a change to the measured code
            [
                "git",
                "-C",
                str(ROOT),
                "status",
                "--porcelain",
                "--untracked-files=no",
                "--",
                ".",
                ":!benchmarks/results",
            ],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+dirty" if dirty else "")


def stamp() -> str:
    """Now in UTC as ``20261127T083807``: a record id that a later record of the same file does not repeat."""
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%S")


def new_record(record_id: str, title: str, figure: str, *, table: dict | None = None, data=None) -> dict:
    """A record measured now: this command line, today's date, this machine and commit."""
    record = {
        "id": record_id,
        "title": title,
        "figure": figure,
        # quoted as a shell would need it: a case of several words stays one argument
        "command": "python " + shlex.join([os.path.relpath(sys.argv[0], ROOT), *sys.argv[1:]]),
        "date": _dt.datetime.now(_dt.timezone.utc).date().isoformat(),
        "machine": machine(),
        "commit": commit(),
        "transcribed": False,
    }
    if table is not None:
        record["table"] = table
    if data is not None:
        record["data"] = data
    return record


def append_record(path: str | Path, benchmark: str, script: str, record: dict) -> Path:
    """Append ``record`` to the results file ``path`` (created if absent); written whole, then renamed."""
    path = Path(path)
    doc = json.loads(path.read_text()) if path.exists() else {"benchmark": benchmark, "script": script, "records": []}
    doc["records"].append(record)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1, ensure_ascii=False) + "\n")
    tmp.replace(path)
    return path


def add_results_option(parser) -> None:
    """``--results PATH``: also append the script's JSON as a record of that results file."""
    parser.add_argument(
        "--results",
        default=None,
        metavar="PATH",
        help="also append this run as a record to a results file (benchmarks/results/NAME.json)",
    )


def save_run(path: str | None, benchmark: str, title: str, figure: str, doc: dict, table: dict | None = None) -> None:
    """Append ``doc`` (the script's printed JSON) as a record of ``path``; nothing when ``path`` is None."""
    if path:
        record = new_record(f"{benchmark}-{stamp()}", title, figure, table=table, data=doc)
        append_record(path, benchmark, "benchmarks/" + Path(sys.argv[0]).name, record)
