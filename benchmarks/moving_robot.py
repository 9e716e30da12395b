"""Moving-robot certificate on ``paper_2r --domain paper``: the three certificates of a controller per bandwidth factor.

For each run ``FACTOR:CONTROLLER`` (a controller file, or ``paper`` for the
paper's K*), the weights at ``--bandwidth-scale FACTOR``:

* ``moving``: :func:`polyrob.analysis.lpv.moving.moving_robot_certificate`
  (the linearised robot scheduled on ``(q2, qdot1, qdot2)``, ``dq2/dt =
  qdot2`` at every grid point, the velocities bounded by the domain's
  accelerations or, for large loops, arbitrary: docs/certificates.md), its
  proved gamma, status, frozen peak and seconds;
* with ``--full``: also the frozen-robot μ and the arbitrarily fast verdict
  of :func:`polyrob.pipeline.analyze_controller` (the PLDI bounded on the
  paper's domain, ``lft`` model) -- minutes more per run.

Prints one JSON document (with the machine, the date and the load average).

    python benchmarks/moving_robot.py [--runs 4:tests/fixtures/paper_2r_tf3_alpha4_K.json,1:paper]
                                      [--velocities auto|bounded|arbitrary] [--points 5,3] [--full]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
from types import SimpleNamespace


def _controller(spec: str):
    if spec == "paper":
        from polyrob.plant.generalized import paper_controller

        return paper_controller()
    from polyrob.io.controller import load_controller

    return load_controller(spec)


def _light_problem(robot, domain, factor: float):
    """What the moving certificate reads of a problem (robot, domain, weights), without bounding a PLDI."""
    from polyrob.pipeline.problem import default_hyperparameters
    from polyrob.plant.weights import paper_weights

    W_S, W_T = paper_weights(default_hyperparameters(robot.m, bandwidth_scale=factor))
    return SimpleNamespace(robot=robot, domain=domain, P=SimpleNamespace(W_S=W_S, W_T=W_T, W_KS=None))


def run(factor: float, spec: str, *, velocities: str, points, full: bool) -> dict:
    from polyrob import load_robot
    from polyrob.analysis.lpv.moving import moving_robot_certificate
    from polyrob.domains.torque_box import Domain

    robot = load_robot("paper_2r")
    domain = Domain.from_robot(robot, "paper")
    K = _controller(spec)
    out = {"bandwidth_factor": factor, "controller": spec}
    t = time.perf_counter()
    mv = moving_robot_certificate(_light_problem(robot, domain, factor), K, velocities=velocities, points=points)
    s = mv.summary()
    out["moving"] = {
        "verdict": mv.verdict,
        "status": s["status"],
        "gamma": s["gamma"],
        "frozen_gamma": s["frozen_gamma"],
        "grid": s["grid"],
        "rates": s["rate_words"],
        "solver_status": None if mv.result is None else mv.result.solver_status,
        "n_states": None if mv.result is None else mv.result.n_states,
        "seconds": round(time.perf_counter() - t, 1),
    }
    if full:
        from polyrob.pipeline import analyze_controller, build_problem
        from polyrob.pipeline.problem import default_hyperparameters

        t = time.perf_counter()
        h = default_hyperparameters(robot.m, bandwidth_scale=factor)
        problem = build_problem(robot, domain, hyperparameters=h, uncertainty="lft", progress=False)
        a = analyze_controller(problem, K, mc=20, progress=False, time_varying=True, moving=False)
        out["frozen_mu"] = {"verdict": a.certificate.verdict, "bound": a.certificate.bound}
        tv = a.time_varying
        out["arbitrarily_fast"] = {"verdict": None if tv is None else tv.verdict}
        out["full_seconds"] = round(time.perf_counter() - t, 1)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", default="4:tests/fixtures/paper_2r_tf3_alpha4_K.json")
    ap.add_argument("--velocities", default="auto", choices=["auto", "bounded", "arbitrary"])
    ap.add_argument("--points", default="5,3", help="grid points per position and per velocity parameter")
    ap.add_argument("--full", action="store_true", help="also the frozen-robot mu and the arbitrarily fast verdict")
    args = ap.parse_args(argv)
    points = tuple(int(x) for x in args.points.split(","))
    doc = {
        "problem": "paper_2r --domain paper",
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "load_average_start": list(os.getloadavg()),
        "runs": [],
    }
    for item in args.runs.split(","):
        factor, spec = item.split(":", 1)
        doc["runs"].append(run(float(factor), spec, velocities=args.velocities, points=points, full=args.full))
    doc["load_average_end"] = list(os.getloadavg())
    print(json.dumps(doc, indent=2, allow_nan=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
