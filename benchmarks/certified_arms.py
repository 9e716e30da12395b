"""Proved factor ranges of the arms' computed-torque loops on their default tasks: time, boxes, width ratios.

Prints JSON, per robot (ur5, panda):

- ``proof``: :func:`polyrob.bounds.certified.factors.prove_factor_ranges` on the
  default task (the same call as ``polyrob bounds ROBOT --certify``) and on
  the task scaled by each of ``--proof-scales``, with ``--max-boxes`` of
  counted work: its time, its number of boxes and the ratios of the proved
  widths to the sampled ones (the bar is 1.10); at the work limit (status
  ``work limit: ...``), those of the ranges proved by then
  (``partial=True``: every entry enclosed, the sides not yet closed by the
  boxes where they are open) and the fraction of the work done;
- ``one_box``: the enclosure of one box around the reference pose, the
  task scaled by ``s`` (q ±0.2 s rad, qdot ±0.5 s, qddot ±2 s), against the
  sampled widths of that box, by the mean-value and slope forms alone and
  with the second-order Taylor form: how the over-estimation falls with
  the box.

"Sampled" widths: the extremes of ``--samples`` points of the box with
``qdot`` and ``qddot`` at random vertices and, for the proofs, of the
vertices :func:`~polyrob.bounds.certified.factors.vertex_ascent` visits
(attained values, a lower bound of the true width).  Ratios (:func:`polyrob.bounds.certified.factors.width_ratio.width_ratios`)
are taken on the entries whose sampled width is at least ``--floor`` of
their factor's largest entry; on the others the excess of the proved width
over the sampled one is reported relative to that scale (``excess_max``).
The sampled values are Pinocchio's floats (``FactorProblem.value_parts``),
computed apart from the proof's interval recursion, so ``outside`` (the
entries whose sampled values leave the proved interval) checks the proof:
it must read 0.

- ``inverse``: per scale of ``--scales``, the proved enclosure of
  ``M_hat(q)^-1`` over the box by each method of
  :meth:`~polyrob.bounds.certified.factors.FactorProblem.inverse_enclosure`
  (``taylor3``, the branch and bound's; ``taylor2``; ``fixed-point``, the
  earlier one): whether it proves ``M_hat`` invertible on the whole box,
  and its widths against those of Pinocchio's ``computeMinverse`` at
  ``--samples`` points of the box (``width_ratios`` with a floor of
  :data:`INVERSE_FLOOR`: ``M_hat^-1``'s entries span four decades, and an
  entry far below the largest still varies);
- ``hessian``: per scale of ``--scales``, the factors' Hessian in ``(q, qdot)``
  (at ``a = 0``) over the box, by
  :func:`~polyrob.bounds.certified.factors.hessian.hessian_enclosure`
  (``taylor-model``, the Taylor form's since issue 41's Taylor models;
  ``balls``, the earlier ball jets over the box): the largest radius, the
  entry where the balls' is largest (both radii and the spread of the
  second differences sampled there), the median ratio of the two radii,
  and whether both hold the second differences (step 1e-4) at a few points;
- ``wrapping`` (at the scale ``--wrapping-scale``): the radius of the
  mean-value form's interval gradient per unit of the box's half-width
  (the second-derivative bound that form uses: max and median over the
  entries and coordinates) against the largest second difference of the
  factors in ``q`` sampled at 16 points of the box (step 1e-4): how much of
  the over-estimation is the ball arithmetic's, not the function's.

- ``corners`` (``--corner-scales``, ``--corners`` random corners of the
  task): what the branch and bound must reach where the entries' extremes
  lie.  A sub-box at a corner of the task, each coordinate's range shrunk
  to the fraction ``s`` of it at that end, is enclosed with the Taylor
  form; a side of an entry is still open there when its bound exceeds the
  whole task's attained value (``--samples`` points and the vertex
  ascent) by more than the proof's tolerance (``REL_TOL`` of the entry's
  width, floored at ``--floor`` of its factor's scale, as
  :func:`~polyrob.bounds.certified.factors.prove_factor_ranges` closes
  it).  Per scale: the open sides (the most over the corners), the worst
  excess in tolerances, and that entry (factor, row, column) with whether
  it is thin (below the floor).

Usage: ``python benchmarks/certified_arms.py [--robots ur5,panda] [--max-boxes N] [--workers N] [--samples N] [--floor F]
[--scales 1,0.25,0.05,0.01] [--proof-scales 1,0.05] [--corner-scales 0.25,0.1,0.05,0.02] [--corners 3]``
(an empty list skips that part).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
import pinocchio as pin
from _results import add_results_option, save_run

from polyrob import load_robot
from polyrob.bounds.certified.factors import (
    MAX_BOXES,
    REL_TOL,
    FactorProblem,
    attained_range,
    prove_factor_ranges,
    vertex_ascent,
)
from polyrob.bounds.certified.factors.hessian import hessian_enclosure
from polyrob.bounds.certified.factors.width_ratio import FLOOR, closing_tolerance, width_ratios
from polyrob.bounds.parallel import available_cores
from polyrob.domains.default_task import default_task_domain, default_task_robot
from polyrob.errors import CertificationError
from polyrob.plant.models.inner_factors import factor_parameters


def wrapping(problem, box, rng) -> dict:
    """The mean-value form's second-derivative bound against sampled second differences in ``q``."""
    m, r = problem.m, 0.5 * (box.q_upper - box.q_lower)
    mid, rad = problem.interval_gradient(box.q_lower[None], box.q_upper[None], box.qdot_lower[None],
                                         box.qdot_upper[None])  # fmt: skip
    per_r = rad[:m, 0] / r.max()
    h, E, largest = 1e-4, np.eye(m), 0.0
    for _ in range(16):
        q0 = rng.uniform(box.q_lower, box.q_upper)
        v0 = np.zeros((1, m))
        for p in range(m):
            for k in range(p, m):
                pts = np.array([q0 + h * (sp * E[p] + sk * E[k]) for sp, sk in ((1, 1), (1, -1), (-1, 1), (-1, -1))])
                K = problem.values(pts, np.repeat(v0, 4, 0), np.zeros((4, m)))
                largest = max(largest, float(np.abs(K[0] - K[1] - K[2] + K[3]).max() / (4 * h * h)))
    return {"gradient_radius_per_r_max": float(per_r.max()), "gradient_radius_per_r_median": float(np.median(per_r)),
            "sampled_second_difference_max": largest}  # fmt: skip


