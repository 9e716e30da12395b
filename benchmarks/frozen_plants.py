"""How far a controller is from robust performance on the robot's own frozen plants.

For each controller file: the worst, over Jacobians of the robot sampled in its
domain (uniform points plus the corners of the velocity and torque box on a
grid of positions), of the sampled peak of ``σ_max([W_S S; W_T T](jω))``
(:func:`polyrob.synthesis.fixed.vertex.vertex_peak`).  Every frozen plant is a
member of any uncertainty model that covers the robot, and μ < 1 on a model
means that every member meets the performance: so when this figure is at
least 1, no covering model can certify the controller (μ ≥ 1 on all of
them), however tight it is.  ``--tune STRUCTURE`` then minimises that worst peak
over the same plants (:func:`polyrob.synthesis.fixed.vertex.vertex_synthesis`, a
multi-model fixed-structure synthesis, started from the controller) and
prints what it reached.

Prints one JSON document.  Usage (docs/uncertainty.md)::

    python benchmarks/frozen_plants.py paper_2r --domain paper K3.json K4.json --tune tf4
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import sys
import time

import numpy as np


def frozen_points(domain, n: int, grid: int, seed: int) -> np.ndarray:
    """``(q, qdot, u)`` rows: ``n`` uniform points, then box corners of ``(qdot, u)`` at ``grid`` positions."""
    lo = np.r_[domain.q_lower, domain.qdot_lower, domain.u_lower]
    hi = np.r_[domain.q_upper, domain.qdot_upper, domain.u_upper]
    m = len(domain.q_lower)
    rng = np.random.default_rng(seed)
    uniform = lo + (hi - lo) * rng.random((n, 3 * m))
    rest = [(a, b) for a, b in zip(lo[m:], hi[m:])]
    corners = np.array(list(itertools.product(*[(a, b) if b > a else (a,) for a, b in rest])))
    q = lo[:m] + (hi[:m] - lo[:m]) * rng.random((grid, m))
    edges = np.array([np.r_[qi, c] for qi in q for c in corners[rng.permutation(len(corners))[:64]]])
    return np.vstack([uniform, edges])


def main(argv=None) -> int:
    import polyrob
    from polyrob.io.controller import load_controller
    from polyrob.pipeline.problem import build_problem
    from polyrob.synthesis.fixed.vertex import vertex_peak, vertex_synthesis

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("robot")
    p.add_argument("controllers", nargs="+", help="controller files (polyrob synth -o)")
    p.add_argument("--domain", default=None, help="a named domain of the robot (e.g. paper)")
    p.add_argument("--samples", type=int, default=3000, help="uniform points of the domain")
    p.add_argument("--grid", type=int, default=40, help="positions at which the box corners are added")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tune", default=None, help="structure of a multi-model synthesis on the same plants")
    p.add_argument("--max-iter", type=int, default=150)
    args = p.parse_args(argv)

    robot = polyrob.load_robot(args.robot)
    domain = polyrob.Domain.from_robot(robot, args.domain) if args.domain else polyrob.Domain.from_robot(robot)
    # the weights of `polyrob synth` (the plant's bounds do not enter this figure)
    problem = build_problem(robot, domain, uncertainty="box", progress=False, bound_options={"samples": 16})
    P = problem.P
    X = frozen_points(domain, args.samples, args.grid, args.seed)
    m = robot.m
    A, B = robot.jacobians_batch(X[:, :m], X[:, m : 2 * m], X[:, 2 * m :])
    plants = [(A[i], B[i]) for i in range(len(X))]
    omega = np.logspace(-4, 3.5, 120)
    doc = {
        "machine": {"platform": platform.platform(), "cores": len(os.sched_getaffinity(0))},
        "robot": args.robot,
        "domain": domain.name,
        "frozen_plants": len(plants),
        "omega": [1e-4, 10**3.5, len(omega)],
        "controllers": [],
    }
    for path in args.controllers:
        K = load_controller(path)
        row = {"controller": path, "worst_frozen_peak": vertex_peak(plants, K, P.W_S, P.W_T, omega=omega)}
        if args.tune:
            t0 = time.perf_counter()
            res = vertex_synthesis(
                plants, P.W_S, P.W_T, structure=args.tune, initial=K, omega=omega, max_iter=args.max_iter, certify=False
            )
            row["tuned"] = {
                "structure": args.tune,
                "worst_frozen_peak": res.grid_peak,
                "from": res.initial_grid_peak,
                "seconds": round(time.perf_counter() - t0, 1),
                "optimiser": res.info.get("bfgs_message"),
            }
        doc["controllers"].append(row)
    print(json.dumps(doc, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
