"""Bounding the Jacobians: polyrob's PLDI against plain uniform sampling.

Prints JSON.  For planar_2r, ur5 and panda: the wall time of ``bound_pldi``,
the coverage on 10,000 fresh points, and the widths that plain uniform
sampling of (q, qdot, u) reaches in the same time, as a fraction of polyrob's
(per entry: min, median, max).  For panda also uniform sampling given 10x the
time ("at least as wide as uniform sampling given 10x the time, in every
entry" holds when ``uniform_10x_over_polyrob.max <= 1``).  For planar_2r the
certified/sampled width ratio per entry.

Usage: ``python benchmarks/bounds.py [--robots planar_2r,ur5,panda] [--panda-factor 10]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np
from _results import add_results_option, save_run

from polyrob import Domain, bound_pldi, load_robot


def uniform_widths(robot, pldi, seconds, seed=123, chunk=20000):
    """Per-entry widths reached by uniform random sampling within ``seconds``."""
    rng_seed = seed
    lo = np.full(len(pldi.entries), np.inf)
    hi = -lo
    n = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        q, qdot, u = pldi.domain.sample(chunk, method="uniform", seed=rng_seed)
        rng_seed += 1
        vals = pldi.entry_values(*robot.jacobians_batch(q, qdot, u))
        lo = np.minimum(lo, vals.min(axis=0))
        hi = np.maximum(hi, vals.max(axis=0))
        n += chunk
    return hi - lo, n


def ratio_stats(r, digits=4):
    return {
        "min": round(float(r.min()), digits),
        "median": round(float(np.median(r)), digits),
        "max": round(float(r.max()), digits),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="planar_2r,ur5,panda")
    parser.add_argument("--panda-factor", type=float, default=10.0)
    add_results_option(parser)
    args = parser.parse_args()
    results = []
    for name in args.robots.split(","):
        robot = load_robot(name)
        domain = Domain.from_robot(robot)
        t0 = time.perf_counter()
        pldi = bound_pldi(robot, domain, coverage=0, progress=False)
        seconds = time.perf_counter() - t0
        from polyrob.bounds.pldi import coverage_fraction

        coverage = coverage_fraction(pldi, robot, 10_000, seed=987)
        width = pldi.upper - pldi.lower
        w1, n1 = uniform_widths(robot, pldi, seconds)
        rec = {
            "robot": name,
            "m": robot.m,
            "varying_entries": len(pldi.entries),
            "seconds": round(seconds, 2),
            "coverage_10000_fresh": coverage,
            "polytope_halfspaces": pldi.polytope.n_halfspaces,
            "polytope_reduced_dim": pldi.polytope.reduced_dim,
            "polytope_volume_hits": [pldi.polytope.volume_hits, pldi.polytope.volume_samples],
            "max_refinement_widening": round(float(pldi.refinement.max()), 4),
            "uniform_same_time": {"samples": n1, "width_over_polyrob": ratio_stats(w1 / width)},
        }
        if name == "panda":
            w10, n10 = uniform_widths(robot, pldi, args.panda_factor * seconds, seed=10_000)
            rec["uniform_10x_time"] = {
                "factor": args.panda_factor,
                "samples": n10,
                "width_over_polyrob": ratio_stats(w10 / width),
            }
        if name == "planar_2r":
            t1 = time.perf_counter()
            cert = bound_pldi(robot, domain, coverage=0, certify=True, progress=False)
            rec["certified"] = {
                "seconds": round(time.perf_counter() - t1, 2),
                "certified_over_sampled_width": ratio_stats((cert.upper - cert.lower) / width, 6),
            }
        results.append(rec)
        print(json.dumps(rec), flush=True) if os.environ.get("POLYROB_BENCH_STREAM") else None
    doc = {
        "benchmark": "bounds",
        "machine": {
            "processor": platform.processor() or platform.machine(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
        },
        "results": results,
    }
    save_run(
        args.results, "bounds", "Bounding the Jacobians against uniform sampling", "the script's JSON in data", doc
    )
    print(json.dumps(doc, indent=2))


if __name__ == "__main__":
    main()
