"""Which of the task's coordinates lift a per-link set's frozen μ: the model over sub-boxes of the task, as JSON.

    python benchmarks/motion_share.py CONTROLLER.json [--robot-uncertainty FILE|default] [--link-error 10]
        [--payload-max 0] [--com-radius 0.1] [--rad-s 79] [--cases "q=0;q.4=0;..."]

For the controller file's robot, task and weights (as ``polyrob synth -o``
writes them) this builds the ``inner-links-moving`` model
(:mod:`polyrob.plant.moving_links`: the link scalars exact at the task's
centre, the instrument's part its exact LFT, the motion over the task in
two full blocks) over the whole task and over sub-boxes of it, each
centred where the task is, and prints μ's bounds (descent's D-G upper
bound and the power iteration's lower bound) of the robust-performance
loop, every block constant (the model's frozen figure), at one frequency.

A case is a list of ``GROUP[.JOINT]=FACTOR`` separated by commas, the
cases by semicolons: ``q.4=0`` fixes joint 4's position at the centre
(index from 0), ``qdot=0.5`` halves every velocity range, ``q=0,qdot=0,
qddot=0`` is the task's centre alone (the exact model there); the items
apply in order, and a range fixed stays fixed (``q.4=0,q=0.5``: joint 4's
position fixed, the others' halved).  The item ``first=q`` (or ``first=x``)
takes the motion's first-order part in the positions (or in the whole
state: positions, velocities, accelerations) out of the motion blocks, each
sample's ``sum_i (x_i - c_i) dK/dx_i`` at the centre (central differences
of the unit factors), and carries it nowhere: what a model carrying that
part exactly (an LFT first-order in the state) could reach at best, since
its own blocks would add to μ; a what-if, a bound of no set.  The
default cases are the whole task, each joint's position fixed in turn,
the velocities fixed, the accelerations fixed, and the centre.

Grid figures at one frequency, not certificates: they say which
coordinates' ranges the model's motion blocks pay for, where a true robot
at each point pays for its own point only.
"""

from __future__ import annotations

import argparse
import json
import time

from _results import add_results_option, save_run
from _sets import add_set_options, controller_problem, pldi_stand_in

#: A range fixed "at the centre" keeps this half-width (the sampled model needs a box, not a point).
POINT = 1e-6


def sub_task(domain, robot, case: str):
    """The task domain with the ranges of ``case`` (``GROUP[.JOINT]=FACTOR,...``) scaled about their centres."""
    from polyrob.domains.task import TaskDomain

    data = json.loads(json.dumps(domain.to_dict()))
    joints = data["joints"]
    for item in (x.strip() for x in case.split(",") if x.strip()):
        target, _, factor = item.partition("=")
        if target == "first":
            continue
        group, _, joint = target.partition(".")
        if group not in ("q", "qdot", "qddot") or not factor:
            raise SystemExit(f"case {item!r}: expected GROUP[.JOINT]=FACTOR with GROUP q, qdot or qddot")
        for k, name in enumerate(joints):
            if joint and int(joint) != k:
                continue
            lo, hi = data[group][name]
            centre, half = (lo + hi) / 2, max((hi - lo) / 2 * float(factor), POINT)
            data[group][name] = [centre - half, centre + half]
    return TaskDomain.from_dict(data, robot=robot)


