"""Robust performance of a controller with its model's parameters constant and its residual blocks moving at any rate, as JSON.

    python benchmarks/mixed_ltv.py ROBOT [polyrob analyze options] --controller K.json [--points 120]

An arm's computed-torque model (``inner-gain``, :mod:`polyrob.plant.models.inner_gain`)
holds the robot's constant parameters (the links' factor, the payload's
mass) as real scalars and what changes with the state (``J(x) - J_c``, the
stiffness, damping and inertia residuals) in full blocks.  In motion the
parameters stay constant and the residuals move with the state.  Three
figures on the same model and controller, from the most to the least
variation allowed:

* ``all_any_rate``: every block time-varying at any rate, the constant-D
  scaled small gain of the time-varying verdict
  (:func:`~polyrob.analysis.time_varying.smallgain.scaled_small_gain`);
* ``mixed``: the real scalars constant (LTI: frequency-dependent D-G
  scalings), the residual blocks time-varying at any rate and the
  performance block an L2 gain: each of those full blocks keeps a constant
  multiplier ``r_i^2 [[I, 0], [0, -I]]``.  At one frequency the μ upper
  bound with the full blocks merged into one (after scaling block ``i`` by
  ``r_i``, the performance block's ``r`` 1) uses one scaling ``d(ω)`` for
  all of them; dividing every multiplier at ``ω`` by ``d(ω)`` leaves the
  frequency condition and makes the full blocks' multipliers constant, the
  real scalars' still frequency-dependent, which constant real scalars
  allow (the mixed LTI/LTV condition of Paganini, Automatica 1996; Shamma,
  IEEE TAC 1994).  ``r`` is searched (a grid, then Nelder-Mead on the
  coarse frequencies); the figure is the largest μ bound over the grid;
* ``frozen``: every block constant, μ's upper bound (the frozen certificate's
  figure) on the same grid.

The grid figures are the largest values on ``--points`` log-spaced
frequencies (and the poles' magnitudes), not bounds between them: a
measurement of what motion costs, not a certificate.  Only the ``inner-gain``
model's real scalars are the robot's constant parameters (``inner-links``'
directions and the ``axes`` model's move with the state): other models are
refused.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from _results import add_results_option, save_run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=120, help="log-spaced frequencies from 1e-3 to 1e4 rad/s")
    add_results_option(ap)
    args, rest = ap.parse_known_args()

    import control
    import numpy as np
    from scipy.optimize import minimize

    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.analysis.time_varying.smallgain import scaled_small_gain
    from polyrob.cli import build_parser
    from polyrob.cli.analyze import load_controller_args
    from polyrob.cli.common import robot_from_args
    from polyrob.cli.plant import problem_from_args
    from polyrob.controller import Controller
    from polyrob.plant.generalized import lft

    class Quiet:  # problem_from_args's output: this script prints JSON only
        def __getattr__(self, name):
            return lambda *a, **k: None

    t0 = time.perf_counter()
    cli = build_parser().parse_args(["analyze", *rest, "--no-moving"])
    problem = problem_from_args(robot_from_args(cli), cli, Quiet())
    if problem.model != "inner-gain":  # only there are the real scalars the robot's constant parameters
        sys.exit(
            f"mixed_ltv.py: the model is {problem.model!r}; its real scalars move with the state, so holding them "
            "constant would not describe the moving robot: give an arm's default task ('inner-gain')"
        )
    K = load_controller_args(cli.controller)[0]
    P = problem.P
    N = lft(P, Controller.of(K))
    st = as_block_structure(P.block_structure_rp)
    blocks = list(st.blocks)
    perf = len(blocks) - 1
    moving = [k for k, b in enumerate(blocks[:-1]) if b.kind == "full"]
    constant = [k for k in range(perf) if k not in moving]
    A, B, C, D = (np.asarray(X, float) for X in (N.A, N.B, N.C, N.D))
    poles = np.abs(np.linalg.eigvals(A))
    omega = np.unique(np.r_[np.logspace(-3, 4, args.points), poles[(poles > 1e-3) & (poles < 1e4)]])
    H = matrix_response(A, B, C, D)(omega)
    frozen = np.array([mussv(H[k], st, lower=False).upper for k in range(len(omega))])

    def span(sl):
        return np.arange(sl.start, sl.stop)

    merged = moving + [perf]
    order = constant + merged
    rows = np.concatenate([span(st.col_slices[k]) for k in order])  # N's outputs: the blocks' inputs
    cols = np.concatenate([span(st.row_slices[k]) for k in order])  # N's inputs: the blocks' outputs
    structure = [blocks[k].matlab for k in constant] + [
        (sum(blocks[k].rows for k in merged), sum(blocks[k].cols for k in merged))
    ]

    def mixed(log_r, at):
        r = np.exp(np.append(log_r, 0.0))
        out_scale, in_scale = np.ones(H.shape[1]), np.ones(H.shape[2])
        for k, rk in zip(merged, r):
            out_scale[span(st.col_slices[k])] = rk
            in_scale[span(st.row_slices[k])] = 1.0 / rk
        return np.array(
            [
                mussv((out_scale[:, None] * H[f] * in_scale[None, :])[np.ix_(rows, cols)], structure, lower=False).upper
                for f in at
            ]
        )

    coarse = np.unique(np.r_[np.arange(0, len(omega), 6), frozen.argmax()])
    axes = [np.linspace(-9.0, 0.0, 7)] * len(moving)
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(moving), -1).T
    start = min(grid, key=lambda g: mixed(g, coarse).max())
    found = minimize(lambda x: mixed(x, coarse).max(), start, method="Nelder-Mead", options={"maxfev": 150})
    values = mixed(found.x, range(len(omega)))
    fast = scaled_small_gain(control.ss(A, B, C, D), P.block_structure_rp)
    out = {
        "robot": problem.robot.name,
        "controller": cli.controller,
        "model": problem.model,
        "blocks": [list(b.matlab) for b in blocks],
        "constant_blocks": constant,
        "moving_blocks": moving,
        "frequencies": len(omega),
        "frozen": {"grid_peak": round(float(frozen.max()), 4), "at": float(omega[frozen.argmax()])},
        "mixed": {
            "grid_peak": round(float(values.max()), 4),
            "at": float(omega[values.argmax()]),
            "r": [float(x) for x in np.exp(found.x)],
        },
        "all_any_rate": {"gamma": round(float(fast.gamma), 4), "route": fast.info.get("route")},
        "seconds": round(time.perf_counter() - t0, 1),
    }
    figure = (
        f"{out['robot']}: frozen mu {out['frozen']['grid_peak']}, residuals at any rate with constant parameters "
        f"{out['mixed']['grid_peak']} (grid of {len(omega)}), everything at any rate {out['all_any_rate']['gamma']}"
    )
    save_run(args.results, "mixed_ltv", "What motion costs a controller's robust performance", figure, out)
    print(json.dumps(out, indent=1))
    print(figure, file=sys.stderr)


if __name__ == "__main__":
    main()
