"""The moving robot of a per-link set on three cuts of the ``inner-links-moving`` model, for one controller, as JSON.

    python benchmarks/moving_links_models.py CONTROLLER.json [--link-error 10] [--payload-max 0]
        [--com-radius 0.1] [--robot-uncertainty FILE] [--points 45] [--coverage 200]

The model (:mod:`polyrob.plant.moving_links`) splits each true robot's
computed-torque factor at the task's centre into constants and the motion.
For the controller file's robot, task and weights (as ``polyrob synth -o``
writes them) this builds the model three ways:

* ``directions, entry boxes``: the ``inner-links`` principal directions at
  the centre, the motion blocks as the entry box's Frobenius covering (the
  model before commit caaa1d3);
* ``directions, balls``: the motion blocks' balls shrunk to the motion's
  norm bound over the set at each sample;
* ``exact, balls``: the set's link and joint scalars themselves at the
  centre, the instrument's part there in the constant blocks (the model
  before the instrument's exact LFT);
* ``exact, instrument exact``: the same with the instrument's part at the
  centre the exact LFT in its mass and centre of mass
  (:mod:`polyrob.plant.payload_lft`: the model as it is).  On a set without
  an instrument it is the row above.

For each it prints the μ upper bound's peak on ``--points`` log-spaced
frequencies from 0.01 to 3162 rad/s, with the motion blocks merged with the
performance channels by constant scalings searched as the moving-robot
certificate does (:func:`~polyrob.analysis.lpv.constant.search_scalings`):
the moving robot's figure; and with every block a block of its own: the
frozen robot's figure on that model.  Both are grid figures, not
certificates (``polyrob analyze ... --moving`` proves one between its
points).  ``--coverage N``: each model's :func:`~polyrob.plant.moving_links.motion_coverage`
on N (true robot, point) pairs drawn anew.
"""

from __future__ import annotations

import argparse
import json
import time

from _results import add_results_option, save_run
from _sets import add_set_options, controller_problem

VARIANTS = (
    ("directions, entry boxes", False, False, False),
    ("directions, balls", False, True, False),
    ("exact, balls", True, True, False),
    ("exact, instrument exact", True, True, True),
)


def peaks(P, K, omega):
    """``(merged, frozen, d)``: the μ upper bound's peaks and frequencies, merged and with every block its own."""
    import numpy as np

    from polyrob.analysis.lpv.constant import residual_scalings, scaled_plant, search_scalings
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.plant.loops import lft

    m = P.n_u

    def sweep(system, blk):
        N = lft(system, K, n_u=m, n_y=m)
        H = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(omega)
        mu = np.array([mussv(H[k], blk, lower=False).upper for k in range(len(omega))])
        return {"peak": float(mu.max()), "at_rad_s": float(omega[mu.argmax()])}

    frozen = sweep(P.system, P.block_structure_rp)
    d = search_scalings(P, K, residual_scalings(P, K)[0])
    return sweep(*scaled_plant(P, d)), frozen, [float(x) for x in d]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controller", help="a controller file as `polyrob synth -o` writes it (an inner-links problem)")
    add_set_options(ap, payload_max=0.0)
    ap.add_argument("--points", type=int, default=45, help="frequencies of the grid (default 45)")
    ap.add_argument("--coverage", type=int, default=200, help="(true robot, point) pairs per coverage (0: none)")
    ap.add_argument("--models", default=None, help="only these models, by their names, separated by semicolons")
    add_results_option(ap)
    args = ap.parse_args()

    import numpy as np

    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.moving_links import motion_coverage, moving_links_plant

    t0 = time.perf_counter()
    robot, loop, domain, weights, K, pldi = controller_problem(args, args.controller)
    omega = np.logspace(-2, 3.5, args.points)
    rows = []
    chosen = None if args.models is None else {name.strip() for name in args.models.split(";")}
    for name, exact, balls, payload in VARIANTS:
        if chosen is not None and name not in chosen:
            continue
        t1 = time.perf_counter()
        unc = moving_links_plant(pldi, loop, exact=exact, motion_balls=balls, exact_payload=payload)
        merged, frozen, d = peaks(generalized_plant(unc, **weights), K, omega)
        cover = motion_coverage(unc, loop, domain, args.coverage) if args.coverage else None
        rows.append({"model": name, "parameters": int(unc.n_params), "moving": merged, "frozen": frozen,
                     "scalings": d, "motion_ball": list(unc.info["motion_ball"]), "coverage": cover,
                     "seconds": round(time.perf_counter() - t1, 1)})  # fmt: skip
    out = {
        "controller": args.controller,
        "robot": robot.name,
        "set": loop.uncertainty.words(),
        "grid": f"{args.points} log-spaced frequencies, 0.01 to 3162 rad/s (grid figures, not certificates)",
        "models": rows,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(out, indent=1))
    table = {
        "columns": ["model", "moving robot (merged)", "frozen robot", "coverage"],
        "rows": [[r["model"], f"{r['moving']['peak']:.4g}", f"{r['frozen']['peak']:.4g}", r["coverage"]] for r in rows],
    }
    figure = ", ".join(f"{r['model']}: {r['moving']['peak']:.4g} / {r['frozen']['peak']:.4g}" for r in rows)
    save_run(args.results, "moving_links_models", f"{robot.name}: the moving-links model's cuts", figure, out, table)


if __name__ == "__main__":
    main()
