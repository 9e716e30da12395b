"""Moving-robot certificate on ``paper_2r --domain paper``: the three certificates of a controller per bandwidth factor.

For each run ``FACTOR:CONTROLLER`` (a controller file, or ``paper`` for the
paper's K*), the weights at ``--bandwidth-scale FACTOR``:

* ``moving``: :func:`polyrob.analysis.lpv.moving.moving_robot_certificate`
  (the linearised robot scheduled on ``(q2, qdot1, qdot2)``, ``dq2/dt =
  qdot2`` at every grid point, the velocities bounded by the domain's
  accelerations with ``X`` on the tensor basis, or arbitrary:
  docs/certificates.md), its proved gamma (the larger of the search grid's
  and the finer re-check grid's, or the cells' level when they hold), status,
  frozen peak, seconds and peak memory;
* with ``--full``: also the frozen-robot μ and the arbitrarily fast verdict
  of :func:`polyrob.pipeline.analyze_controller` (the PLDI bounded on the
  paper's domain, ``lft`` model) -- minutes more per run.

Prints one JSON document (with the machine, the date and the load average).

    python benchmarks/moving_robot.py [--runs 4:tests/fixtures/paper_2r_tf3_alpha4_K.json,1:paper]
                                      [--velocities auto|bounded|arbitrary] [--points 5,3] [--full]
                                      [--separable] [--recheck 9,5|none] [--level L --cells --cell-level G]
    python benchmarks/moving_robot.py --lower-only    # the gain found along admissible trajectories, alone
    python benchmarks/moving_robot.py --slice 3.9564,9.9561 --harmonics 1,2 [--q-points 12] [--slice-rate 0]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
from types import SimpleNamespace

from _results import add_results_option, save_run


def _controller(spec: str):
    if spec == "paper":
        from polyrob.plant.generalized import paper_controller

        return paper_controller()
    from polyrob.io.controller import load_controller

    return load_controller(spec)


def _light_problem(robot, domain, factor: float):
    """What the moving certificate reads of a problem (robot, domain, weights), without bounding a PLDI."""
    from polyrob.pipeline.problem import default_hyperparameters
    from polyrob.plant.weights import paper_weights

    W_S, W_T = paper_weights(default_hyperparameters(robot.m, bandwidth_scale=factor))
    return SimpleNamespace(robot=robot, domain=domain, P=SimpleNamespace(W_S=W_S, W_T=W_T, W_KS=None))


def run(
    factor: float,
    spec: str,
    *,
    velocities: str,
    points,
    full: bool,
    tensor: bool = True,
    recheck="auto",
    harmonics=1,
    save_x=None,
    level=None,
    cell_level=None,
    cells=False,
    cell_time_limit=900.0,
    symmetric=False,
    cell_workers=None,
) -> dict:
    from polyrob import load_robot
    from polyrob.analysis.lpv.moving import moving_robot_certificate
    from polyrob.domains.torque_box import Domain

    robot = load_robot("paper_2r")
    domain = Domain.from_robot(robot, "paper")
    K = _controller(spec)
    out = {"bandwidth_factor": factor, "controller": spec}
    t = time.perf_counter()
    problem = _light_problem(robot, domain, factor)
    mv = moving_robot_certificate(
        problem, K, velocities=velocities, points=points, tensor=tensor, recheck=recheck, harmonics=harmonics,
        level=level, cells=cells, cell_time_limit=cell_time_limit, progress=cells, symmetric=symmetric,
        cell_workers=cell_workers, cell_level=cell_level,
    )  # fmt: skip
    s = mv.summary()
    if save_x and mv.result is not None and mv.result.proved:
        import numpy as np

        # the proved X(rho) coefficients (coordinates of the search's conditioned loop), for checks between grid points
        np.savez(save_x, X=np.array(mv.result.X), gamma=mv.result.gamma, factor=factor, harmonics=harmonics, symmetric=symmetric,
                 points=np.array(points), notes=np.array(mv.result.notes, dtype=object))  # fmt: skip
    out["moving"] = {
        "verdict": mv.verdict,
        "status": s["status"],
        "gamma": s["gamma"],
        "gamma_on_the_search_grid": None if mv.result is None or not mv.result.proved else mv.result.gamma,
        "finer_grid": s["finer_grid"],
        "frozen_gamma": s["frozen_gamma"],
        "basis": None if mv.result is None else mv.result.n_basis,
        "grid": s["grid"],
        "rates": s["rate_words"],
        "cells": s["cells"],
        "lower": s["lower"],
        "solver_status": None if mv.result is None else mv.result.solver_status,
        "n_states": None if mv.result is None else mv.result.n_states,
        "seconds": round(time.perf_counter() - t, 1),
        "memory": peak_memory(),
    }
    if full:
        from polyrob.pipeline import analyze_controller, build_problem
        from polyrob.pipeline.problem import default_hyperparameters

        t = time.perf_counter()
        h = default_hyperparameters(robot.m, bandwidth_scale=factor)
        problem = build_problem(robot, domain, hyperparameters=h, uncertainty="lft", progress=False)
        a = analyze_controller(problem, K, mc=20, progress=False, time_varying=True, moving=False)
        out["frozen_mu"] = {"verdict": a.certificate.verdict, "bound": a.certificate.bound}
        tv = a.time_varying
        out["arbitrarily_fast"] = {"verdict": None if tv is None else tv.verdict}
        out["full_seconds"] = round(time.perf_counter() - t, 1)
    return out


def peak_memory() -> dict:
    """Peak resident memory (MB) of this process and of its largest finished child (a cell worker), and their sum
    over this process and the available cores' workers: a bound of the peak while they ran at once."""
    import resource

    from polyrob.workers import available_cores

    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux
    child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    return {"process_mb": round(own, 1), "largest_worker_mb": round(child, 1),
            "bound_mb": round(own + available_cores() * child, 1)}  # fmt: skip


