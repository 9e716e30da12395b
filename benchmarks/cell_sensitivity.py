"""How fast the moving robot's weighted LMI really moves between grid points, for a saved ``X(rho)``.

The cells of :func:`polyrob.analysis.lpv.cells.check_cells` bound the change
of the bounded-real matrix ``L(rho)`` over a cell by norms of its parts (the
plant's and ``X``'s, each weighted by ``W = (-L(rho_c))^(-1/2)``), and on the
× 4 tf3 loop of ``paper_2r --domain paper`` reported 4302 per radian of
``q2`` (docs/certificates.md).  This script measures, at sampled centres of
the box and every rate vertex, by central differences of the exact
``L`` (``polyrob.analysis.lpv.check.brl_matrices``):

* ``N``: ``||W dL/drho_a W||`` per coordinate ``(q2, qdot1, qdot2)``, the
  whole matrix differentiated (steps 1e-5 and 1e-6 must agree);
* ``split_q2``: the same along ``q2`` for the plant part alone (``X`` and the
  rates frozen at the centre), the ``X`` part alone, the rate part alone;
* ``K_q2``: ``||W d2L/dq2^2 W||`` (second differences, steps 1e-3 and 3e-4).

Large ``split_q2`` beside a small ``N`` means the parts cancel (``X`` follows
the loop), so a cell test that norms them separately overstates the change.
``expansion``: what the second-order cell test
(:mod:`polyrob.analysis.lpv.cells.second_order`) proves on cells of four
sizes about the first centre: guaranteed bounds, not differences.

    python benchmarks/moving_robot.py --runs 4:tests/fixtures/paper_2r_tf3_alpha4_K.json --velocities bounded \\
        --harmonics 2 --points 17,3 --symmetric --level 0.95 --save-x x4s.npz
    python benchmarks/cell_sensitivity.py x4s.npz [--gamma 0.98] [--centres 12]

Prints one JSON document.  Pointwise derivatives (``rows``) bound nothing over a cell; ``expansion`` does.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time

import numpy as np


def _setup(path: str, factor: float, controller: str):
    from moving_robot import saved_search

    from polyrob.analysis.lpv.robot import kinematic_rates

    saved, model, _, sysf, c, basis, rates, _ = saved_search(factor, controller, path)
    return model, sysf, basis, kinematic_rates(model, rates, c), np.asarray(saved["X"], float)


def measure(path: str, gamma: float, centres: int, factor: float, controller: str) -> dict:
    from polyrob.analysis.lpv.check import GridData, brl_matrices

    model, sysf, basis, rates_at, Xs = _setup(path, factor, controller)
    lo = np.array([a[0] for a in model.axes])
    hi = np.array([a[-1] for a in model.axes])

    def parts(rho):
        A, B, C, D = sysf(rho)
        nus = np.array(np.meshgrid(*[np.unique(x) for x in np.array(rates_at(rho))], indexing="ij"))
        F = np.array([[f(rho) for f, _ in basis]])
        G = np.array([[g(rho) for _, g in basis]])
        return (A, B, C, D), (F, G), nus.reshape(len(rho), -1).T

    def lmi(rho, plant=None, x=None, rate=None):
        p, fx, nus = parts(rho)
        (A, B, C, D), (F, G) = plant or p, x or fx
        nus = nus if rate is None else rate
        data = GridData(A[None], B[None], C[None], D[None], F, G, nus[None], np.asarray(rho)[None])
        return brl_matrices(data, Xs, gamma)[0][0]

    rng = np.random.default_rng(1)
    rhos = np.clip(np.vstack([[2.159845, -1.9782, -4.97805], [np.pi / 4, 3.9564, 9.9561],
                              rng.uniform(lo, hi, size=(centres, 3))]), lo, hi)  # fmt: skip
    rows, e1 = [], np.array([1.0, 0.0, 0.0])
    for rho in rhos:
        Lc = lmi(rho)
        pc, xc, nc = parts(rho)
        for v in range(Lc.shape[0]):
            lam, V = np.linalg.eigh(-Lc[v])
            if lam[0] <= 0:
                rows.append({"rho": rho.round(5).tolist(), "vertex": v, "lmi_negative": False})
                continue
            W = (V * lam**-0.5) @ V.T

            def weighted(M):
                return float(np.linalg.norm(W @ M @ W, 2))

            N = [[weighted((lmi(rho + t * e)[v] - lmi(rho - t * e)[v]) / (2 * t)) for t in (1e-5, 1e-6)]
                 for e in np.eye(3)]  # fmt: skip
            t = 1e-5
            split = [weighted((lmi(rho + t * e1, **kw)[v] - lmi(rho - t * e1, **kw)[v]) / (2 * t))
                     for kw in ({"x": xc, "rate": nc}, {"plant": pc, "rate": nc}, {"plant": pc, "x": xc})]  # fmt: skip
            K = [weighted((lmi(rho + h * e1)[v] - 2 * Lc[v] + lmi(rho - h * e1)[v]) / h**2) for h in (1e-3, 3e-4)]
            rows.append({"rho": rho.round(5).tolist(), "vertex": v, "lmi_negative": True,
                         "N": [[round(x, 3) for x in n] for n in N], "split_q2": [round(x, 1) for x in split],
                         "K_q2": [round(x, 2) for x in K]})  # fmt: skip
    ok = [r for r in rows if r["lmi_negative"]]
    return {
        "expansion": expansion_bounds(path, gamma, factor, controller, rhos[0]),
        "centres": len(rhos),
        "rate_vertices": len(rows) // len(rhos),
        "lmi_not_negative": len(rows) - len(ok),
        "largest_N": np.max([[n[0] for n in r["N"]] for r in ok], axis=0).round(3).tolist(),
        "largest_split_q2": np.max([r["split_q2"] for r in ok], axis=0).round(1).tolist(),
        "largest_K_q2": float(np.max([r["K_q2"][0] for r in ok])),
        "rows": rows,
    }


def expansion_bounds(path: str, gamma: float, factor: float, controller: str, centre) -> list:
    """What the second-order cell test bounds on cells of several widths about ``centre`` (guaranteed, not sampled).

    Per cell: the largest ``||D_a||`` over the rate vertices (the whole LMI's derivative at the centre), the
    diagonal of the curvature bound ``K`` (largest over the vertices), the rounding allowance, and the margin
    the test proves (> 0: the cell holds).
    """
    from moving_robot import saved_search

    from polyrob.analysis.lpv.cells import cell_setting
    from polyrob.analysis.lpv.cells.second_order import expansions, second_order_cell

    saved, model, system, sysf, c, basis, rates, _ = saved_search(factor, controller, path)
    st = cell_setting(model, system, saved["X"], basis, rates, similarity=sysf.similarity, c=c)
    out = []
    for h in ([0.1, 0.5, 1.0], [0.05, 0.25, 0.5], [0.02, 0.5, 1.0], [0.01, 0.05, 0.1]):
        h = np.array(h)
        lo, hi = np.maximum(centre - h, st.lo), np.minimum(centre + h, st.hi)
        args = (st.loop, model, st.enclose, st.basis, st.Xs, st.rate_plan, st.fixed, gamma, lo, hi)
        ex, _, why = expansions(*args)
        out.append({"half_widths": h.tolist(), "why": why,
                    "D": np.max([[np.linalg.norm(d, 2) for d in e.D] for e in ex], axis=0).round(3).tolist(),
                    "K_diagonal": np.max([np.diag(e.K) for e in ex], axis=0).round(2).tolist(),
                    "allowance": round(max(e.allowance for e in ex), 5),
                    "margin": round(float(second_order_cell(*args)[0]), 4)})  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("saved", help="an X saved by benchmarks/moving_robot.py --save-x")
    ap.add_argument("--gamma", type=float, default=0.98, help="the level of the LMIs (the cells check at about 0.98)")
    ap.add_argument("--centres", type=int, default=12, help="random centres besides the two fixed ones")
    ap.add_argument("--factor", type=float, default=4.0)
    ap.add_argument("--controller", default="tests/fixtures/paper_2r_tf3_alpha4_K.json")
    args = ap.parse_args()
    t0 = time.perf_counter()
    out = {
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "load_average_start": list(os.getloadavg()),
        "saved": args.saved,
        "gamma": args.gamma,
        **measure(args.saved, args.gamma, args.centres, args.factor, args.controller),
    }
    out["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
