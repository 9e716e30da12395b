"""The inner maximisation beyond four joints: vertices + coordinate ascent against the exact face enumeration.

    python benchmarks/box_maximum.py [--robot panda] [--positions 40] [--seed 0]

At random positions of the robot's default domain, every entry of ``(A, B)``
is a polynomial in the scaled velocities and torques
(:func:`polyrob.bounds.extremes.polynomial_coefficients`); each is maximised
and minimised over the velocity/torque box twice with
:func:`polyrob.bounds.extremes.box_maximum`: ``exact=False`` (the ``2^m``
vertices, then coordinate ascent from the best four: what the position
search uses beyond four joints) and ``exact=True`` (all ``3^m`` faces).
Prints, as JSON, the fraction of (position, entry, sign) pairs where the
first reaches the exact maximum (to 1e-9 relative), the largest shortfall,
and the time per polynomial of each.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np
from _results import add_results_option, save_run


def box_maximum_figure(out: dict) -> str:
    """One line of the JSON: how often the ascent is exact, its worst shortfall, the time per polynomial."""
    return (
        f"exact for {100 * out['fraction_exact_quadratic_pairs']:.1f} % of the pairs quadratic in the velocities, "
        f"{100 * out['fraction_exact_all_pairs']:.1f} % of all, at worst {100 * out['largest_relative_shortfall']:.2f} % "
        f"below; {out['ms_per_polynomial_exact_faces']:.3g} ms per polynomial (faces) against "
        f"{out['ms_per_polynomial_vertices_ascent']:.2g} ms (vertices and ascent)"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--positions", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    add_results_option(ap)
    args = ap.parse_args(argv)

    import polyrob
    from polyrob.bounds.extremes import box_maximum, polynomial_coefficients

    robot = polyrob.load_robot(args.robot)
    dom = polyrob.Domain.from_robot(robot)
    rng = np.random.default_rng(args.seed)
    q = dom.q_lower + (dom.q_upper - dom.q_lower) * rng.random((args.positions, dom.m))
    t_c, t_s = 0.5 * (dom.qdot_upper + dom.qdot_lower), 0.5 * (dom.qdot_upper - dom.qdot_lower)
    u_c, u_s = 0.5 * (dom.u_upper + dom.u_lower), 0.5 * (dom.u_upper - dom.u_lower)

    def entries_at(qq, qd, uu):
        A, B = robot.jacobians_batch(qq, qd, uu)
        return np.hstack([A.reshape(len(qq), -1), B.reshape(len(qq), -1)])

    c, a, b, Q = polynomial_coefficients(entries_at, q, t_c, t_s, u_c, u_s)
    quadratic = np.abs(Q).max(axis=(0, 1, 2)) > 1e-12 * np.maximum(np.abs(c).max(axis=0), 1e-300)
    out = {"robot": robot.name, "m": int(dom.m), "positions": args.positions, "machine": platform.machine()}
    res = {}
    for exact in (False, True):
        vals, t0 = [], time.perf_counter()
        for sign in (1.0, -1.0):
            v, _, _ = box_maximum(sign * c, sign * a, sign * b, sign * Q, t_s > 0, u_s > 0, exact=exact)
            vals.append(v)
        res[exact] = (np.stack(vals), time.perf_counter() - t0)
    approx, exact_v = res[False][0], res[True][0]
    n_poly = approx.size
    # only the entries with a quadratic part: the others are maximised at a vertex by both
    sel = np.broadcast_to(quadratic, approx.shape)
    scale = np.maximum(np.abs(exact_v), 1e-12)
    hit = approx >= exact_v - 1e-9 * scale
    short = (exact_v - approx) / scale
    out.update(
        {
            "entries": int(c.shape[1]),
            "entries_with_quadratic_part": int(quadratic.sum()),
            "pairs": int(n_poly),
            "fraction_exact_all_pairs": float(hit.mean()),
            "fraction_exact_quadratic_pairs": float(hit[sel].mean()),
            "largest_relative_shortfall": float(short.max()),
            "ms_per_polynomial_vertices_ascent": 1e3 * res[False][1] / n_poly,
            "ms_per_polynomial_exact_faces": 1e3 * res[True][1] / n_poly,
        }
    )
    save_run(args.results, "box_maximum", "The inner maximisation beyond four joints", box_maximum_figure(out), out)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
