"""Jacobian samples per second: polyrob's batched form against the floors.

Prints JSON, one record per robot, side by side in the same run:

- ``batched``: ``robot.jacobians_batch`` (polyrob);
- ``plain_loop``: a Python loop over ``pinocchio.computeABADerivatives`` that
  copies its outputs (the floor a Python caller can reach);
- ``finite_differences``: central differences over ``pinocchio.aba``, what a
  user without polyrob would write.

Usage: ``python benchmarks/jacobians.py [--samples N] [--repeats R]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np
import pinocchio
from _results import add_results_option, save_run

from polyrob import Domain, load_robot


def best_rate(fn, n, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n / best


def plain_loop(robot, config, qdot, tau):
    model, data = robot.model, robot.model.createData()
    out = []
    for k in range(len(config)):
        dq, dv, minv = pinocchio.computeABADerivatives(model, data, config[k], qdot[k], tau[k])
        out.append((dq.copy(), dv.copy(), minv.copy()))
    return out


def finite_differences(robot, config, qdot, tau, h=1e-6):
    model, data = robot.model, robot.model.createData()
    nv = model.nv
    for k in range(len(config)):
        for j in range(nv):
            e = np.zeros(nv)
            e[j] = h
            qp = pinocchio.integrate(model, config[k], e)
            qm = pinocchio.integrate(model, config[k], -e)
            pinocchio.aba(model, data, qp, qdot[k], tau[k]) - pinocchio.aba(model, data, qm, qdot[k], tau[k])
            pinocchio.aba(model, data, config[k], qdot[k] + e, tau[k]) - pinocchio.aba(
                model, data, config[k], qdot[k] - e, tau[k]
            )
            pinocchio.aba(model, data, config[k], qdot[k], tau[k] + e) - pinocchio.aba(
                model, data, config[k], qdot[k], tau[k] - e
            )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=5)
    add_results_option(parser)
    args = parser.parse_args()
    results = []
    for name, extra in (("planar_2r", {}), ("ur5", {}), ("panda", {})):
        robot = load_robot(name)
        domain = Domain.from_robot(robot, **extra)
        q, qdot, u = domain.sample(args.samples, seed=0)
        config = robot.configuration(q)
        tau = u - robot.damping * qdot
        n_fd = max(args.samples // 20, 100)
        batched = best_rate(lambda: robot.jacobians_batch(q, qdot, u), args.samples, args.repeats)
        loop = best_rate(lambda: plain_loop(robot, config, qdot, tau), args.samples, args.repeats)
        fd = best_rate(lambda: finite_differences(robot, config[:n_fd], qdot[:n_fd], tau[:n_fd]), n_fd, 1)
        results.append(
            {
                "robot": name,
                "m": robot.m,
                "samples": args.samples,
                "batched_per_s": round(batched),
                "plain_loop_per_s": round(loop),
                "finite_differences_per_s": round(fd),
                "batched_over_plain_loop": round(batched / loop, 3),
                "batched_over_finite_differences": round(batched / fd, 2),
            }
        )
    doc = {
        "benchmark": "jacobians",
        "machine": {
            "processor": platform.processor() or platform.machine(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
            "pinocchio": pinocchio.__version__,
        },
        "results": results,
    }
    ratios = ", ".join(f"{r['robot']} {r['batched_over_finite_differences']}x" for r in results if "robot" in r)
    save_run(
        args.results, "jacobians", "Jacobian samples per second", f"batched over finite differences: {ratios}", doc
    )
    print(
        json.dumps(
            doc,
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
