"""The report's "Provenance" section and footer: what made the report and the controller it shows.

One column per :class:`~polyrob.provenance.Provenance` (the report's own,
then the controller file's when it records one): polyrob's version, the
command, the date, the machine, the libraries, the robot's URDF/SRDF and
the problem inputs' SHA-256; the page ends with the first column's
:meth:`~polyrob.provenance.Provenance.footer` line.
"""

from __future__ import annotations

import html

__all__ = ["add_provenance", "provenance_rows"]


def _versions(mapping: dict) -> str:
    return ", ".join(f"{name} {version}" for name, version in mapping.items()) or "not recorded"


def _file(path, digest, absent: str) -> str:
    return f"{digest} ({path})" if digest else absent


def provenance_rows(columns: dict) -> list[tuple]:
    """``(what, value per column)`` rows of the provenance table; ``columns``: ``{title: Provenance}``."""
    fields = (
        ("polyrob", lambda p: p.polyrob_version + (f" ({p.source_commit})" if p.source_commit else "")),
        ("command", lambda p: p.command),
        ("date (UTC)", lambda p: p.created_utc),
        ("platform", lambda p: f"{p.platform} ({p.machine}), Python {p.python}"),
        ("libraries", lambda p: _versions(p.dependencies)),
        ("solvers (cvxpy)", lambda p: _versions(p.solvers)),
        ("robot", lambda p: p.robot or "not recorded"),
        ("URDF sha256", lambda p: _file(p.urdf, p.urdf_sha256, "no URDF file (an analytic model)")),
        ("SRDF sha256", lambda p: _file(p.srdf, p.srdf_sha256, "no SRDF file")),
        ("problem inputs sha256", lambda p: p.inputs_sha256 or "not recorded"),
        (
            "input files sha256",
            lambda p: (
                "; ".join(f"{k} {v.get('path')}: {v.get('sha256')}" for k, v in p.input_files.items())
                or "no file given (the problem from options)"
            ),
        ),
    )
    return [(name, *(value(p) for p in columns.values())) for name, value in fields]


def add_provenance(page, columns: dict) -> None:
    """Add the "Provenance" section and the footer line to a :class:`~polyrob.report.page.Page`."""
    if not columns:
        return
    page.heading("Provenance")
    titles = list(columns)
    page.table(
        ["", *titles],
        provenance_rows(columns),
        ident="provenance",
        left=tuple(range(len(titles) + 1)),
        classes={i + 1: "text" for i in range(len(titles))},
    )
    line = next(iter(columns.values())).footer()
    page.h.append(f"<footer><p id='footer'>{html.escape(line)}</p></footer>")
    page.md += ["---", "", line, ""]