def saved_search(factor: float, spec: str, path: str):
    """The search's own setting for an ``X`` a run saved (``--save-x``): ``(saved, model, system, sysf, c, basis, rates, source)``.

    The coordinates are rebuilt as :func:`~polyrob.analysis.lpv.moving.moving_robot_certificate`
    builds them (the conditioned loop at the grid's centre; the saved ``X`` lives there).
    """
    import numpy as np

    from polyrob import load_robot
    from polyrob.analysis.lpv.basis import default_basis, even_functions
    from polyrob.analysis.lpv.robot import closed_loop_system, conditioned, even_half, rate_bounds, scheduling
    from polyrob.domains.torque_box import Domain

    saved = np.load(path, allow_pickle=True)
    points, harmonics = tuple(int(x) for x in saved["points"]), int(saved["harmonics"])
    robot = load_robot("paper_2r")
    domain = Domain.from_robot(robot, "paper")
    P = _light_problem(robot, domain, factor).P
    model = scheduling(robot, domain, points=points)
    system = closed_loop_system(model, _controller(spec), P.W_S, P.W_T, P.W_KS)
    rates, source = rate_bounds(model, domain)
    basis = default_basis(model, tensor=True, harmonics=harmonics)
    if bool(saved.get("symmetric", False)):
        model = even_half(model, system)
        basis = even_functions(basis, [-a[-1] for a in model.axes], [a[-1] for a in model.axes])
    sysf, c = conditioned(system, np.array([0.5 * (a[0] + a[-1]) for a in model.axes]))
    return saved, model, system, sysf, c, basis, rates, source


def saved_x_between(factor: float, spec: str, path: str, *, recheck, cell_time_limit: float, level=None,
                    cell_workers=None, cell_level=None) -> dict:  # fmt: skip
    """The ``X`` a run saved (``--save-x``) re-checked on a finer grid (``recheck=None``: only on its own) and proved
    on cells, without searching again."""
    from types import SimpleNamespace

    import numpy as np

    from polyrob.analysis.lpv.basis import finer_recheck
    from polyrob.analysis.lpv.cells import check_cells

    saved, model, system, sysf, c, basis, rates, source = saved_search(factor, spec, path)
    points = tuple(int(x) for x in saved["points"])
    result = SimpleNamespace(proved=True, X=tuple(saved["X"]), gamma=float(saved["gamma"]))
    out = {"bandwidth_factor": factor, "controller": spec, "saved": path, "search_grid": model.words(),
           "gamma_saved": result.gamma, "rates": rates, "rates_source": source}  # fmt: skip
    t = time.perf_counter()
    out["search_grid_recheck"] = finer_recheck(sysf, model, result, rates, basis, points=points, c=c)
    if recheck is not None:
        out["finer_grid"] = finer_recheck(sysf, model, result, rates, basis, points=recheck, c=c)
    g = out["finer_grid" if recheck is not None else "search_grid_recheck"]["gamma"]
    for key in ("search_grid_recheck", "finer_grid")[: 1 + (recheck is not None)]:  # strict JSON: no bound is null
        out[key]["gamma"] = out[key]["gamma"] if np.isfinite(out[key]["gamma"]) else None
    out["recheck_seconds"] = round(time.perf_counter() - t, 1)
    if np.isfinite(g) and g < 1:
        from polyrob.analysis.lpv.robot import cells_level

        g_cells = cells_level(g, level, cell_level)
        chk = check_cells(model, system, saved["X"], basis, rates, g_cells, similarity=sysf.similarity, c=c,
                          time_limit=cell_time_limit, progress=True, workers=cell_workers)  # fmt: skip
        out["cells"] = chk.summary()
    out["lower"] = found_along_trajectories(factor, spec)
    return out


