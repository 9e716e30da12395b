"""Time-varying certificate on the paper's problem: largest bandwidth factor alpha certified.

On ``paper_2r --domain paper`` (the PLDI of tests/conftest.py), for each bandwidth
factor alpha of the paper's weights (``scaled_hyperparameters(alpha)``: omega_b and
omega_bt times alpha), in decreasing order, a tf3 controller is tuned on the worst
vertex of the PLDI (warm-started from K* or from the previous alpha's controller,
:func:`polyrob.synthesis.fixed.vertex.vertex_synthesis`) and certified with quadstab /
quadperf (common Lyapunov matrix at every vertex, verified a posteriori).  The
scan stops at the first alpha whose quadratic performance holds (gamma < 1).
Also reports K* itself.  Prints one JSON document.

    python benchmarks/time_varying.py [--alphas 1,0.5,0.25] [--which auto|polytope|box]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time

from _results import add_results_option, save_run


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--alphas", default="1,0.7,0.5,0.35,0.25,0.125")
    ap.add_argument("--which", default="auto")
    ap.add_argument("--max-iter", type=int, default=150)
    add_results_option(ap)
    args = ap.parse_args(argv)

    from polyrob import bound_pldi, load_robot
    from polyrob.analysis.time_varying.quadratic import quadperf, quadstab
    from polyrob.plant.generalized import paper_controller
    from polyrob.plant.weights import paper_weights
    from polyrob.synthesis.bandwidth import scaled_hyperparameters
    from polyrob.synthesis.fixed.vertex import vertex_synthesis

    t0 = time.perf_counter()
    pldi = bound_pldi(load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    out = {
        "problem": "paper_2r --domain paper",
        "enclosure": pldi.enclosure,
        "machine": f"{platform.machine()}, {__import__('os').cpu_count()} cores",
        "runs": [],
    }
    W_S, W_T = paper_weights()
    t = time.perf_counter()
    qs = quadstab(pldi, paper_controller(), which=args.which)
    qp = quadperf(pldi, paper_controller(), W_S, W_T, which=args.which, vertex_norms=False)
    out["paper_controller"] = {
        "alpha": 1.0,
        "order": 12,
        "quadstab": qs.holds,
        "quadstab_status": qs.solver_status,
        "quadperf": qp.holds,
        "gamma": qp.gamma,
        "n_vertices": qs.n_vertices,
        "vertex_source": qs.vertex_source,
        "seconds": round(time.perf_counter() - t, 2),
    }
    K0, best = None, None
    for alpha in (float(a) for a in args.alphas.split(",")):
        W_S, W_T = paper_weights(scaled_hyperparameters(alpha))
        t = time.perf_counter()
        try:
            r = vertex_synthesis(
                pldi,
                W_S,
                W_T,
                initial=K0,
                which=args.which,
                max_iter=args.max_iter,
                progress=lambda msg: print(f"  alpha {alpha}: {msg}", file=sys.stderr),
            )
        except Exception as exc:  # record and go on to the next alpha
            out["runs"].append({"alpha": alpha, "error": f"{type(exc).__name__}: {exc}"})
            continue
        row = {"alpha": alpha, **r.summary(), "seconds": round(time.perf_counter() - t, 2)}
        out["runs"].append(row)
        print(json.dumps(row), file=sys.stderr)
        if r.quadstab.holds:
            K0 = r.controller
        if r.quadperf is not None and r.quadperf.holds:
            best = row
            break
    out["largest_alpha_certified"] = None if best is None else best["alpha"]
    out["seconds"] = round(time.perf_counter() - t0, 2)
    figure = f"largest factor with time-varying robust performance: {out['largest_alpha_certified']}"
    save_run(
        args.results,
        "time_varying",
        "Time-varying certificates per bandwidth factor",
        figure,
        json.loads(json.dumps(out, default=float)),
    )
    print(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
