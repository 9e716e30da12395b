"""The μ certificate of a controller, with its check between the grid points.

Runs the certificate of the syntheses (:func:`polyrob.analysis.certificate.certify_loop`:
a peak-refined sweep, then :func:`polyrob.analysis.mu.between.with_between`)
and prints, as JSON, the grid peak, the level verified at every frequency
(or why none), the points added and the times.  Usage (docs/mu.md)::

    python benchmarks/mu_between.py paper_2r K.json --domain paper --uncertainty lft --bandwidth-scale 4
    python benchmarks/mu_between.py --batch-dir out/planar_2r    # a `polyrob batch -o out` robot folder
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

from _results import add_results_option, save_run


def between_figure(out: dict) -> str:
    """One line of the JSON: the grid peak and the level verified at every frequency (or why none)."""
    head = f"{out['robot']}: grid peak {out['grid_peak_mu_upper']:.4g}"
    if out["verified_every_frequency"]:
        return f"{head}; mu <= {out['level']:.4g} at every frequency, {out['points_added']} points added"
    return f"{head}; not verified between the points: {out['reason']}"


def main(argv=None) -> int:
    import polyrob
    from polyrob.analysis.certificate import certify_loop
    from polyrob.io.controller import load_controller
    from polyrob.pipeline.problem import build_problem, default_hyperparameters

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("robot", nargs="?")
    p.add_argument("controller", nargs="?")
    p.add_argument("--domain", default=None)
    p.add_argument("--uncertainty", default="auto")
    p.add_argument("--bandwidth-scale", type=float, default=1.0)
    p.add_argument("--batch-dir", default=None, help="a robot folder of `polyrob batch -o`: its problem and controller")
    add_results_option(p)
    args = p.parse_args(argv)
    if args.batch_dir:
        with open(os.path.join(args.batch_dir, "certificate.json")) as fh:
            doc = json.load(fh)["problem"]
        robot = polyrob.load_robot(doc["robot"])
        weights, model = doc["weights"], doc["uncertainty"]["model"]
        domain = polyrob.Domain.from_robot(robot)
        path = os.path.join(args.batch_dir, "controller.json")
    else:
        if not (args.robot and args.controller):
            p.error("give ROBOT CONTROLLER or --batch-dir")
        robot = polyrob.load_robot(args.robot)
        domain = polyrob.Domain.from_robot(robot, args.domain) if args.domain else polyrob.Domain.from_robot(robot)
        weights = default_hyperparameters(robot.m, bandwidth_scale=args.bandwidth_scale)
        model, path = args.uncertainty, args.controller
    t0 = time.perf_counter()
    problem = build_problem(robot, domain, hyperparameters=weights, uncertainty=model, progress=False)
    t_bounds = time.perf_counter() - t0
    K = load_controller(path)
    t0 = time.perf_counter()
    c = certify_loop(problem.P, K, problem.P.block_structure_rp)
    peak, lower, N, cert = c.mu_upper_grid, c.mu_lower, c.closed_loop, c.mu
    between = cert.between
    out = {
        "machine": {"platform": platform.platform(), "cores": len(os.sched_getaffinity(0))},
        "robot": robot.name,
        "model": problem.model,
        "controller": path,
        "closed_loop_states": int(N.nstates),
        "grid_points": int(cert.omega.size),
        "grid_peak_mu_upper": peak,
        "grid_peak_mu_lower": lower,
        "verified_every_frequency": bool(between.holds),
        "level": between.level if between.holds else None,
        "points_added": between.points_added,
        "reason": between.reason,
        "between_seconds": between.seconds,
        "certificate_seconds": round(time.perf_counter() - t0, 1),
        "bounds_seconds": round(t_bounds, 1),
    }
    out = json.loads(json.dumps(out, default=float))
    save_run(args.results, "mu_between", "The check between the grid points", between_figure(out), out)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
