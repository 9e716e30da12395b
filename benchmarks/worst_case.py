"""A controller's worst-case weighted gain over the whole per-link set, frozen and in motion, as JSON.

    python benchmarks/worst_case.py CONTROLLER.json [--robot-uncertainty FILE|default] [--link-error 10]
        [--payload-max 0] [--com-radius 0.1] [--which frozen,moving]

For the controller file's robot, task and weights (as ``polyrob synth -o``
writes them) this builds

* ``frozen``: the set's ``inner-links`` model (every frozen robot of the
  set) and bounds the worst-case gain of the robust-performance loop over
  the whole set (:func:`polyrob.analysis.worst_case.wcgain`: a member's
  gain below, an upper bound proved at every frequency above);
* ``moving``: the set's ``inner-links-moving`` model with its moving blocks
  scaled by constants ``d`` and merged with the performance channels
  (:func:`polyrob.analysis.lpv.constant.scaled_plant`: the set's constants
  fixed, the state moving at any rate), and bounds the gain on that
  structure (:func:`~polyrob.analysis.lpv.constant.moving_worst_case`, from
  the constant-D small gain's ``d``, then ``d`` searched for the level
  reached or for stability alone; an upper bound only: the structure is a
  sufficient test).

The figures answer what robust performance's VIOLATED leaves open on a set
no model certifies: is every member stable, and by how much does the worst
miss the weights?  Both models' enclosures over the task are sampled (the
``inner-links`` samples), over the parameters exact.
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
    ap.add_argument("--which", default="frozen,moving", help="frozen, moving or both (default frozen,moving)")
    ap.add_argument("--points", type=int, default=0,
                    help="a grid of this many log-spaced frequencies from 1e-3 to 1e6 rad/s (default: the loop's own; "
                    "the certificate checks between the points either way)")  # fmt: skip
    add_results_option(ap)
    args = ap.parse_args()

    import numpy as np

    from polyrob.analysis.lpv.constant import moving_worst_case, residual_scalings
    from polyrob.analysis.worst_case import wcgain
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.models.inner_links import inner_links_plant
    from polyrob.plant.moving_links import moving_links_plant

    omega = np.logspace(-3, 6, args.points) if args.points > 0 else None
    t0 = time.perf_counter()
    robot, loop, domain, weights, K, pldi = controller_problem(args, args.controller)
    out = {"controller": args.controller, "robot": robot.name, "set": loop.uncertainty.words(), "rows": []}
    which = {w.strip() for w in args.which.split(",")}
    if "frozen" in which:
        t1 = time.perf_counter()
        P = generalized_plant(inner_links_plant(pldi, loop), **weights)
        g = wcgain(P, K, omega=omega)
        row = {"loop": "frozen (inner-links)", **g.summary(), "seconds": round(time.perf_counter() - t1, 1)}
        row.pop("certificate")
        print(json.dumps(row), flush=True)
        out["rows"].append(row)
    if "moving" in which:
        t1 = time.perf_counter()
        P = generalized_plant(moving_links_plant(pldi, loop, exact=True), **weights)
        d0, source = residual_scalings(P, K)
        g, d = moving_worst_case(P, K, d0, omega=omega)
        row = {"loop": "moving (inner-links-moving, merged)", **g.summary(), "scalings": [float(x) for x in d],
               "scalings_from": f"{source}, then moving_worst_case's search", "seconds": round(time.perf_counter() - t1, 1)}  # fmt: skip
        row.pop("certificate")
        print(json.dumps(row), flush=True)
        out["rows"].append(row)
    out["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out, indent=1))

    def upper(r):
        return f"{r['upper']:.3g}" if r["proved"] else f"none ({r['reason']})"

    table = {
        "columns": ["loop", "lower (a member)", "upper (every frequency)", "at rad/s", "s"],
        "rows": [
            [
                r["loop"],
                "-" if r["loop"].startswith("moving") else str(r["lower"]),
                upper(r),
                f"{r['critical_frequency']:.3g}",
                f"{r['seconds']:.0f}",
            ]
            for r in out["rows"]
        ],
    }
    figure = "; ".join(f"{r['loop']}: {upper(r)}" for r in out["rows"])
    save_run(args.results, "worst_case", f"{robot.name}: the worst-case gain over the whole set", figure, out, table)


if __name__ == "__main__":
    main()
