"""The independent frozen check of a controller file on true robots drawn from a stated set, as JSON.

    python benchmarks/independent_check.py CONTROLLER.json [-n 2000] [--points 1] [--seed 0] [--extremes 0.5]
        [--robot-uncertainty FILE | --link-error 10 --payload-max 1.5 --com-radius 0.1]

For each of ``n`` true robots (each link's mass, first moment and inertia by
its own factor; a payload body whose centre of mass lies anywhere within the
radius of the flange; the inner layer computing with the nominal links and
the middle payload; the share ``--extremes`` of them at vertices of the set,
at random corners of the task) and ``--points`` random points of the controller's task
domain: the frozen inner+outer loop's Jacobians from Pinocchio's derivative
routines (not polyrob's bounds or plant code), the closed loop with the
controller, its largest pole, and the weighted norm ``||N_zw||inf`` with the
weights of the controller's problem, against the certificate's bound
(:mod:`polyrob.validate.independent`).  Prints: the unstable count, the worst
pole, the median and worst weighted norm, the bound.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from _results import add_results_option, save_run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controller", help="a controller file as `polyrob synth -o` writes it")
    ap.add_argument("-n", type=int, default=2000, help="true robots drawn (default 2000)")
    ap.add_argument("--points", type=int, default=1, help="random task points per robot")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--extremes",
        type=float,
        default=None,
        help="share of the robots drawn at vertices of the set, at corners of the task (default polyrob's 0.5)",
    )
    ap.add_argument("--robot-uncertainty", default=None, help="a robot-uncertainty file (YAML/JSON)")
    ap.add_argument("--link-error", type=float, default=10.0, help="per-link error in percent (default 10)")
    ap.add_argument("--payload-max", type=float, default=1.5, help="payload up to this many kg (capped at the rated)")
    ap.add_argument("--com-radius", type=float, default=0.1, help="payload centre of mass within this radius (m)")
    ap.add_argument(
        "--common-factor",
        type=float,
        default=None,
        help="draw from the set today's certificates cover instead: one factor on every link within ±P %%",
    )
    ap.add_argument(
        "--paper-block",
        action="store_true",
        help="a controller made with limit weights: the norm of its W_S/W_T sub-block only (a lower bound)",
    )
    add_results_option(ap)
    args = ap.parse_args()

    from polyrob.io.controller import read_controller_file
    from polyrob.model.robots import load_robot
    from polyrob.uncertainty_set.spec import RATED_PAYLOAD, PayloadBody, RobotUncertainty
    from polyrob.validate.independent import frozen_check

    if args.robot_uncertainty:
        spec = RobotUncertainty.from_file(args.robot_uncertainty)
    else:
        name = (read_controller_file(args.controller).get("info") or {}).get("robot", "")
        rated = RATED_PAYLOAD.get(load_robot(name).name)
        top = min(args.payload_max, rated.kg) if rated is not None and rated.kg else args.payload_max
        payload = PayloadBody(0.0, top, com_radius=args.com_radius) if top > 0 else None
        spec = RobotUncertainty(link_error=args.link_error / 100.0, payload=payload, source="benchmark options")
    t0 = time.perf_counter()
    step = [0]

    def progress(done, total):
        if done * 10 // total > step[0] or done == total:
            step[0] = done * 10 // total
            print(f"independent check: {done} of {total} loops", file=sys.stderr, flush=True)

    factor = None if args.common_factor is None else args.common_factor / 100.0
    check = frozen_check(
        args.controller,
        spec,
        n=args.n,
        points=args.points,
        seed=args.seed,
        common_factor=factor,
        on_loop=progress,
        paper_block=args.paper_block,
        **({} if args.extremes is None else {"extremes": args.extremes}),
    )
    out = check.summary()
    out["seconds"] = round(time.perf_counter() - t0, 1)
    figure = (
        f"{out['robot']}: {out['unstable']} of {out['loops']} frozen loops unstable (worst pole "
        f"{out['worst_pole_real']:.3g}), weighted norm median {out['weighted_norm_median']} / worst "
        f"{out['weighted_norm_worst']}, certified bound {out['bound']}"
    )
    save_run(args.results, "independent_check", "Independent frozen check on drawn true robots", figure, out)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