def found_along_trajectories(factor: float, spec: str) -> dict:
    """The largest gain found along admissible trajectories of the whole box (:mod:`polyrob.analysis.time_varying.trajectory_gains`)."""
    from polyrob import load_robot
    from polyrob.analysis.lpv.robot import closed_loop_system, rate_bounds, scheduling
    from polyrob.analysis.time_varying.trajectory_gains import trajectory_lower_bound
    from polyrob.domains.torque_box import Domain

    robot = load_robot("paper_2r")
    domain = Domain.from_robot(robot, "paper")
    P = _light_problem(robot, domain, factor).P
    model = scheduling(robot, domain, points=(5, 3))
    rates, _ = rate_bounds(model, domain)
    return trajectory_lower_bound(model, closed_loop_system(model, _controller(spec), P.W_S, P.W_T, P.W_KS),
                                  rates).summary()  # fmt: skip


def position_slice(factor: float, spec: str, velocity, harmonics: int, q_points: int, rate: float = 0.0) -> dict:
    """The frozen loops along ``q2`` at one velocity: how well ``X(q2)`` on ``harmonics`` harmonics fits them.

    :func:`polyrob.lpvnorm` on the loops at ``q2`` in ``q_points`` values of
    ``[-pi, pi)``, ``qdot = velocity``, with ``|dq2/dt| <= rate`` (0: every
    loop frozen; negative: ``dq2/dt = qdot2`` exactly, as in the full search) and ``X(q2)`` on ``1, cos k q2, sin k q2`` (``k <=
    harmonics``).  With rate 0 no rate bound can give less on this slice, so
    a value far above the frozen peak says the basis, not the rates, limits
    the moving-robot bound.
    """
    import numpy as np

    from polyrob import load_robot
    from polyrob.analysis.lpv.norm import lpvnorm
    from polyrob.analysis.lpv.robot import closed_loop_system, conditioned, scheduling
    from polyrob.domains.torque_box import Domain

    robot = load_robot("paper_2r")
    domain = Domain.from_robot(robot, "paper")
    P = _light_problem(robot, domain, factor).P
    model = scheduling(robot, domain, points=(q_points + 1, 2))
    system = closed_loop_system(model, _controller(spec), P.W_S, P.W_T, P.W_KS)
    v = np.asarray(velocity, float)
    sysc, c = conditioned(system, np.array([0.0, *v]))
    basis = [(lambda r: 1.0, lambda r: np.zeros(1))]
    for k in range(1, harmonics + 1):
        basis.append((lambda r, k=k: np.cos(k * r[0]), lambda r, k=k: np.array([-k * np.sin(k * r[0])])))
        basis.append((lambda r, k=k: np.sin(k * r[0]), lambda r, k=k: np.array([k * np.cos(k * r[0])])))
    t = time.perf_counter()
    rb = [(-rate / c, rate / c)] if rate >= 0 else [(v[-1] / c, v[-1] / c)]  # rate < 0: dq2/dt = qdot2 exactly
    r = lpvnorm(lambda rho: sysc(np.array([rho[0], *v])), [model.axes[0][:-1]], rb, basis, eps=1e-4)
    return {
        "bandwidth_factor": factor,
        "controller": spec,
        "qdot": v.tolist(),
        "q2_points": q_points,
        "harmonics": harmonics,
        "q2_rate_bound": rate if rate >= 0 else "dq2/dt = qdot2",
        "gamma": r.gamma if r.proved else None,
        "frozen_gamma": r.frozen_gamma,
        "solver_status": r.solver_status,
        "seconds": round(time.perf_counter() - t, 1),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", default="4:tests/fixtures/paper_2r_tf3_alpha4_K.json")
    ap.add_argument("--velocities", default="auto", choices=["auto", "bounded", "arbitrary"])
    ap.add_argument("--points", default="5,3", help="grid points per position and per velocity parameter")
    ap.add_argument("--full", action="store_true", help="also the frozen-robot mu and the arbitrarily fast verdict")
    ap.add_argument(
        "--separable", action="store_true", help="X on 1, cos q2, sin q2, qdot1, qdot2 (not the tensor basis)"
    )
    ap.add_argument(
        "--recheck", default="auto", help="finer grid the X is re-checked on ('none': not re-checked; 'auto': 4 x, 2 x)"
    )
    ap.add_argument("--slice", default=None, metavar="QDOT1,QDOT2", help="only position_slice() at this velocity")
    ap.add_argument("--harmonics", default="1", help="harmonics of X in q2 (--slice: a comma-separated list)")
    ap.add_argument("--q-points", type=int, default=12, help="--slice: points of q2 in [-pi, pi)")
    ap.add_argument(
        "--slice-rate",
        type=float,
        default=0.0,
        help="--slice: bound of |dq2/dt| (0: frozen loops; -1: dq2/dt = qdot2 exactly)",
    )
    ap.add_argument("--save-x", default=None, metavar="FILE.npz", help="save the proved X(rho) of the (last) run")
    ap.add_argument("--level", type=float, default=None, help="fix gamma there and maximise the LMIs' margin")
    ap.add_argument("--cell-level", type=float, default=None, help="the level the cells prove (default: cells_level's rule)")
    ap.add_argument("--cells", action="store_true", help="prove the X between the grid points, on cells")
    ap.add_argument("--symmetric", action="store_true", help="the half box and an even X (the loop is even in rho)")
    ap.add_argument("--cell-time-limit", type=float, default=900.0, help="seconds for --cells")
    ap.add_argument("--cell-workers", type=int, default=None, help="processes for --cells (default: the available cores)")
    ap.add_argument("--load-x", default=None, metavar="FILE.npz", help="no search: the saved X, re-checked and --cells")
    ap.add_argument("--lower-only", action="store_true", help="only the largest gain found along admissible trajectories")
    add_results_option(ap)
    args = ap.parse_args(argv)
    points = tuple(int(x) for x in args.points.split(","))
    named = {"none": None, "auto": "auto"}
    recheck = named[args.recheck] if args.recheck in named else tuple(int(x) for x in args.recheck.split(","))
    doc = {
        "problem": "paper_2r --domain paper",
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "load_average_start": list(os.getloadavg()),
        "runs": [],
    }
    for item in args.runs.split(","):
        factor, spec = item.split(":", 1)
        if args.lower_only:
            t = time.perf_counter()
            doc["runs"].append({"bandwidth_factor": float(factor), "controller": spec,
                                "lower": found_along_trajectories(float(factor), spec),
                                "seconds": round(time.perf_counter() - t, 1)})  # fmt: skip
            continue
        if args.load_x:
            doc["runs"].append(saved_x_between(float(factor), spec, args.load_x, recheck=recheck if recheck != "auto"
                               else (33, 5), cell_time_limit=args.cell_time_limit, level=args.level,
                               cell_workers=args.cell_workers, cell_level=args.cell_level))  # fmt: skip
            continue
        if args.slice:
            v = [float(x) for x in args.slice.split(",")]
            for k in args.harmonics.split(","):
                doc["runs"].append(position_slice(float(factor), spec, v, int(k), args.q_points, args.slice_rate))
            continue
        doc["runs"].append(
            run(
                float(factor),
                spec,
                velocities=args.velocities,
                points=points,
                full=args.full,
                tensor=not args.separable,
                recheck=recheck,
                harmonics=int(args.harmonics.split(",")[0]),
                save_x=args.save_x,
                level=args.level,
                cell_level=args.cell_level,
                cells=args.cells,
                cell_time_limit=args.cell_time_limit,
                symmetric=args.symmetric,
                cell_workers=args.cell_workers,
            )
        )
    doc["load_average_end"] = list(os.getloadavg())
    save_run(args.results, "moving_robot", "The moving robot's certificate", "the script's JSON in data", doc)
    print(json.dumps(doc, indent=2, allow_nan=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