def hessian_widths(problem, box, rng, points: int = 6, step: float = 1e-4) -> dict:
    """The factors' Hessian over the box (at ``a = 0``) by each method against second differences at random points."""
    m, n = problem.m, 2 * problem.m
    args = (box.q_lower[None], box.q_upper[None], box.qdot_lower[None], box.qdot_upper[None])
    E, lo, hi = np.eye(n), None, None
    for _ in range(points):
        x0 = np.concatenate([rng.uniform(box.q_lower, box.q_upper), rng.uniform(box.qdot_lower, box.qdot_upper)])
        pts = np.array([x0 + step * (sp * E[p] + sl * E[k]) for p in range(n) for k in range(n)
                        for sp, sl in ((1, 1), (1, -1), (-1, 1), (-1, -1))])  # fmt: skip
        K = problem.values(pts[:, :m], pts[:, m:], np.zeros((len(pts), m))).reshape(n, n, 4, -1)
        H = (K[:, :, 0] - K[:, :, 1] - K[:, :, 2] + K[:, :, 3]) / (4 * step * step)
        lo, hi = (H, H) if lo is None else (np.minimum(lo, H), np.maximum(hi, H))
    out, radii = {"sampled_spread_max": float((hi - lo).max()), "points": points}, {}
    for method in ("balls", "taylor-model"):
        t0 = time.perf_counter()
        mid, rad = hessian_enclosure(problem, *args, method=method)
        seconds = time.perf_counter() - t0
        mid, rad = mid[:, :, 0].reshape(n, n, -1), rad[:, :, 0].reshape(n, n, -1)
        radii[method] = rad
        out[method] = {"radius_max": float(rad.max()), "holds_samples": bool(np.all((lo >= mid - rad - 1e-4 * (1 + np.abs(lo)))
                       & (hi <= mid + rad + 1e-4 * (1 + np.abs(hi))))), "seconds": round(seconds, 2)}  # fmt: skip
    worst = np.unravel_index(np.argmax(radii["balls"]), radii["balls"].shape)
    live = radii["balls"] > 1e-9
    out["worst_entry"] = {"balls": float(radii["balls"][worst]), "taylor_model": float(radii["taylor-model"][worst]),
                          "sampled_spread": float((hi - lo)[worst])}  # fmt: skip
    out["radius_ratio_median"] = float(np.median(radii["balls"][live] / radii["taylor-model"][live]))
    return out


