"""The frozen robot over task cells for a saved controller, as JSON: each cell's certificate and the union's verdict.

    python benchmarks/frozen_cells.py CONTROLLER.json [--robot-uncertainty FILE|default] [--link-error 10]
        [--payload-max 0] [--com-radius 0.1] [--max-cells 8] [--screen-at 130.6] [--coverage-points 200]
        [--cells-dir DIR]

For the controller file's robot, task and weights (as ``polyrob synth -o``
writes them) and the set the options state, this bounds the task as
``polyrob analyze`` does, then runs
:func:`polyrob.analysis.frozen_cells.frozen_cells_certificate` (what
``polyrob analyze --frozen-cells N`` runs when the whole task's model does
not certify the controller), screening the cells at ``--screen-at`` (rad/s;
``polyrob analyze`` screens at the whole task's μ peak).  Prints two lines
per cell visited (its progress; its box and outcome) and one JSON document: the union's verdict
and covers line, and per cell kept its positions' box, coverage, status, μ
bounds and seconds.  ``--cells-dir`` keeps each finished cell's
certificate there, so a run stopped goes on where it stopped (as
``polyrob analyze --cells-dir``).  A run stopped with Ctrl-C (or SIGTERM)
before its verdict prints, and with ``--results`` saves, the cells it
visited as they were (each screened cell's bound, each decided cell's
certificate), marked ``"stopped": true`` and with no verdict: a cell
limit in hours can still leave a measured record.
"""

from __future__ import annotations

import argparse
import json
import signal
import time

from _results import add_results_option, save_run
from _sets import add_set_options, controller_file_problem


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controller", help="a controller file as `polyrob synth -o` writes it (a per-link set's problem)")
    add_set_options(ap, payload_max=0.0)
    ap.add_argument("--max-cells", type=int, default=8, help="cells at most (default 8)")
    ap.add_argument("--screen-at", default="", help="frequencies (rad/s, comma-separated) the cells are screened at")
    ap.add_argument("--coverage-points", type=int, default=200, help="fresh (robot, point) pairs per cell")
    ap.add_argument("--cells-dir", default=None, help="where each finished cell's certificate is kept (default: none)")
    add_results_option(ap)
    args = ap.parse_args()

    from polyrob.analysis.frozen_cells import frozen_cells_certificate

    t0 = time.perf_counter()
    robot, loop, problem, K = controller_file_problem(args, args.controller)
    screen = [float(w) for w in args.screen_at.split(",") if w.strip()]

    def progress(done, total):
        print(
            json.dumps({"visited": done, "at_most": total, "seconds": round(time.perf_counter() - t0, 1)}), flush=True
        )

    visited = []

    def on_cell(record):
        visited.append(record)
        print(json.dumps(record), flush=True)

    head = {
        "controller": args.controller,
        "robot": robot.name,
        "set": loop.uncertainty.words(),
        "screen_at": screen,
    }
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # `kill` stops it as Ctrl-C does: what it visited is kept
    try:
        result = frozen_cells_certificate(
            problem,
            K,
            max_cells=args.max_cells,
            coverage_points=args.coverage_points,
            screen_at=screen,
            progress=progress,
            on_cell=on_cell,
            cells_dir=args.cells_dir,
        )
    except KeyboardInterrupt:
        _save_stopped(args, head, visited, time.perf_counter() - t0)
        raise SystemExit(130) from None
    out = {
        **head,
        "verdict": result.verdict,
        "covers": result.certificate.scope.sentence(),
        "cells": result.words(),
        "result": result.summary(),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(out, indent=1))
    table = {
        "columns": [
            "cell (positions, rad)",
            "coverage",
            "status",
            "μ upper (every frequency)",
            "μ grid [lower, upper]",
            "s",
        ],
        "rows": [
            [
                ", ".join(f"[{lo:.3f}, {hi:.3f}]" for lo, hi in zip(c["q_lower"], c["q_upper"])),
                f"{c['coverage']:.4g}",
                c["status"],
                "-" if c["mu_upper"] is None else f"{c['mu_upper']:.4f}",
                f"[{c['mu_lower']:.4f}, {c['mu_upper_grid']:.4f}]",
                f"{c['seconds']:.0f}",
            ]
            for c in out["result"]["cells"]
        ],
    }
    save_run(
        args.results, "frozen_cells", f"{robot.name}: the frozen robot over task cells", result.verdict, out, table
    )


def _save_stopped(args, head: dict, visited: list, seconds: float) -> None:
    """Print and save (``--results``) the cells a stopped run visited: no verdict, each cell as it was left."""
    out = {**head, "stopped": True, "visited": visited, "seconds": round(seconds, 1)}
    print(json.dumps(out, indent=1))

    def outcome(c):
        if "screen_mu_upper" in c:
            return (
                "screened out",
                f"{c['screen_mu_upper']:.4f} at {', '.join(f'{w:g}' for w in c['screened_out_at'])} rad/s",
            )
        upper = "-" if c["mu_upper"] is None else f"{c['mu_upper']:.4f}"
        return c["status"], f"{upper} (grid [{c['mu_lower']:.4f}, {c['mu_upper_grid']:.4f}])"

    table = {
        "columns": [
            "cell (positions, rad)",
            "outcome",
            "μ upper (screened out: at those frequencies only; decided: every frequency)",
        ],
        "rows": [
            [", ".join(f"[{lo:.3f}, {hi:.3f}]" for lo, hi in zip(c["q_lower"], c["q_upper"])), *outcome(c)]
            for c in visited
        ],
    }
    figure = f"stopped after {len(visited)} cells, before a verdict"
    save_run(
        args.results, "frozen_cells", f"{head['robot']}: the frozen robot over task cells (stopped)", figure, out, table
    )


if __name__ == "__main__":
    main()
