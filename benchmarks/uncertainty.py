"""Box vs tight uncertainty models on the paper's problem, side by side (prints JSON).

``paper_2r --domain paper`` with the paper's weights: for each model
(``box``: the paper's; ``lft``: the default tight model; optionally ``axes``)
the number of real parameters, blocks, coverage on fresh samples, volume
over the polytope, the robust-performance μ (upper and lower bound) of the
paper's K*, then a D-G-K controller synthesised on that model (μ, order,
time) and, for every controller, its μ on every model (so the tight model's
μ of K* and of the D-K controllers stands beside the box's).

``--bandwidth-scale α`` multiplies both weights' bandwidths (``ω_B``,
``ω_BT``); the robot's performance limit at those weights (the floor no
controller beats, :mod:`polyrob.analysis.limits`) and, for every controller
on every model, the time-varying certificate
(:func:`polyrob.analysis.time_varying.certificate.time_varying_certificate`) are printed
beside μ.

Usage::

    python benchmarks/uncertainty.py [--models box,lft] [--no-synthesis] [--tf3] [--bandwidth-scale 4]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "src"))

from _results import add_results_option, save_run  # noqa: E402

import polyrob  # noqa: E402
import polyrob.analysis.limits  # noqa: E402
from polyrob.analysis.robust import robperf  # noqa: E402
from polyrob.analysis.time_varying.certificate import time_varying_certificate  # noqa: E402
from polyrob.pipeline import Problem, default_hyperparameters  # noqa: E402
from polyrob.plant.coverage import det_b_range  # noqa: E402
from polyrob.plant.generalized import generalized_plant, paper_controller  # noqa: E402
from polyrob.plant.uncertainty import uncertain_plant  # noqa: E402
from polyrob.plant.weights import paper_weights  # noqa: E402


def _mu(P, K):
    t = time.perf_counter()
    rp = robperf(P, K)
    return {
        "rp_upper": round(rp.mu_upper_grid, 4),
        "rp_lower": round(rp.mu_lower, 4),
        "seconds": round(time.perf_counter() - t, 1),
    }


def _time_varying(problem, K):
    t = time.perf_counter()
    tv = time_varying_certificate(problem, K)
    return {
        "method": tv.method,
        "stability_holds": tv.stability_holds,
        "performance_holds": tv.performance_holds,
        "stability_gamma": (
            round(float(tv.stability.gamma), 4) if getattr(tv.stability, "gamma", None) is not None else None
        ),
        "performance_gamma": None if tv.performance is None else round(float(tv.performance.gamma), 4),
        "notes": list(tv.notes),
        "seconds": round(time.perf_counter() - t, 1),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--models", default="box,lft")
    ap.add_argument("--no-synthesis", action="store_true")
    ap.add_argument("--tf3", action="store_true", help="also tf3 from K* on the tight model (slow)")
    ap.add_argument("--samples", type=int, default=256, help="PLDI design size (the tests' 256)")
    ap.add_argument("--bandwidth-scale", type=float, default=1.0, help="multiply omega_b and omega_bt")
    ap.add_argument("--no-time-varying", action="store_true")
    add_results_option(ap)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    robot = polyrob.load_robot("paper_2r")
    pldi = polyrob.bound_pldi(robot, samples=args.samples, progress=False)
    h = default_hyperparameters(2, bandwidth_scale=args.bandwidth_scale)
    W_S, W_T = paper_weights(h)
    out = {
        "problem": f"paper_2r --domain paper, paper's weights with bandwidths x {args.bandwidth_scale:g}",
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}",
        "pldi": {
            "samples": args.samples,
            "coverage": pldi.coverage,
            "seconds": pldi.info["seconds_total"],
            "polytope_over_box": pldi.polytope.volume_ratio,
        },
        "models": {},
    }
    t = time.perf_counter()
    limit = polyrob.analysis.limits.performance_limit(robot, pldi.domain, W_T)
    out["performance_limit"] = dict(limit.to_dict(), seconds=round(time.perf_counter() - t, 1))
    plants, problems, controllers = {}, {}, {"K*": paper_controller()}
    for name in args.models.split(","):
        t = time.perf_counter()
        unc = uncertain_plant(pldi, model=name, coverage=10_000)
        secs = time.perf_counter() - t
        P = generalized_plant(unc, W_S, W_T)
        plants[name] = P
        problems[name] = Problem(robot, pldi, unc, P, h, name, unc.model)
        lo, hi = det_b_range(unc, 2000)
        out["models"][name] = {
            "model": unc.model,
            "parameters": unc.n_params,
            "channels": unc.n_delta,
            "blocks": np.asarray(unc.block_structure).tolist(),
            "coverage": unc.coverage,
            "coverage_points": unc.coverage_points,
            "volume_over_polytope": unc.volume_ratio,
            "det_B_over_centre": [round(lo, 3), round(hi, 3)],
            "seconds_model": round(secs, 2),
        }
        if not args.no_synthesis:
            from polyrob.synthesis import musyn

            t = time.perf_counter()
            res = musyn(P)
            controllers[f"D-G-K on {name}"] = res.controller
            out["models"][name]["dgk"] = {
                "mu": round(res.peak_mu, 4),
                "mu_lower": round(res.peak_mu_lower, 4),
                "order": res.order,
                "seconds": round(time.perf_counter() - t, 1),
            }
    if args.tf3:
        from polyrob.synthesis.fixed.synthesis import fixed_structure_musyn

        tight = [n for n in plants if n != "box"][0]
        t = time.perf_counter()
        res = fixed_structure_musyn(plants[tight], structure="tf3", init="paper", starts=1, progress=False)
        controllers[f"tf3 from K* on {tight}"] = res.controller
        out["models"][tight]["tf3"] = {
            "mu": round(res.peak_mu, 4),
            "mu_lower": round(res.peak_mu_lower, 4),
            "order": res.order,
            "seconds": round(time.perf_counter() - t, 1),
        }
    out["mu_of_each_controller"] = {k: {name: _mu(P, K) for name, P in plants.items()} for k, K in controllers.items()}
    if not args.no_time_varying:
        out["time_varying_of_each_controller"] = {
            k: {name: _time_varying(prob, K) for name, prob in problems.items()} for k, K in controllers.items()
        }
    out["seconds_total"] = round(time.perf_counter() - t0, 1)
    save_run(args.results, "uncertainty", "Uncertainty models side by side", "the script's JSON in data", out)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
