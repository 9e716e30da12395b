"""Benchmark of polyrob's μ-synthesis, side by side with dkpy and the paper's K*.

Run ``python benchmarks/synthesis.py`` (about 15-20 min on two
cores); prints one JSON document.

Problems
--------
* ``distillation``: Skogestad & Postlethwaite's distillation column (Table
  8.1, p. 325; dkpy's ``example_skogestad2006_p325``): diagonal complex input
  uncertainty and a full 2x2 performance block.  polyrob's full-order D-K
  (:func:`polyrob.synthesis.mu_synthesis`, automatic D orders) against dkpy's
  ``DkIterAutoOrder`` (HinfSynSlicot, SsvLmiBisection, DScaleFitSlicot,
  3 iterations, orders up to 4: dkpy's documented example).  Both
  controllers are also certified with the same :func:`polyrob.analysis.mu.bounds.mu_bounds`
  sweep (peak-refined), since each tool reports μ on its own grid.
* ``paper_2r``: the paper's 2R robot (ten independent real parameters,
  paper weights): the paper's K* analysed, full-order D-K (reals treated as
  complex), D-G-K (reals kept real),
  the reduced controller, the fixed-structure third-order controller
  (``structure="tf3"`` from K*, two starts, run in a parallel process under
  a time limit) and the largest bandwidth factor α of the weights with a
  certified μ < 1 (:func:`polyrob.synthesis.max_bandwidth_scaling` on the
  scan ``BANDWIDTH_ALPHAS``).

Every μ reported for polyrob is the certified upper bound of ``lft(P, K)``
from :func:`polyrob.analysis.mu.bounds.mu_bounds` against the true structure.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
import sys
import time
import warnings

import control
import numpy as np

warnings.simplefilter("ignore")

import polyrob  # noqa: E402
import polyrob.plant.weights  # noqa: E402
from polyrob.analysis.certificate import certify_loop  # noqa: E402
from polyrob.analysis.mu.bounds import mu_bounds  # noqa: E402
from polyrob.examples import DISTILLATION_BLK as DIST_BLK  # noqa: E402
from polyrob.examples import distillation_plant  # noqa: E402
from polyrob.synthesis import max_bandwidth_scaling, musyn, reduce_controller  # noqa: E402


def log(msg: str) -> None:
    print(f"[synthesis benchmark] {msg}", file=sys.stderr, flush=True)


DIST_OMEGA = np.logspace(-3, 3, 61)
CERT_OMEGA = np.logspace(-4, 4, 97)
#: scan of the bandwidth factor (the full default scan takes too long here)
BANDWIDTH_ALPHAS = (1.0, 2.0, 4.0, 8.0)


def bench_distillation() -> dict:
    P = distillation_plant()
    out = {}
    log("distillation: polyrob")
    t0 = time.perf_counter()
    res = musyn(P, DIST_BLK, n_u=2, n_y=2, omega=DIST_OMEGA, progress=False)
    out["polyrob"] = {
        "status": _status(res),
        "peak_mu_certified": res.peak_mu,
        "peak_mu_lower": res.peak_mu_lower,
        "peak_mu_grid": res.info["grid_peak_mu"],
        "order": res.order,
        "iterations": res.iterations,
        "mu_history": [round(float(x), 4) for x in res.mu_history],
        "seconds": round(time.perf_counter() - t0, 2),
    }
    mu_same = certify_loop(P, res.controller, DIST_BLK, CERT_OMEGA, n_u=2, n_y=2).mu_upper_grid
    out["polyrob"]["peak_mu_certified_common_grid"] = mu_same
    try:
        import dkpy
    except ImportError:
        out["dkpy"] = "not installed"
        return out
    log("distillation: dkpy")
    eg = dkpy.example_skogestad2006_p325()
    it = dkpy.DkIterAutoOrder(
        controller_synthesis=dkpy.HinfSynSlicot(),
        structured_singular_value=dkpy.SsvLmiBisection(),
        d_scale_fit=dkpy.DScaleFitSlicot(),
        max_mu=1,
        max_mu_fit_error=1e-2,
        max_iterations=3,
        max_fit_order=4,
    )
    t0 = time.perf_counter()
    K, N, mu, _, _ = it.synthesize(eg["P"], eg["n_y"], eg["n_u"], DIST_OMEGA, np.array(DIST_BLK))
    secs = time.perf_counter() - t0
    Kss = control.ss(K)
    out["dkpy"] = {
        "version": importlib.metadata.version("dkpy"),
        "peak_mu_grid": float(mu),
        "order": int(Kss.nstates),
        "seconds": round(secs, 2),
        "peak_mu_certified_common_grid": certify_loop(P, Kss, DIST_BLK, CERT_OMEGA, n_u=2, n_y=2).mu_upper_grid,
    }
    return out


FIXED_SNIPPET = r"""
import json, time, warnings, sys
warnings.simplefilter("ignore")
import polyrob, polyrob.plant.weights
from polyrob.synthesis import musyn
pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), progress=False)
P = polyrob.generalized_plant(polyrob.uncertain_plant(pldi, model="box"), *polyrob.plant.weights.paper_weights())
t0 = time.perf_counter()
r = musyn(P, structure="tf3", init="paper", starts=2, progress=False)
print(json.dumps({"status": r.certificate.status.value, "peak_mu_certified": r.peak_mu, "peak_mu_lower": r.peak_mu_lower, "order": r.order,
                  "iterations": r.iterations, "init": "paper", "starts": 2,
                  "seconds": round(time.perf_counter() - t0, 2)}))
