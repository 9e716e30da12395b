"""Where a per-link set's frozen μ comes from: the model exact at the task's centre, its D-G gap, and the task's motion, as JSON.

    python benchmarks/exact_centre.py CONTROLLER.json [--robot-uncertainty FILE|default] [--link-error 10]
        [--payload-max 0] [--com-radius 0.1] [--instrument exact|blocks] [--points 16] [--max-cells 64]

For the controller file's robot, task and weights (as ``polyrob synth -o``
writes them) this builds the ``inner-links-moving`` model
(:mod:`polyrob.plant.moving_links`: the link scalars exact at the task's
centre, the instrument's part its exact LFT with ``--instrument exact``,
the motion over the task in two full blocks) and, on ``--points``
log-spaced frequencies from 0.1 to 3162 rad/s, prints μ's bounds
(descent's D-G upper bound and the power iteration's lower bound) of the
robust-performance loop

* ``centre``: with the motion blocks closed at zero
  (:func:`~polyrob.analysis.lpv.constant.without_motion`): every frozen
  robot of the set *at the task's centre*, exact in its parameters;
* ``partition``: where the centre's D-G bound is not below 1 and its lower
  bound is, :func:`~polyrob.analysis.mu.partition.partition_mu` at level 1
  (the real scalars' box split into cells until every cell's D-G bound is
  below 1, or a member is found, or ``--max-cells`` are spent);
* ``task``: with the motion blocks as constant blocks of their own: every
  frozen robot over the task (the model's frozen figure).

Grid figures at one pose and on a frequency grid, not certificates: they
say how much of μ is the D-G bound's gap on the exact scalars, and how
much the task's motion adds.
"""

from __future__ import annotations

import argparse
import json
import time

from _results import add_results_option, save_run
from _sets import add_set_options, controller_problem


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controller", help="a controller file as `polyrob synth -o` writes it (an inner-links problem)")
    add_set_options(ap, payload_max=0.0)
    ap.add_argument("--instrument", choices=("exact", "blocks"), default="exact",
                    help="the instrument's part at the centre: its exact LFT (default) or the constant blocks")  # fmt: skip
    ap.add_argument("--points", type=int, default=16, help="frequencies of the grid (default 16)")
    ap.add_argument("--max-cells", type=int, default=64, help="cells of each partition at most (default 64)")
    add_results_option(ap)
    args = ap.parse_args()

    import numpy as np

    from polyrob.analysis.lpv.constant import without_motion
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.analysis.mu.partition import partition_mu
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.loops import lft
    from polyrob.plant.moving_links import moving_links_plant

    t0 = time.perf_counter()
    robot, loop, domain, weights, K, pldi = controller_problem(args, args.controller)
    unc = moving_links_plant(pldi, loop, exact=True, exact_payload=args.instrument == "exact")
    P = generalized_plant(unc, **weights)
    N = lft(P.system, K, n_u=P.n_u, n_y=P.n_u)
    omega = np.logspace(-1, 3.5, args.points)
    H = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(omega)
    outs, ins, blk_centre = without_motion(P)
    st_centre = as_block_structure(blk_centre)
    rows = []
    for k, w in enumerate(omega):
        t1 = time.perf_counter()
        centre = mussv(H[k][np.ix_(outs, ins)], blk_centre, method="gradient")
        task = mussv(H[k], P.block_structure_rp, method="gradient")
        row = {"rad_s": float(w), "centre": [float(centre.lower), float(centre.upper)],
               "task": [float(task.lower), float(task.upper)]}  # fmt: skip
        if centre.upper >= 1.0 > centre.lower:
            part = partition_mu(st_centre.pad(H[k][np.ix_(outs, ins)]), st_centre, 1.0, max_cells=args.max_cells)
            row["partition"] = {"verdict": part.verdict, "cells": part.cells,
                                "proved_fraction": round(part.proved_fraction, 4), "splits": list(part.splits)}  # fmt: skip
        row["seconds"] = round(time.perf_counter() - t1, 1)
        print(json.dumps(row), flush=True)
        rows.append(row)
    reals = [b for b in st_centre.blocks if b.kind == "real"]
    out = {
        "controller": args.controller,
        "robot": robot.name,
        "set": loop.uncertainty.words(),
        "instrument": args.instrument,
        "real_scalars": len(reals),
        "real_channels": int(sum(b.size for b in reals)),
        "grid": f"{args.points} log-spaced frequencies, 0.1 to 3162 rad/s (grid figures at one pose, not certificates)",
        "rows": rows,
        "centre_peak": max(r["centre"][1] for r in rows),
        "task_peak": max(r["task"][1] for r in rows),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(out, indent=1))

    def verdict(r):
        p = r.get("partition")
        return "" if p is None else f"{p['verdict']} ({p['cells']} cells)"

    table = {
        "columns": ["rad/s", "centre: lower, D-G upper", "partition at 1", "task: lower, upper"],
        "rows": [
            [
                f"{r['rad_s']:.3g}",
                f"{r['centre'][0]:.3f}, {r['centre'][1]:.3f}",
                verdict(r),
                f"{r['task'][0]:.3f}, {r['task'][1]:.3f}",
            ]
            for r in rows
        ],  # fmt: skip
    }
    figure = f"centre's D-G peak {out['centre_peak']:.4g}, the task's {out['task_peak']:.4g}"
    save_run(args.results, "exact_centre", f"{robot.name}: the exact model at the task's centre", figure, out, table)


if __name__ == "__main__":
    main()