def corner_boxes(problem, domain, rng, scales, corners, samples, floor) -> list:
    """Open sides at sub-boxes of ``domain``'s corners against the whole task's attained values (module text)."""
    m = problem.m
    a_lo, a_hi = domain.qddot_lower, domain.qddot_upper
    x_lo, x_hi = np.r_[domain.q_lower, domain.qdot_lower], np.r_[domain.q_upper, domain.qdot_upper]
    p_lo, p_hi = attained_range(problem, domain.q_lower, domain.q_upper, domain.qdot_lower, domain.qdot_upper,
                                a_lo, a_hi, samples, rng)  # fmt: skip
    v_lo, v_hi = vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi)
    p_lo, p_hi = np.minimum(p_lo, v_lo), np.maximum(p_hi, v_hi)
    tol = closing_tolerance(p_lo, p_hi, REL_TOL, floor)
    factor_scale = np.maximum(np.abs(p_lo), np.abs(p_hi)).max(axis=(1, 2), keepdims=True)
    thin = p_hi - p_lo < floor * factor_scale
    picks = [rng.integers(0, 2, 2 * m).astype(bool) for _ in range(corners)]
    out = []
    for s in scales:
        row = {"scale": s, "open_sides_max": 0, "worst_excess": 0.0}
        for at_upper in picks:
            lo_b = np.where(at_upper, x_hi - s * (x_hi - x_lo), x_lo)
            hi_b = np.where(at_upper, x_hi, x_lo + s * (x_hi - x_lo))
            lo, hi, _ = problem.enclose(lo_b[None, :m], hi_b[None, :m], lo_b[None, m:], hi_b[None, m:], a_lo, a_hi,
                                        taylor=True)  # fmt: skip
            excess = np.maximum((hi[0] - p_hi) / tol, (p_lo - lo[0]) / tol)
            row["open_sides_max"] = max(
                row["open_sides_max"], int((hi[0] - p_hi > tol).sum() + (p_lo - lo[0] > tol).sum())
            )
            if excess.max() > row["worst_excess"]:
                worst = np.unravel_index(np.argmax(excess), excess.shape)
                row.update(worst_excess=round(float(excess.max()), 3), worst_entry=[int(k) for k in worst],
                           worst_entry_thin=bool(thin[worst]))  # fmt: skip
        out.append(row)
    return out


#: Entries of ``M_hat^-1`` whose sampled width is below this fraction of its largest entry are judged by their excess.
INVERSE_FLOOR = 1e-6


