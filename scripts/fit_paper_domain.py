"""Find the velocity box behind the paper's A intervals (it prints none).

The paper's intervals follow its printed Coriolis matrix (``paper_2r``).  With
``u = 0`` and ``q2`` over ``[-pi, pi]``, this searches ``|qdot1| <= v1``,
``|qdot2| <= v2`` for the box whose intervals come closest to the printed ones,
measured per entry as the endpoint error over the printed interval's width,
and prints the fit and the per-entry mismatch as JSON (quoted in
docs/paper_2r.md).  Usage: ``python scripts/fit_paper_domain.py``.
"""

from __future__ import annotations

import json

import numpy as np
from scipy import optimize

from polyrob import Domain, bound_pldi, load_robot

PAPER = {
    "a32": (-19.127, 19.6402),
    "a33": (-1.58, 1.58),
    "a34": (-3.56, 3.56),
    "a42": (-13.9637, 28.2362),
    "a43": (-5.42, 5.42),
    "a44": (-3.95, 3.95),
    "b31": (0.0286, 0.0312),
    "b32": (-0.0461, -0.0164),
    "b41": (-0.0461, -0.0164),
    "b42": (0.0848, 0.144),
}


def mismatch(robot, v1, v2, refine=False):
    domain = Domain.from_robot(robot, qdot_max={"joint1": v1, "joint2": v2}, u_max=0.0)
    pldi = bound_pldi(robot, domain, samples=512, refine=refine, coverage=0, progress=False)
    out = {}
    for name, (lo, hi) in PAPER.items():
        plo, phi = pldi.interval(name)
        out[name] = {
            "polyrob": [round(plo, 5), round(phi, 5)],
            "paper": [lo, hi],
            "error_over_width": round(max(abs(plo - lo), abs(phi - hi)) / (hi - lo), 5),
        }
    return out


def main():
    robot = load_robot("paper_2r")

    def cost(v):
        if np.any(v <= 0):
            return 1e9
        return max(e["error_over_width"] for k, e in mismatch(robot, *v).items() if k.startswith("a"))

    best = optimize.minimize(
        cost, x0=[4.0, 10.0], method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-6, "maxiter": 200}
    )
    v1, v2 = (float(x) for x in best.x)
    table = mismatch(robot, v1, v2, refine=True)
    print(
        json.dumps(
            {
                "qdot_max": [round(v1, 4), round(v2, 4)],
                "u": 0.0,
                "max_error_over_width": max(e["error_over_width"] for e in table.values()),
                "entries": table,
                "round_box_4_10": mismatch(robot, 4.0, 10.0, refine=True),
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
