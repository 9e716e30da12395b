"""Time of μ's D-G descent on a task cell's loop, as JSON: per objective evaluation, and the cell's whole sweep.

    python benchmarks/mu_descent.py [CONTROLLER.json] [--robot-uncertainty default] [--fraction 0.5]
        [--points 8] [--no-sweep]

For the controller file's robot, task, weights and the set the options
state (default: so101's engineer-set PID on the engineer's set), this
builds the task cell centred on the task with its positions' ranges times
``--fraction`` (:func:`polyrob.analysis.frozen_cells.cell_plant`, the model
a cell of ``polyrob analyze --frozen-cells`` is certified on), closes the
loop and times, on one BLAS thread:

* ``descent``: :class:`polyrob.analysis.mu.gradient.GradientUpper` at
  ``--points`` frequencies from 0.01 to 300 rad/s, each warm-started from the
  last (as a sweep does): seconds, objective evaluations and milliseconds per
  evaluation, and the bounds reached;
* ``sweep``: :func:`polyrob.analysis.loop_sweep.sweep_loop` on the loop's own
  grid (what a cell's certificate sweeps before its check between the
  points): seconds, grid points, the peak's bounds.

The cells' time is mostly this sweep, and the sweep's mostly the descent's
objective (an eigen-decomposition of a ~90-channel Hermitian matrix and the
block-structured products around it).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from _results import add_results_option, save_run
from _sets import add_set_options, controller_file_problem

DEFAULT_CONTROLLER = Path(__file__).parent / "controllers" / "so101_engineer_set_pid.json"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controller", nargs="?", default=str(DEFAULT_CONTROLLER), help="a controller file (`synth -o`)")
    add_set_options(ap, payload_max=0.0)
    ap.add_argument("--fraction", type=float, default=0.5, help="the cell's share of each position range (0.5)")
    ap.add_argument("--points", type=int, default=8, help="frequencies of the descent's timing (8)")
    ap.add_argument("--no-sweep", action="store_true", help="time the descent only (seconds, not minutes)")
    add_results_option(ap)
    ap.set_defaults(robot_uncertainty="default")
    args = ap.parse_args()

    from polyrob._threads import single_blas_thread
    from polyrob.analysis.frozen_cells import cell_domain, cell_plant
    from polyrob.analysis.loop_sweep import sweep_loop
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.analysis.mu.gradient import GradientUpper
    from polyrob.plant.loops import lft

    t0 = time.perf_counter()
    robot, loop, problem, K = controller_file_problem(args, args.controller)
    domain = problem.domain
    centre = 0.5 * (domain.q_lower + domain.q_upper)
    half = 0.5 * args.fraction * (domain.q_upper - domain.q_lower)
    _, P = cell_plant(problem, cell_domain(domain, centre - half, centre + half))
    N = lft(P, K)
    st = as_block_structure(P.block_structure_rp)
    built = time.perf_counter() - t0

    omega = np.logspace(-2, np.log10(300.0), args.points)
    response = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(omega)
    descent = GradientUpper(st)
    uppers, x = [], None
    with single_blas_thread():
        t = time.perf_counter()
        for H in response:
            beta, _, _, x = descent(st.pad(H), x)
            uppers.append(float(beta))
        descent_s = time.perf_counter() - t
        sweep = None
        if not args.no_sweep:
            t = time.perf_counter()
            mu, _ = sweep_loop(N, P.block_structure_rp)
            sweep = {
                "seconds": round(time.perf_counter() - t, 1),
                "grid_points": int(len(mu.omega)),
                "peak_upper": float(mu.peak_upper),
                "peak_lower": float(mu.peak_lower),
                "peak_frequency": float(mu.peak_upper_frequency),
            }
    out = {
        "controller": args.controller,
        "robot": robot.name,
        "set": loop.uncertainty.words(),
        "cell_fraction": args.fraction,
        "structure": str(st),
        "padded_channels": int(st.padded_size),
        "blocks": len(st.blocks),
        "states": int(np.asarray(N.A).shape[0]),
        "build_seconds": round(built, 1),
        "descent": {
            "omega": omega.tolist(),
            "upper": uppers,
            "seconds": round(descent_s, 2),
            "objective_calls": descent.evaluations,
            "ms_per_objective": round(1e3 * descent_s / max(descent.evaluations, 1), 2),
        },
        "sweep": sweep,
    }
    print(json.dumps(out, indent=1))
    figure = f"{out['descent']['ms_per_objective']} ms per objective evaluation ({st.padded_size} channels)"
    if sweep:
        figure += f"; the cell's sweep {sweep['seconds']} s on {sweep['grid_points']} frequencies"
    save_run(args.results, "mu_descent", f"{robot.name}: mu's D-G descent on a task cell's loop", figure, out)


if __name__ == "__main__":
    main()