"""


def start_fixed():
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    proc = subprocess.Popen(
        [sys.executable, "-c", FIXED_SNIPPET], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True
    )
    return proc


def finish_fixed(proc, timeout):
    try:
        out, err = proc.communicate(timeout=max(timeout, 1.0))
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return f"not finished within the benchmark's time limit ({timeout:.0f} s left)"
    if proc.returncode != 0:
        return "failed: " + (err.strip().splitlines() or ["?"])[-1]
    return json.loads(out.strip().splitlines()[-1])


def _status(res):
    """The certificate's status (docs/certificates.md), or None when the result carries none."""
    cert = getattr(res, "certificate", None)
    return None if cert is None else cert.status.value


def summary(res, seconds=None) -> dict:
    return {
        "status": _status(res),
        "peak_mu_certified": res.peak_mu,
        "peak_mu_lower": res.peak_mu_lower,
        "peak_frequency": res.peak_frequency,
        "order": res.order,
        "iterations": res.iterations,
        "method": res.info.get("method"),
        "seconds": round(seconds if seconds is not None else res.seconds, 2),
    }


def bench_paper(t_start: float, budget: float) -> dict:
    out = {}
    proc = start_fixed()  # runs on the other core meanwhile
    t0 = time.perf_counter()
    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), progress=False)
    unc = polyrob.uncertain_plant(pldi, model="box")
    P = polyrob.generalized_plant(unc, *polyrob.plant.weights.paper_weights())
    out["plant_seconds"] = round(time.perf_counter() - t0, 2)
    # the paper's K*
    log("2R: K* analysis")
    t0 = time.perf_counter()
    r = mu_bounds(polyrob.lft(P, polyrob.paper_controller()), P.block_structure_rp, progress=False)
    out["paper_K_star"] = {
        "peak_mu_upper": r.peak_upper,
        "peak_mu_lower": r.peak_lower,
        "peak_frequency": r.peak_upper_frequency,
        "order": 12,
        "seconds": round(time.perf_counter() - t0, 2),
    }
    # full-order D-K, real parameters treated as complex
    log("2R: full-order D-K")
    t0 = time.perf_counter()
    dk = musyn(P, mixed=False, progress=False)
    t_dk = time.perf_counter() - t0
    out["full_order_dk_complex"] = summary(dk, t_dk)
    out["full_order_dk_complex"]["mu_history_complex"] = [round(float(x), 4) for x in dk.mu_history]
    # D-G-K: D-K steps while they gain 2 % per iteration, then D-G-K steps
    log("2R: full-order D-G-K")
    t0 = time.perf_counter()
    dgk = musyn(P, mixed=True, progress=False, max_iter=25)
    t_dgk = time.perf_counter() - t0
    out["full_order_dgk_mixed"] = summary(dgk, t_dgk)
    out["full_order_dgk_mixed"]["mu_history_mixed"] = [round(float(x), 4) for x in dgk.mu_history]
    best = dgk if dgk.peak_mu <= dk.peak_mu else dk
    # reduced controller
    log("2R: reduction")
    t0 = time.perf_counter()
    red = reduce_controller(P, best, tol=0.05)
    out["reduced"] = dict(
        red.summary(),
        status=_status(getattr(red, "result", None)),
        seconds=round(time.perf_counter() - t0, 2),
        reduced_from=best.info.get("method"),
    )
    # the largest bandwidth factor of the weights with certified mu < 1
    log("bandwidth scaling")
    t0 = time.perf_counter()
    try:
        bw = max_bandwidth_scaling(unc, alphas=BANDWIDTH_ALPHAS, rtol=0.1, mixed=False, max_iter=15, progress=False)
        out["bandwidth_scaling"] = bw.summary()
    except Exception as exc:  # noqa: BLE001 - report, do not abort the benchmark
        out["bandwidth_scaling"] = {"result": f"no alpha found: {exc}"}
    out["bandwidth_scaling"]["seconds"] = round(time.perf_counter() - t0, 2)
    left = budget - (time.perf_counter() - t_start)
    log(f"2R: waiting for tf3 (at most {left:.0f} s)")
    out["fixed_tf3"] = finish_fixed(proc, left)
    return out


def synthesis_figure(doc: dict) -> str:
    """One line of the document: each method's certified peak μ (the record's data holds the rest)."""
    parts = []
    for problem in ("distillation", "paper_2r"):
        for method, res in doc.get(problem, {}).items():
            if isinstance(res, dict) and isinstance(res.get("peak_mu_certified"), (int, float)):
                parts.append(f"{problem} {method} {res['peak_mu_certified']:.4g}")
    return "certified peak mu: " + (", ".join(parts) or "none") + f"; {doc['total_seconds']:.0f} s in all"


def main(argv=None):
    import argparse

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from _results import add_results_option, save_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_results_option(ap)
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    doc = {"machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0]}}
    doc["distillation"] = bench_distillation()
    doc["paper_2r"] = bench_paper(t_start, budget=30 * 60)
    doc["total_seconds"] = round(time.perf_counter() - t_start, 1)
    doc = json.loads(json.dumps(doc, default=float))
    save_run(args.results, "synthesis", "mu-synthesis methods side by side", synthesis_figure(doc), doc)
    print(json.dumps(doc, indent=2, default=float))


if __name__ == "__main__":
    main()