def inverse_widths(problem, model, box, samples, rng, floor=INVERSE_FLOOR) -> dict:
    """Each method's enclosure of ``M_hat^-1`` on the box against sampled inverses (Pinocchio)."""
    data = model.createData()
    Y = []
    for q in rng.uniform(box.q_lower, box.q_upper, (samples, problem.m)):
        pin.computeMinverse(model, data, q)
        Y.append(np.triu(data.Minv) + np.triu(data.Minv, 1).T)
    Y = np.array(Y)
    out = {}
    for method in ("taylor3", "taylor2", "fixed-point"):
        mid, rad, proved = problem.inverse_enclosure(box.q_lower[None], box.q_upper[None], method)
        out[method] = {"proved": bool(proved[0])}
        if proved[0]:
            lo, hi = (mid - rad)[:, None], (mid + rad)[:, None]
            out[method]["holds_samples"] = bool(np.all((Y >= lo[0, 0]) & (Y <= hi[0, 0])))
            out[method].update(width_ratios(lo[0], hi[0], Y.min(0)[None], Y.max(0)[None], floor))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="ur5,panda")
    parser.add_argument("--max-boxes", type=int, default=MAX_BOXES)
    parser.add_argument("--samples", type=int, default=4000)
    parser.add_argument("--scales", default="1,0.25,0.05,0.01")
    parser.add_argument("--floor", type=float, default=FLOOR)
    parser.add_argument("--wrapping-scale", type=float, default=0.01)
    parser.add_argument("--proof-scales", default="1", help="task scales the branch and bound is run on (1: the task)")
    parser.add_argument("--corner-scales", default="", help="sub-box sizes at the task's corners (fractions of it)")
    parser.add_argument("--corners", type=int, default=3, help="random corners of the task for --corner-scales")
    parser.add_argument("--workers", type=int, default=None, help="processes the proof's boxes are shared among "
                        "(default: the cores, as `polyrob bounds --certify`)")  # fmt: skip
    add_results_option(parser)
    args = parser.parse_args()
    workers = args.workers or available_cores()
    out = {"machine": f"{os.cpu_count()} cores", "workers": workers, "load_average": os.getloadavg()[0], "robots": {}}
    for name in args.robots.split(","):
        robot = load_robot(name)
        loops = [(n, loop) for n, _, loop in factor_parameters(default_task_robot(robot))]
        domain = default_task_domain(robot)
        problem = FactorProblem.from_loops(loops)
        row = {"joints": robot.m, "factors": [n for n, _ in loops], "one_box": [], "inverse": [], "hessian": []}
        model_robot = loops[0][1].model_robot
        row["wrapping"] = wrapping(problem, domain.scaled(args.wrapping_scale), np.random.default_rng(2))
        row["wrapping"]["scale"] = args.wrapping_scale
        for s in [float(x) for x in args.scales.split(",") if x]:
            box = domain.scaled(s)
            inv = inverse_widths(problem, model_robot.model, box, args.samples, np.random.default_rng(3))
            row["inverse"].append({"scale": s, **inv})
            row["hessian"].append({"scale": s, **hessian_widths(problem, box, np.random.default_rng(5))})
            s_lo, s_hi = attained_range(
                problem, box.q_lower, box.q_upper, box.qdot_lower, box.qdot_upper, box.qddot_lower,
                box.qddot_upper, args.samples, np.random.default_rng(1))  # fmt: skip
            entry = {"scale": s}
            for form, taylor in (("mean_value_and_slope", False), ("taylor", True)):
                t0 = time.perf_counter()
                lo, hi, _ = problem.enclose(box.q_lower[None], box.q_upper[None], box.qdot_lower[None],
                                            box.qdot_upper[None], box.qddot_lower, box.qddot_upper, taylor=taylor)  # fmt: skip
                entry[form] = {"seconds": round(time.perf_counter() - t0, 3)}
                if np.all(np.isfinite(hi)):
                    entry[form].update(width_ratios(lo[0], hi[0], s_lo, s_hi, args.floor))
                else:
                    entry[form]["note"] = (
                        "M_hat not provably invertible on the whole box: no enclosure without splitting"
                    )
            row["one_box"].append(entry)
        corner_scales = [float(x) for x in args.corner_scales.split(",") if x]
        if corner_scales:
            row["corners"] = corner_boxes(problem, domain, np.random.default_rng(4), corner_scales, args.corners,
                                          args.samples, args.floor)  # fmt: skip
        row["proof"] = []
        for s in [float(x) for x in args.proof_scales.split(",") if x]:
            box = domain.scaled(s)
            t0 = time.perf_counter()
            try:  # at the work limit, what is proved by then (every entry enclosed, not yet within the tolerance)
                enc = prove_factor_ranges(loops, box, max_boxes=args.max_boxes, workers=workers, partial=True)
                s_lo, s_hi = attained_range(
                    problem, box.q_lower, box.q_upper, box.qdot_lower, box.qdot_upper,
                    box.qddot_lower, box.qddot_upper, args.samples, np.random.default_rng(1))  # fmt: skip
                x_lo, x_hi = np.r_[box.q_lower, box.qdot_lower], np.r_[box.q_upper, box.qdot_upper]
                v_lo, v_hi = vertex_ascent(problem, x_lo, x_hi, box.qddot_lower, box.qddot_upper)
                s_lo, s_hi = np.minimum(s_lo, v_lo), np.maximum(s_hi, v_hi)
                status = "proved" if enc.done == 1.0 else "work limit: the ranges proved by then"
                row["proof"].append({"scale": s, "status": status, "boxes": enc.boxes, "seconds": round(enc.seconds, 1),
                                     "done": round(enc.done, 4),
                                     "ratio": width_ratios(enc.lower, enc.upper, s_lo, s_hi, args.floor)})  # fmt: skip
            except CertificationError as exc:
                row["proof"].append({"scale": s, "status": "gave up", "seconds": round(time.perf_counter() - t0, 1),
                                     "message": str(exc)})  # fmt: skip
        out["robots"][name] = row
    out["load_average_end"] = os.getloadavg()[0]
    print(json.dumps(out, indent=1))
    figure = "; ".join(
        f"{n} at scale {p['scale']:g}: {p['status']} in {p['seconds']} s"
        for n, r in out["robots"].items()
        for p in r["proof"]
    )
    save_run(args.results, "certified_arms", "proved factor ranges of the arms' default tasks", figure, out)


if __name__ == "__main__":
    main()
