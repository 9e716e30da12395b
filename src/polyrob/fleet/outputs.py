"""The files of a batch: per robot a controller file and a JSON certificate, and the summary table.

Layout of ``out_dir``::

    summary.json            the batch (settings, executor, one row per robot)
    summary.md              the same rows as a Markdown table
    ROBOT/controller.json   the controller, its certificate and its problem
                            (:func:`polyrob.io.controller.save_controller`)
    ROBOT/certificate.json  the robot's row, certificate, problem and details
                            (synthesis, analysis, validation), or its error

Both robot files carry the provenance of :mod:`polyrob.provenance`.

Every file is written atomically (temporary file, then rename); the summary
is rewritten as each robot finishes, so an interrupted batch leaves a
summary of the robots done.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

__all__ = [
    "robot_dir_name",
    "write_robot",
    "write_summary",
    "markdown_table",
    "controller_words",
    "moving_words",
    "plain",
]

COLUMNS = (
    ("robot", "robot"),
    ("joints", "joints"),
    ("uncertainty", "uncertainty"),
    ("inner_layer", "inner layer"),
    ("parameters", "parameters"),
    ("mu_upper", "mu bound"),
    ("mu_upper_grid", "mu peak (grid)"),
    ("status", "status"),
    ("moving_status", "moving robot"),
    ("controller_words", "controller"),
    ("bandwidth", "bandwidth (rad/s)"),
    ("alpha", "bandwidth factor"),
    ("seconds", "time (s)"),
    ("validation", "validation"),
    ("at_rate", "validation at the rate"),
)


def plain(obj):
    """JSON-ready: non-finite floats become null, tuples lists, numpy values Python ones."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, (str, int, bool)) or obj is None:
        return obj
    if hasattr(obj, "tolist"):
        return plain(obj.tolist())
    return str(obj)


def robot_dir_name(name: str) -> str:
    """A file-system-safe folder name for a result name (``a/b c`` -> ``a_b_c``)."""
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", str(name)).strip("._") or "robot"


def _dump(path: Path, doc) -> None:
    from polyrob.io.atomic import atomic_write

    atomic_write(path, lambda f: f.write(json.dumps(plain(doc), indent=1, allow_nan=False) + "\n"))


def write_robot(out_dir, result) -> dict:
    """Write one robot's files; returns ``{"certificate": path, "controller": path or None}``."""
    folder = Path(out_dir) / robot_dir_name(result.name)
    paths = {"certificate": str(folder / "certificate.json"), "controller": None}
    from polyrob.provenance import Provenance, robot_urdf

    made = Provenance.capture(
        urdf=robot_urdf((result.problem or {}).get("job", {}).get("robot") or result.robot),
        description=result.problem,
        function="polyrob.fleet.outputs.write_robot",
    )
    if result.ok and result.controller is not None:
        from polyrob.io.controller import save_controller

        paths["controller"] = str(
            save_controller(
                result.controller_system(),
                folder / "controller.json",
                certificate=plain(result.certificate),
                info=plain(result.problem),
                provenance=made,
            )
        )
    doc = {
        "row": result.row(),
        "certificate": result.certificate,
        "problem": result.problem,
        "details": result.details,
        "files": paths,
        "provenance": made.to_dict(),
    }
    _dump(folder / "certificate.json", doc)
    return paths


def _status(row: dict) -> str:
    if not row["ok"]:
        return f"FAILED: {row['error']}: {row['message']}"
    return str(row.get("status") or "-")


def moving_words(moving: dict | None) -> str | None:
    """The moving-robot cell: its status and figure, why it was not computed, or nothing (not asked).

    The figure is a bound (``<=``) only when the certificate holds; otherwise
    ``gamma`` is what its test reached on its grid (the μ route's grid peak
    of a sufficient test, or the L2 gain's level at the grid's points), no
    bound of the moving robot's gain, and the cell says so.
    """
    if not moving:
        return None
    if not moving.get("computed"):
        return "not computed"
    gamma, status = moving.get("gamma"), f"{moving.get('status')}"
    if gamma is None:
        return status
    return f"{status} (<= {gamma:.4g})" if moving.get("certified") else f"{status} ({gamma:.4g} on its grid)"


def controller_words(row: dict) -> str | None:
    """The controller in a few words: ``"per-joint PID"`` or its structure and order (``None``: no controller)."""
    if row.get("order") is None:
        return None
    if row.get("structure") == "pid":
        return "per-joint PID"
    return f"{row.get('structure') or 'state space'}, order {row['order']}"


def _cell(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def markdown_table(rows) -> str:
    """The summary rows as a Markdown table (one line per robot)."""
    lines = ["| " + " | ".join(title for _, title in COLUMNS) + " |", "|" + "|".join("---" for _ in COLUMNS) + "|"]
    for row in rows:
        at_rate = row.get("validation_at_rate") or {}
        moving = row.get("moving") or {}
        row = dict(
            row,
            status=_status(row),
            at_rate=at_rate.get("verdict"),
            moving_status=moving_words(moving),
            controller_words=controller_words(row),
        )
        lines.append("| " + " | ".join(_cell(row.get(key)) for key, _ in COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def write_summary(out_dir, doc: dict) -> dict:
    """``summary.json`` (the whole ``doc``) and ``summary.md`` (its rows); returns their paths."""
    from polyrob.io.atomic import atomic_write

    out = Path(out_dir)
    _dump(out / "summary.json", doc)
    head = (
        f"# polyrob batch\n\n{doc.get('done', 0)} of {doc.get('total', 0)} robot(s) done on "
        f"{doc.get('executor', '')}; {doc.get('certified', 0)} certified, {doc.get('failed', 0)} failed; "
        f"{doc.get('seconds', 0):.1f} s.\n\n"
    )
    text = head + markdown_table(doc.get("rows", []))
    atomic_write(out / "summary.md", lambda f: f.write(text))
    return {"json": str(out / "summary.json"), "markdown": str(out / "summary.md")}
