"""How far is μ < 1 on the paper's 2R problem?  Syntheses under scaled weights.

Run ``python benchmarks/weights_scan.py`` (about 35 min on two cores; the
syntheses run two at a time; ``--cases tf3`` runs the fixed-structure rows
only); prints one JSON document.  ``docs/synthesis.md`` quotes its figures.

Every row is a full-order complex D-K synthesis (:func:`polyrob.synthesis.mu_synthesis`,
``mixed=False``, 25 iterations at most), or for the ``tf3`` rows the
third-order fixed structure started from K* (one start, mixed μ), on
``paper_2r --domain paper`` (ten independent real parameters) with the
paper's weights modified as named,
certified by :func:`polyrob.analysis.mu.bounds.mu_bounds` against the real structure, plus
the robust-stability μ of the same controller.  A last row adds a lag
``(s + 1)/(s + 1e-4)`` per channel to the paper-weights controller to show
what its low-frequency plateau hides.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor

import control
import numpy as np

warnings.simplefilter("ignore")

import polyrob  # noqa: E402
from polyrob.analysis.mu.bounds import mu_bounds  # noqa: E402
from polyrob.analysis.robust import robstab  # noqa: E402
from polyrob.plant.weights import paper_weights  # noqa: E402
from polyrob.synthesis import musyn, scaled_hyperparameters  # noqa: E402

BOTH = ("omega_b", "omega_bt")
#: (name, bandwidth factor, scaled hyperparameters, gain on both weights, structure)
CASES = [
    ("paper weights", 1.0, (), 1.0, "full"),
    ("bandwidths x2", 2.0, BOTH, 1.0, "full"),
    ("bandwidths x4", 4.0, BOTH, 1.0, "full"),
    ("bandwidths x8", 8.0, BOTH, 1.0, "full"),
    ("performance bandwidth x0.01", 0.01, ("omega_b",), 1.0, "full"),
    ("weight gains x0.3", 1.0, (), 0.3, "full"),
    ("weight gains x0.01", 1.0, (), 0.01, "full"),
    ("tf3 from K*, bandwidths x4", 4.0, BOTH, 1.0, "tf3"),
    ("tf3 from K*, bandwidths x8", 8.0, BOTH, 1.0, "tf3"),
    ("tf3 from K*, then tf4 from it, bandwidths x8", 8.0, BOTH, 1.0, "tf3>tf4"),
]


def log(msg: str) -> None:
    print(f"[weights scan] {msg}", file=sys.stderr, flush=True)


def uncertain():
    robot = polyrob.load_robot("paper_2r")
    pldi = polyrob.bound_pldi(robot, polyrob.Domain.from_robot(robot, "paper"), progress=False)
    return polyrob.uncertain_plant(pldi)


def plant(unc, alpha, scale, gain):
    W_S, W_T = paper_weights(scaled_hyperparameters(alpha, None, scale))
    return polyrob.generalized_plant(unc, gain * W_S, gain * W_T)


#: the uncertain plant, bounded once in main() and inherited by the forked workers
UNC = None


def run_case(case):
    name, alpha, scale, gain, structure = case
    P = plant(UNC, alpha, scale, gain)
    t0 = time.perf_counter()
    if structure == "full":
        res = musyn(P, mixed=False, max_iter=25, progress=False)
    else:  # mixed mu optimised directly over the controller's parameters, from K*
        init = "paper"
        for step in structure.split(">"):  # "tf3>tf4": each result starts the richer structure
            res = musyn(P, structure=step, init=init, starts=1, max_iter=30, progress=False)
            init = res.controller
    rs = robstab(P, res.controller, progress=False)
    out = {
        "case": name,
        "structure": structure,
        "peak_mu_certified": res.peak_mu,
        "peak_mu_lower": res.peak_mu_lower,
        "peak_frequency": res.peak_frequency,
        "robust_stability_mu": rs.mu_upper_grid,
        "order": res.order,
        "iterations": res.iterations,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    if name == "paper weights":
        lag = control.ss(control.tf([1, 1], [1, 1e-4]))
        K = control.ss(res.controller) * control.append(lag, lag)
        w = np.logspace(-5, 3, 33)
        mu = mu_bounds(polyrob.lft(P, K), P.block_structure_rp, w, progress=False, refine_peak=False).upper
        out["with_lag"] = {
            "mu_below_1e-3_rad_s": float(mu[w < 1e-3].max()),
            "mu_0.1_to_30_rad_s": float(mu[(w >= 0.1) & (w <= 30)].max()),
        }
    log(f"{name}: mu {res.peak_mu:.4f} (RS {rs.mu_upper_grid:.4f}), order {res.order}, {out['seconds']} s")
    return out


def main():
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="", help="only the cases whose name contains this text (e.g. tf3)")
    cases = [c for c in CASES if parser.parse_args().cases in c[0]]
    t0 = time.perf_counter()
    global UNC
    UNC = uncertain()
    with ProcessPoolExecutor(max_workers=min(2, os.cpu_count() or 1), mp_context=mp.get_context("fork")) as pool:
        rows = list(pool.map(run_case, cases))
    print(
        json.dumps(
            {
                "machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]},
                "problem": "paper_2r --domain paper, ten independent real parameters",
                "rows": rows,
                "total_seconds": round(time.perf_counter() - t0, 1),
            },
            indent=2,
            default=float,
        )
    )


if __name__ == "__main__":
    main()
