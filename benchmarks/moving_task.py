"""The main job's moving-robot verdict on its task: time, peak memory and the bound of each search (JSON).

    python benchmarks/moving_task.py RUN_DIR [--variants arbitrary:1,bounded:1,arbitrary:2] [--points 5,3]
        [--cells] [--solver clarabel|structured] [--rounds N] [--results PATH]
    python benchmarks/moving_task.py RUN_DIR --parts [--results PATH]

``RUN_DIR`` is what ``polyrob run -o RUN_DIR`` writes (the main job: planar_2r
on its task); its problem and controller are read back
(:func:`polyrob.pipeline.rebuild.load_run`).  Each variant ``VELOCITIES:HARMONICS``
runs :func:`polyrob.analysis.lpv.task.task_motion_certificate` in its own
process (so that its peak memory is its own, read with ``wait4``): ``arbitrary``
is ``X`` on the positions only (what ``--moving`` takes for the main job's
16-state loop), ``bounded`` ``X`` on the positions times ``(1, qdot)`` with
the velocities' rates bounded by the task's accelerations.  ``--solver``: the
search's LMI solver (Clarabel, this script's default and the task
certificate's on loops of at most 8 states, or the structured interior
point, the certificate's on larger ones); ``--rounds N``: rounds of constraint generation
(the re-check grid's failing points added to the search,
:data:`polyrob.analysis.lpv.task.RECHECK_ROUNDS` by default with ``--cells``,
else none).  Printed per variant: the bound proved on the
search grid, on the finer re-check grid (twice as dense along positions and
velocities, :func:`polyrob.analysis.lpv.task.recheck_points`), the cells'
outcome with ``--cells``, the status, the seconds and the peak memory, and
the machine's load at the start and the end.

``--parts``: which motion the bound pays for.  The same loop, one kind of
parameter moving at a time, the others frozen at the task's centre: the
accelerations switching between their ends (one constant ``X``), the
velocities over their box arbitrarily fast (one constant ``X``), and ``q2``
over its range at ``|dq2/dt| <= qdot_max`` (and at a hundredth of it) with
``X(q2)`` on one or two harmonics, on 5 to 17 points; each bound as searched
in the Gramian's coordinates and searched again in its own ``X``'s
(:func:`polyrob.analysis.lpv.robot.refine`); beside the frozen peak of the same
points.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _results import add_results_option, save_run


def one(run_dir: str, velocities: str, harmonics: int, points, cells: bool, solver: str = "clarabel",
        rounds: int | None = None) -> dict:
    """One search in this process: the summary of its certificate."""
    from polyrob.analysis.lpv.task import task_motion_certificate
    from polyrob.pipeline.rebuild import load_run

    run = load_run(run_dir)
    t0 = time.perf_counter()
    c = task_motion_certificate(run.problem, run.controller, points=points, velocities=velocities,
                                harmonics=harmonics, cells=cells, level=0.95 if cells else None, cell_workers=1,
                                lower_bound=True, solver=solver, recheck_rounds=rounds)  # fmt: skip
    r = c.result
    return {
        "velocities": velocities,
        "harmonics": harmonics,
        "solver": solver,
        "points": list(points),
        "finer_points": c.finer.get("points"),
        "rounds": rounds,
        "notes": list(c.certificate.scope.notes) if c.computed else [],
        "status": c.certificate.status.value if c.computed else "not computed",
        "grid_bound": None if r is None else float(r.gamma),
        "finer_bound": c.finer.get("gamma"),
        "cells": c.cells,
        "lower_bound": (c.lower or {}).get("gamma"),
        "frozen_peak": None if r is None else float(r.frozen_gamma),
        "why": list(c.notes),
        "search_seconds": round(time.perf_counter() - t0, 1),
    }


def parts(run_dir: str) -> list[dict]:
    """The bound of each single motion (module text), searched on its own grid."""
    from dataclasses import replace

    import numpy as np

    from polyrob.analysis.lpv.basis import default_basis
    from polyrob.analysis.lpv.norm import lpvnorm
    from polyrob.analysis.lpv.robot import closed_loop_system, conditioned, kinematic_rates, refine
    from polyrob.analysis.lpv.task import task_rate_bounds, task_scheduling
    from polyrob.pipeline.rebuild import load_run

    run = load_run(run_dir)
    problem, K = run.problem, run.controller
    base = task_scheduling(problem.robot, problem.domain)
    centre = {k: 0.5 * (a[0] + a[-1]) for k, a in zip(base.kinds, base.axes)}
    q_axis = next(a for a, k in zip(base.axes, base.kinds) if k == "q")
    whole = closed_loop_system(base, K, problem.P.W_S, problem.P.W_T, problem.P.W_KS)
    poles = np.abs(np.linalg.eigvals(whole(np.array([centre[k] for k in base.kinds]))[0]))
    print(json.dumps({"loop_pole_moduli_at_centre": [float(poles.min()), float(poles.max())]}), file=sys.stderr)
    cases = [
        ("accelerations at their ends, one X", {"qddot": None}, 0, 1.0),
        ("velocities over their box, arbitrarily fast, one X", {"qdot": 3}, 0, 1.0),
        ("q2 over its range, X(q2) on 1 harmonic, 5 points", {"q": 5}, 1, 1.0),
        ("q2 over its range, X(q2) on 1 harmonic, 9 points", {"q": 9}, 1, 1.0),
        ("q2 over its range, X(q2) on 2 harmonics, 9 points", {"q": 9}, 2, 1.0),
        ("q2 over its range, X(q2) on 2 harmonics, 17 points", {"q": 17}, 2, 1.0),
        ("q2 over its range at a hundredth of the rate, X(q2) on 2 harmonics, 9 points", {"q": 9}, 2, 0.01),
    ]
    out = []
    for name, moving, harmonics, scale in cases:
        axes = []
        for a, k in zip(base.axes, base.kinds):
            if k not in moving:
                axes.append(np.array([centre[k]]))
            else:
                axes.append(a if moving[k] is None else np.linspace(a[0], a[-1], moving[k]))
        model = replace(base, axes=tuple(axes))
        system = closed_loop_system(model, K, problem.P.W_S, problem.P.W_T, problem.P.W_KS)
        sysf, c = conditioned(system, np.array([np.mean(a) for a in axes]))
        t0 = time.perf_counter()
        basis = None if harmonics == 0 else default_basis(model, harmonics=harmonics)[: 1 + 2 * harmonics]
        rates = [r if k == "q" and basis is not None else (-np.inf, np.inf)
                 for r, k in zip(task_rate_bounds(model, problem.domain, scale=scale), model.kinds)]  # fmt: skip

        def solve(system_c, c, options, model=model, basis=basis, rates=rates):
            if basis is None:  # one X for every point: the parameters move arbitrarily fast
                return lpvnorm(system_c, list(model.axes), None, None, **options)
            return lpvnorm(system_c, list(model.axes), [(lo / c, hi / c) for lo, hi in rates], basis,
                           rates_at=kinematic_rates(model, rates, c), **options)  # fmt: skip

        r = solve(sysf, c, {"eps": 1e-4})
        again = refine((r, sysf, c, {"eps": 1e-4}), solve, basis, np.array([np.mean(a) for a in axes]))[0]
        out.append({"motion": name, "bound": float(r.gamma), "why": r.reason, "refined": float(again.gamma),
                    "frozen_peak": float(r.frozen_gamma),
                    "q2_range": [float(q_axis[0]), float(q_axis[-1])], "seconds": round(time.perf_counter() - t0, 1)})  # fmt: skip
        print(json.dumps(out[-1]), file=sys.stderr, flush=True)
    return out, [float(poles.min()), float(poles.max())]


def measure(run_dir: str, variant: str, points: str, cells: bool, solver: str = "clarabel", rounds=None) -> dict:
    """``variant`` in a child process: its summary, wall seconds, peak memory and the load around it."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        cmd = [sys.executable, __file__, run_dir, "--one", variant, "--points", points, "--out", str(out),
               "--solver", solver] + ([] if rounds is None else ["--rounds", str(rounds)])
        cmd += ["--cells"] if cells else []
        t0, load0 = time.perf_counter(), os.getloadavg()[0]
        child = subprocess.Popen(cmd)
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait for it again
        if child.returncode != 0:
            raise SystemExit(f"{variant}: the child exited {child.returncode}")
        doc = json.loads(out.read_text())
    doc.update(seconds=round(time.perf_counter() - t0, 1), peak_gb=round(usage.ru_maxrss / 1e6, 2),
               load=[round(load0, 2), round(os.getloadavg()[0], 2)])  # fmt: skip
    return doc


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("run_dir", help="a directory `polyrob run -o DIR` wrote")
    ap.add_argument("--variants", default="arbitrary:1,bounded:1,arbitrary:2", help="VELOCITIES:HARMONICS, ...")
    ap.add_argument("--points", default="5,3", help="search grid points per position and per velocity")
    ap.add_argument("--cells", action="store_true", help="prove a grid bound below 1 between the points")
    ap.add_argument("--parts", action="store_true", help="the bound of each single motion (module text)")
    ap.add_argument("--solver", default="clarabel", choices=("clarabel", "structured"), help="the search's LMI solver")
    ap.add_argument("--rounds", type=int, default=None, help="rounds of constraint generation (default: 3 with --cells)")
    ap.add_argument("--one", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--out", default=None, help=argparse.SUPPRESS)
    add_results_option(ap)
    args = ap.parse_args()
    points = tuple(int(x) for x in args.points.split(","))
    if args.parts:
        import numpy as np

        rows, poles = parts(args.run_dir)
        doc = {"run_dir": args.run_dir, "parts": rows, "loop_pole_moduli_at_centre": poles}
        print(json.dumps(doc, indent=1, default=float))
        table = {"columns": ["what moves (the rest at the task's centre)", "bound proved on its grid",
                             "searched again in its X's coordinates", "frozen peak there", "time"],
                 "rows": [[r["motion"], f"{r['bound']:.4g}" if np.isfinite(r["bound"]) else f"no bound ({r['why']})",
                           f"{r['refined']:.4g}" if np.isfinite(r["refined"]) else "no bound",
                           f"{r['frozen_peak']:.4g}", f"{r['seconds']:.0f} s"]
                          for r in rows]}  # fmt: skip
        figure = "; ".join(f"{r['motion']}: {r['bound']:.3g} ({r['refined']:.3g} searched again)" for r in rows) + (
            f"; the loop's poles at the task's centre from {poles[0]:.3g} to {poles[1]:.4g} rad/s"
        )
        save_run(args.results, "moving_task", "What each motion of the task costs the main job's moving bound",
                 figure, doc, table)  # fmt: skip
        return
    if args.one:
        velocities, harmonics = args.one.split(":")
        Path(args.out).write_text(json.dumps(one(args.run_dir, velocities, int(harmonics), points, args.cells,
                                                 args.solver, args.rounds), default=float))  # fmt: skip
        return
    rows = [measure(args.run_dir, v, args.points, args.cells, args.solver, args.rounds)
            for v in args.variants.split(",")]
    doc = {"run_dir": args.run_dir, "variants": rows}
    print(json.dumps(doc, indent=1, default=float))

    def bound(x):
        return "no bound" if x is None or x == float("inf") else f"{x:.4g}"

    table = {
        "columns": ["X on", "grid", "solver", "bound on the grid", "on the finer grid (points)",
                    "found along trajectories (lower)", "status", "time", "peak memory"],
        "rows": [[("positions" if r["velocities"] == "arbitrary" else "positions x (1, qdot)")
                  + f", {r['harmonics']} harmonic(s)", "x".join(map(str, r["points"])), r["solver"],
                  bound(r["grid_bound"]), f"{bound(r['finer_bound'])} ({r['finer_points']})", bound(r["lower_bound"]),
                  r["status"], f"{r['seconds']:.0f} s", f"{r['peak_gb']:.1f} GB"] for r in rows],
    }  # fmt: skip
    figure = "; ".join(f"{r['velocities']}:{r['harmonics']} {r['status']} (grid {bound(r['grid_bound'])}, finer "
                       f"{bound(r['finer_bound'])}, {r['solver']}, {r['seconds']:.0f} s, {r['peak_gb']:.1f} GB)"
                       for r in rows)  # fmt: skip
    save_run(args.results, "moving_task", "The main job's moving robot on its task, per search", figure, doc, table)


if __name__ == "__main__":
    main()