def first_order_removed(case: str):
    """A context in which ``inner_links.set_factors`` returns the samples' factors less their first-order part (module text).

    ``case``'s ``first=q`` or ``first=x`` item says which coordinates; none:
    the factors as they are.
    """
    import contextlib
    from dataclasses import replace
    from unittest import mock

    import numpy as np

    from polyrob.plant.models import inner_links as links
    from polyrob.plant.moving_links import task_centre

    which = [x.strip()[6:] for x in case.split(",") if x.strip().startswith("first=")]
    if not which:
        return contextlib.nullcontext()
    if which[-1] not in ("q", "x"):
        raise SystemExit(f"case {case!r}: first= takes q or x")
    original = links.set_factors

    def without_first_order(pldi, robot, **options):
        f = original(pldi, robot, **options)
        samples = links.model_samples(pldi.domain, options.get("samples", 256))
        centre = task_centre(pldi.domain)
        W, W_inv = f.W, np.linalg.inv(f.W)
        part = np.zeros_like(f.Phi)
        for g in range(3 if which[-1] == "x" else 1):  # q, qdot, a
            for i in range(robot.m):
                step = [np.zeros_like(c) for c in centre]
                step[g][0, i] = 1e-4
                up = links.unit_factors(robot, f.scalars, *(c + s for c, s in zip(centre, step)))
                down = links.unit_factors(robot, f.scalars, *(c - s for c, s in zip(centre, step)))
                slope = links.weighted_factor(up - down, W, W_inv)[:, 0] / 2e-4  # (N, m, 3m)
                part += (samples[g][:, i] - centre[g][0, i])[None, :, None, None] * slope[:, None]
        return replace(f, Phi=f.Phi - part)

    # patched here, not a keyword of moving_links_plant: a what-if of this benchmark, no model polyrob offers
    return mock.patch.object(links, "set_factors", without_first_order)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("controller", help="a controller file as `polyrob synth -o` writes it (an inner-links problem)")
    add_set_options(ap, payload_max=0.0)
    ap.add_argument("--rad-s", type=float, default=79.0, help="the frequency (rad/s; default 79)")
    ap.add_argument("--cases", default=None, help="cases separated by ';' (default: the module text's)")
    add_results_option(ap)
    args = ap.parse_args()

    import numpy as np

    from polyrob._threads import single_blas_thread
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.loops import lft
    from polyrob.plant.moving_links import moving_links_plant

    t0 = time.perf_counter()
    robot, loop, domain, weights, K, _ = controller_problem(args, args.controller)
    m = loop.m
    cases = args.cases.split(";") if args.cases is not None else (
        [""] + [f"q.{k}=0" for k in range(m)] + ["qdot=0", "qddot=0", "q=0,qdot=0,qddot=0"])  # fmt: skip
    rows = []
    for case in cases:
        t1 = time.perf_counter()
        pldi = pldi_stand_in(loop, sub_task(domain, loop, case))
        with first_order_removed(case):
            P = generalized_plant(moving_links_plant(pldi, loop, exact=True, exact_payload=True), **weights)
        N = lft(P.system, K, n_u=P.n_u, n_y=P.n_u)
        H = matrix_response(*(np.asarray(X, float) for X in (N.A, N.B, N.C, N.D)))(np.array([args.rad_s]))[0]
        with single_blas_thread():
            mu = mussv(H, P.block_structure_rp, method="gradient")
        row = {"case": case or "whole task", "lower": round(float(mu.lower), 4), "upper": round(float(mu.upper), 4),
               "seconds": round(time.perf_counter() - t1, 1)}  # fmt: skip
        print(json.dumps(row), flush=True)
        rows.append(row)
    out = {
        "controller": args.controller,
        "robot": robot.name,
        "set": loop.uncertainty.words(),
        "rad_s": args.rad_s,
        "grid": f"one frequency, {args.rad_s:g} rad/s (a grid figure, not a certificate)",
        "rows": rows,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(out, indent=1))
    table = {
        "columns": ["ranges (fixed at the centre: =0)", "μ lower", "μ upper (D-G)"],
        "rows": [[r["case"], f"{r['lower']:.3f}", f"{r['upper']:.3f}"] for r in rows],
    }
    whole = rows[0]["upper"] if rows else float("nan")
    figure = f"the whole task's upper bound {whole:.4g} at {args.rad_s:g} rad/s; lowest case {min(r['upper'] for r in rows):.4g}"
    save_run(args.results, "motion_share", f"{robot.name}: which ranges lift the frozen μ", figure, out, table)


if __name__ == "__main__":
    main()
