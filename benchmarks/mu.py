"""Benchmark of polyrob's mu bounds against a plain cvxpy LMI bisection (and dkpy).

Run ``PYTHONPATH=src python benchmarks/mu.py``; prints one JSON document with,
per problem and method, the time per frequency point and the bound reached.

Problems
--------
* ``mixed_random``: random stable 8x8 system, structure
  diag(3 real scalars, 2 complex scalars, one 3x3 full complex block).
* ``distillation_rp``: Skogestad & Postlethwaite's distillation column (LV
  model, inverse-based controller, diagonal input uncertainty + full
  performance block): robust-performance mu peaks at about 5.77 (SP06 §8.12).

Methods
-------
* ``polyrob_ab13md``: :func:`polyrob.analysis.mu.bounds.mussv` upper bound only (SLICOT AB13MD).
* ``polyrob_mu_bounds``: full :func:`polyrob.analysis.mu.bounds.mu_bounds` sweep (upper +
  lower bound + peak refinement), time per grid point.
* ``polyrob_lmi``: :func:`polyrob.analysis.mu.bounds.mussv` with ``method="lmi"`` (DPP-compiled
  D-G LMI, certified bisection).
* ``cvxpy_lmi_bisection``: a plain per-frequency D-G LMI feasibility
  bisection, rebuilt for every frequency, as dkpy does it.
* ``dkpy``: ``dkpy.SsvLmiBisection`` on complex-only problems, if installed.

With ``--large`` (slow: minutes) a third problem, ``large_repeated``: one
random matrix against the size of ur5's ``axes`` model (twelve repeated real
scalars ``δ I_7``, a 6x18 and a 12x12 full complex block, 114 padded
channels), bounded by descent on the D-G scalings (``method="gradient"``,
what ``"auto"`` takes there) and by AB13MD on the relaxed superset structure
(``method="relaxed"``); the D-G LMI is left out (not done in 6 minutes).

With ``--choice`` (about 3 minutes: the bounds come first) only the loops
behind ``method="auto"``'s choice (:func:`method_choice`): finger_edu's and
talos_left_arm's default problems closed by their tuned PIDs, each method
at 8 frequencies.
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import control
import cvxpy as cp
import numpy as np

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.bounds import mu_bounds, mussv
from polyrob.examples import DISTILLATION_BLK, distillation_rp_response


def plain_lmi_bisection(M: np.ndarray, blk, rtol: float = 1e-3) -> float:
    """Per-frequency D-G LMI bisection without any reuse (the dkpy way).

    Square blocks only.  Feasibility of M^H X M + j(GM - M^H G) - g^2 X <= 0
    with X >= I block-structured, bisection on g in [0, sigma_max(M)].
    """
    st = as_block_structure(blk)
    n = st.padded_size
    xs, gs = [], []
    for b, sl in zip(st.blocks, st.padded_slices):
        S = np.zeros((n, b.size))
        S[sl, :] = np.eye(b.size)
        x = cp.Variable()
        xs.append(x * (S @ S.T))
        if b.kind == "real":
            g = cp.Variable()
            gs.append(g * (S @ S.T))
    X = sum(xs)
    G = sum(gs) if gs else np.zeros((n, n))
    gam2 = cp.Parameter(nonneg=True)
    L = M.conj().T @ X @ M + 1j * (G @ M - M.conj().T @ G) - gam2 * X
    prob = cp.Problem(cp.Minimize(0), [(L + L.H) / 2 << 0, X >> np.eye(n)])
    lo, hi = 0.0, float(np.linalg.norm(M, 2))
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        gam2.value = mid**2
        try:
            prob.solve(solver="CLARABEL")
            ok = prob.status == "optimal"
        except cp.error.SolverError:
            ok = False
        hi, lo = (mid, lo) if ok else (hi, mid)
    return hi


def _timed(fn, items):
    t0 = time.perf_counter()
    vals = [fn(x) for x in items]
    return (time.perf_counter() - t0) / len(items), np.array(vals)


def run_problem(name: str, H: np.ndarray, omega: np.ndarray, blk, sys=None, n_lmi: int = 12) -> dict:
    out = {
        "problem": name,
        "size": list(H.shape[1:]),
        "blk": as_block_structure(blk).matlab.tolist(),
        "n_freq": int(len(omega)),
        "methods": {},
    }
    m = out["methods"]
    t, up = _timed(lambda M: mussv(M, blk, lower=False).upper, H)
    m["polyrob_ab13md"] = {"ms_per_point": 1e3 * t, "peak_upper": float(up.max())}
    if sys is not None:
        t0 = time.perf_counter()
        r = mu_bounds(sys, blk, omega, progress=False)
        m["polyrob_mu_bounds"] = {
            "ms_per_point": 1e3 * (time.perf_counter() - t0) / len(omega),
            "peak_upper": r.peak_upper,
            "peak_lower": r.peak_lower,
            "peak_frequency": r.peak_upper_frequency,
        }
    # LMI methods are slow: a sub-grid around the peak and elsewhere
    idx = np.unique(
        np.r_[np.linspace(0, len(omega) - 1, n_lmi - 2).round().astype(int), np.argmax(up), max(np.argmax(up) - 1, 0)]
    )
    t, ul = _timed(lambda M: mussv(M, blk, lower=False, method="lmi", rtol=1e-3).upper, H[idx])
    m["polyrob_lmi"] = {
        "ms_per_point": 1e3 * t,
        "peak_upper_on_subgrid": float(ul.max()),
        "max_rel_gap_vs_ab13md": float(np.max(ul / up[idx] - 1)),
    }
    t, pl = _timed(lambda M: plain_lmi_bisection(M, blk), H[idx])
    m["cvxpy_lmi_bisection"] = {
        "ms_per_point": 1e3 * t,
        "peak_upper_on_subgrid": float(pl.max()),
        "max_rel_gap_vs_ab13md": float(np.max(pl / up[idx] - 1)),
    }
    m["ab13md_peak_on_subgrid"] = float(up[idx].max())
    return out


def run_dkpy(H: np.ndarray, blk) -> dict:
    try:
        import dkpy
    except ImportError:
        return "not installed (pip install polyrob[bench])"
    blocks = [dkpy.ComplexFullBlock(int(r), int(c)) for r, c in blk]
    t0 = time.perf_counter()
    mu_w, *_ = dkpy.SsvLmiBisection(n_jobs=None).compute_ssv(np.moveaxis(H, 0, -1), blocks)
    t = (time.perf_counter() - t0) / H.shape[0]
    return {"ms_per_point": 1e3 * t, "peak_upper": float(np.max(mu_w))}


def large_repeated() -> dict:
    """Descent vs AB13MD-on-a-superset on one ur5-sized matrix (see the module text)."""
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(2)
    blk = [[-7, 0]] * 12 + [[6, 18], [12, 12]]
    st = as_block_structure(blk)
    M = rng.standard_normal(st.m_shape) + 1j * rng.standard_normal(st.m_shape)
    M = M * np.exp(rng.standard_normal(st.m_shape[0]))[:, None]  # rows of unequal size, as in a real loop
    out = {"name": "large_repeated", "structure": str(st), "padded_channels": st.padded_size, "methods": {}}
    with threadpool_limits(1):
        for method in ("gradient", "relaxed"):
            t0 = time.perf_counter()
            r = mussv(M, st, method=method, lower=False)
            out["methods"][method] = {"upper": r.upper, "seconds": time.perf_counter() - t0}
    return out


def method_choice(robots=("finger_edu", "talos_left_arm"), n: int = 8) -> dict:
    """Each method on the robust-performance loop of a robot's default problem with its tuned PID.

    The figures behind ``resolve_method``'s ``"auto"``: finger_edu's computed-torque loop (a repeated
    real block of 3) for the LMI against descent, talos_left_arm's (72 real scalars: its model is
    ``axes``) for AB13MD against descent; ``n`` frequencies from 0.01 to 1000 rad/s.
    """
    from threadpoolctl import threadpool_limits

    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.fleet.jobs import Settings, _problem, as_job
    from polyrob.plant.loops import lower_lft_matrices
    from polyrob.synthesis.pid_tuning import tuned_pid

    out = []
    for robot in robots:
        problem = _problem(as_job(robot), Settings(), {})
        P, st = problem.P, as_block_structure(problem.P.block_structure_rp)
        K = tuned_pid(P).controller
        mats = [np.asarray(X, float) for X in (P.system.A, P.system.B, P.system.C, P.system.D, K.A, K.B, K.C, K.D)]
        Acl, Bcl, Ccl, Dcl = lower_lft_matrices(*mats, P.n_u, P.n_y)
        w = np.logspace(-2, 3, n)
        H = matrix_response(Acl, Bcl, Ccl, Dcl)(w)
        methods = ("lmi", "gradient") if st.has_repeated else ("ab13md", "gradient")
        row = {"robot": robot, "model": problem.model, "structure": str(st), "omega": w.tolist(), "methods": {}}
        with threadpool_limits(1):
            for method in methods:
                ups, secs = [], []
                for k in range(n):
                    t0 = time.perf_counter()
                    ups.append(mussv(H[k], st, method=method, lower=False).upper)
                    secs.append(time.perf_counter() - t0)
                row["methods"][method] = {"upper": ups, "seconds": secs}
        out.append(row)
    return {"method_choice": out}


def main(large: bool = False) -> dict:
    report = {"problems": []}
    # (a) random mixed real/complex
    rng = np.random.default_rng(1)
    n, modes = 8, 6
    # lightly damped modes spread over the band, randomly coupled to the I/O
    wn, zeta = np.logspace(-1, 1, modes), rng.uniform(0.05, 0.3, modes)
    A = np.zeros((2 * modes, 2 * modes))
    for k in range(modes):
        A[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = [[0, 1], [-(wn[k] ** 2), -2 * zeta[k] * wn[k]]]
    sysa = control.ss(
        A, rng.standard_normal((2 * modes, n)), rng.standard_normal((n, 2 * modes)), 0.1 * rng.standard_normal((n, n))
    )
    blka = [[-1, 0], [-1, 0], [-1, 0], [1, 0], [1, 0], [3, 3]]
    wa = np.logspace(-2, 2, 60)
    Ha = np.moveaxis(sysa(1j * wa, squeeze=False), -1, 0)
    report["problems"].append(run_problem("mixed_random", Ha, wa, blka, sys=sysa))
    # (b) complex-only: distillation column robust performance
    blkb = DISTILLATION_BLK
    wb = np.logspace(-3, 3, 61)
    frd = distillation_rp_response(wb)
    Hb = np.moveaxis(np.asarray(frd.fresp), -1, 0)
    res = run_problem("distillation_rp", Hb, wb, blkb, sys=frd)
    res["published_peak"] = 5.77
    res["methods"]["dkpy"] = run_dkpy(Hb, blkb)
    report["problems"].append(res)
    if large:
        report["problems"].append(large_repeated())
    return report


def mu_figure(report: dict) -> str:
    """One line of the report: each problem's peak upper bound per method that gives one over the whole grid."""
    if "method_choice" in report:
        return f"method choice on {len(report['method_choice'])} loops (timings in data)"
    parts = []
    for problem in report["problems"]:
        peaks = [
            f"{name} {m['peak_upper']:.4g}"
            for name, m in problem["methods"].items()
            if isinstance(m, dict) and isinstance(m.get("peak_upper"), (int, float))
        ]
        name = problem.get("problem") or problem.get("name", "?")
        parts.append(f"{name}: " + (", ".join(peaks) or "see data"))
    return "; ".join(parts) + f"; {report['total_seconds']:.0f} s in all"


if __name__ == "__main__":
    import argparse
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _results import add_results_option, save_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--large", action="store_true", help="also the problem of ur5's size (slow: minutes)")
    ap.add_argument("--choice", action="store_true", help="only the loops behind method='auto' (about 3 min)")
    add_results_option(ap)
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # cvxpy's "solution may be inaccurate" chatter
    t0 = time.perf_counter()
    rep = method_choice() if args.choice else main(large=args.large)
    rep["total_seconds"] = time.perf_counter() - t0
    rep = json.loads(json.dumps(rep, default=float))
    save_run(args.results, "mu", "Time per frequency point and bound reached, mu bounds", mu_figure(rep), rep)
    print(json.dumps(rep, indent=2))
