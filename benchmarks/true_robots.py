"""How much of μ is the model's: controllers on true robots drawn from a per-link set, and μ on its two models (JSON).

    python benchmarks/true_robots.py CONTROLLER.json [CONTROLLER.json ...] [--robot-uncertainty FILE]
        [--omega 0.3:100:12] [--draws 500] [--results PATH]

For each controller file (``polyrob synth ROBOT --robot-uncertainty FILE -o K.json``,
with or without ``--init true-robots``), on its robot's default task and the
set of ``FILE`` (default ``examples/uncertainty/ROBOT.yaml``):

* the worst weighted gain of its frozen loops on ``--draws`` true robots drawn
  from the set (:func:`polyrob.synthesis.true_robots.true_robot_check`: a
  sampled lower bound of the set's worst case), all inside the set at random
  task points, and as the check draws them (half at the set's vertices and
  the task's corners);
* robust stability and robust performance μ (upper [lower] bound, the peak on
  the ``--omega`` grid only: a search figure, not a certificate) on the
  ``inner-links`` model (the state columns' residual a complex block, what
  ``auto`` takes) and on ``inner-links-real`` (one real scalar per entry).

A lower bound of μ above the true robots' worst case is a member of the model
that no true robot is: the model's share of μ.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from _results import ROOT, add_results_option, save_run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controllers", nargs="+", help="controller files as `polyrob synth -o` writes them")
    ap.add_argument("--robot-uncertainty", default=None, help="default examples/uncertainty/ROBOT.yaml")
    ap.add_argument("--omega", default="0.3:100:12", help="mu grid LO:HI:N rad/s, log spaced (default 0.3:100:12)")
    ap.add_argument("--draws", type=int, default=500, help="true robots of the check (default 500)")
    add_results_option(ap)
    args = ap.parse_args()

    import numpy as np

    from polyrob.analysis.robust import robperf, robstab
    from polyrob.domains.default_task import default_task_domain
    from polyrob.io.controller import load_controller, read_controller_file
    from polyrob.model.inner import inner_loop_of_set
    from polyrob.model.robots import load_robot
    from polyrob.pipeline.problem import build_problem
    from polyrob.synthesis.true_robots import true_robot_check
    from polyrob.uncertainty_set.spec import RobotUncertainty

    lo, hi, n = args.omega.split(":")
    omega = np.logspace(np.log10(float(lo)), np.log10(float(hi)), int(n))
    rows, out, problems = [], [], {}
    for path in args.controllers:
        info = read_controller_file(path).get("info") or {}
        robot = load_robot(info["robot"])
        file = args.robot_uncertainty or ROOT / "examples" / "uncertainty" / f"{robot.name}.yaml"
        loop = inner_loop_of_set(robot, "computed-torque", RobotUncertainty.from_file(file))
        domain = default_task_domain(loop)
        weights = {k: tuple(v) for k, v in info["weights"].items()}
        K = load_controller(path)
        t0 = time.perf_counter()
        check = true_robot_check(loop, domain, K, weights, n=args.draws)
        inside = true_robot_check(loop, domain, K, weights, n=args.draws, extremes=0.0)
        entry = {"controller": path, "robot": robot.name, "set": loop.uncertainty.words(),
                 "true_robots": check.to_dict(), "true_robots_inside": inside.to_dict(),
                 "check_seconds": time.perf_counter() - t0}  # fmt: skip
        print(f"{path}: {check.words()}; all inside the set: worst {inside.worst:.3g}", file=sys.stderr, flush=True)
        for model in ("inner-links", "inner-links-real"):
            key = (robot.name, str(file), model, json.dumps(weights, sort_keys=True))
            if key not in problems:  # inner-links is what auto takes on a per-link set; one PLDI for both
                pldi = next((p.pldi for k, p in problems.items() if k[:2] == key[:2]), None)
                problems[key] = build_problem(
                    loop, None if pldi else domain, hyperparameters=weights, pldi=pldi, progress=False,
                    uncertainty="auto" if model == "inner-links" else model,
                )
                assert problems[key].model == model, problems[key].model
            P = problems[key].P
            t0 = time.perf_counter()
            rs = robstab(P, K, omega, refine_peak=False)
            rp = robperf(P, K, omega, refine_peak=False)
            entry[model] = {
                "state_residual_norm": problems[key].unc.info.get("state_residual_norm"),
                "rs": [rs.mu_upper_grid, rs.mu_lower],
                "rp": [rp.mu_upper_grid, rp.mu_lower],
                "rp_frequency": rp.critical_frequency,
                "seconds": time.perf_counter() - t0,
            }
            print(f"  {model}: RS mu {rs.mu_upper_grid:.3g} [{rs.mu_lower:.3g}], RP mu {rp.mu_upper_grid:.3g} "
                  f"[{rp.mu_lower:.3g}] ({entry[model]['seconds']:.0f} s)", file=sys.stderr, flush=True)  # fmt: skip
        out.append(entry)
        fmt = "{:.3g} [{:.3g}]".format
        rows.append([Path(path).name, robot.name, f"{inside.worst:.3g} ({inside.unstable} unstable)",
                     f"{check.worst:.3g} ({check.unstable} unstable)",
                     fmt(*entry["inner-links"]["rs"]), fmt(*entry["inner-links-real"]["rs"]),
                     fmt(*entry["inner-links"]["rp"]), fmt(*entry["inner-links-real"]["rp"])])  # fmt: skip
    doc = {"omega": omega.tolist(), "draws": args.draws, "controllers": out}
    print(json.dumps(doc, indent=1, default=float))
    table = {
        "columns": ["controller", "robot", f"true robots inside the set: worst of {args.draws}",
                    f"with half at vertices and task corners: worst of {args.draws}", "RS mu inner-links",
                    "RS mu inner-links-real", "RP mu inner-links", "RP mu inner-links-real"],
        "rows": rows,
    }  # fmt: skip
    figure = "; ".join(f"{r[0]}: true robots {r[2]} inside, {r[3]} with vertices, RP mu {r[6]} (block) / {r[7]} (real)"
                       for r in rows)  # fmt: skip
    save_run(args.results, "true_robots", "Controllers on true robots against mu on the per-link models", figure,
             doc, table)  # fmt: skip


if __name__ == "__main__":
    main()
