"""Frozen closed loops of an arm's default-task controller over true robots drawn from two sets (prints JSON).

Issue 38's measured reason: the project's certified set (one factor on all
links, a payload of 0-1 % of the arm's mass at the flange) against the set an
engineer states (each link's mass, first moment and inertia about its centre
of mass within ±10 % independently; an instrument of 0-1.5 kg whose centre of
mass lies anywhere within 0.1 m of the flange, a solid sphere of 3 cm).  The
inner layer is computed torque with the nominal links and the middle payload
(:func:`polyrob.model.inner.inner_loop`), as in the default task.

For each robot, controller and set, ``--robots-per-set`` true robots are
drawn; each one's inner loop is linearised (exact Jacobians) at rest at the
reference pose and at one point drawn uniformly from the task box
(``|q - q_ref| <= 0.2``, ``|qdot| <= 0.5``, ``|qddot| <= 2``), closed with
the controller on ``e = r - q``, and the row counts (also for the issue's
set's two halves alone: the per-link errors, the payload) the unstable loops, the
largest real part of their poles, and the mixed-sensitivity norm
``max_ω σ̄([W_S S; W_T T])`` of the stable ones (the task's automatic
weights; a stand-in for the certificate's weighted norm, not the same
channels).

The controller: ``--controller FILE`` (what ``polyrob synth ROBOT -o FILE``
writes), else stand-ins of the family :mod:`polyrob.synthesis.pid_tuning`
ranks: a per-joint PID with ``b_j = 1`` at ``ω_c = f ω_BT`` for ``f`` in
``--fractions``, ``k_i = 16``, ``n_f = 10`` (not the tuned, certified PID).

Usage::

    python benchmarks/uncertainty_set.py [--robots ur5,panda] [--robots-per-set 200] [--controller ur5=K.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "src"))

from polyrob import load_robot  # noqa: E402
from polyrob.domains.default_task import DEFAULT_TASK, default_task_domain, default_task_robot  # noqa: E402
from polyrob.fleet.autoweights import automatic_hyperparameters  # noqa: E402
from polyrob.model.inner import inner_loop  # noqa: E402
from polyrob.model.payload import PAYLOAD_RADIUS, PayloadRange  # noqa: E402
from polyrob.pipeline.problem import default_hyperparameters  # noqa: E402
from polyrob.plant.weights import paper_weights  # noqa: E402
from polyrob.synthesis.pid_tuning import pid_controller, pid_gains  # noqa: E402
from polyrob.uncertainty_set.draw import draw_true_robot  # noqa: E402
from polyrob.uncertainty_set.spec import PayloadBody, RobotUncertainty  # noqa: E402

OMEGA = np.logspace(-3, 4, 120)


def issue_set(link_error=0.10, mass=1.5, radius=0.10) -> RobotUncertainty:
    """Issue 38's default: per-link ±10 %, an instrument of 0-1.5 kg, centre of mass within 0.1 m of the flange."""
    body = PayloadBody(0.0, mass, com_radius=radius, solid="sphere", size=(PAYLOAD_RADIUS,))
    return RobotUncertainty(link_error=link_error, payload=body, source="issue 38's default task")


def closed_loop(A, B, K):
    """The frozen loop's state matrix: plant ``(A, B)``, output ``q``, ``v = K (r - q)``."""
    m = B.shape[1]
    C = np.hstack([np.eye(m), np.zeros((m, m))])
    Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
    top = np.hstack([A - B @ Dk @ C, B @ Ck])
    bottom = np.hstack([-Bk @ C, Ak])
    return np.vstack([top, bottom]), C


def responses(K, WS, WT) -> tuple:
    """``K``, ``W_S``, ``W_T`` on :data:`OMEGA`, each ``(n_omega, m, m)`` (computed once per controller)."""

    def at(sys_):
        r = np.asarray(sys_(1j * OMEGA), complex)
        return np.moveaxis(r.reshape(K.ninputs, K.ninputs, OMEGA.size), -1, 0)

    return at(K), at(WS), at(WT)


def weighted_norm(A, B, C, frequency_responses) -> float:
    """``max_ω σ̄([W_S S; W_T T])`` on :data:`OMEGA` (``S = (I + G K)^-1``)."""
    Kw, ws, wt = frequency_responses
    m, n = B.shape[1], A.shape[0]
    resolvent = (1j * OMEGA)[:, None, None] * np.eye(n)[None] - A[None]
    G = C[None] @ np.linalg.solve(resolvent, np.broadcast_to(B, (OMEGA.size, n, m)))
    S = np.linalg.inv(np.eye(m)[None] + G @ Kw)
    T = np.eye(m)[None] - S
    stacked = np.concatenate([ws @ S, wt @ T], axis=1)
    return float(np.max(np.linalg.svd(stacked, compute_uv=False)[:, 0]))


def frozen_row(loops, K, WS, WT, rng, domain, n_points: int = 1) -> dict:
    """Counts over the true inner loops ``loops`` at the reference pose at rest and at drawn task points."""
    m = K.ninputs
    frequency_responses = responses(K, WS, WT)
    unstable, worst_real, norms = 0, -np.inf, []
    total = 0
    for loop in loops:
        points = [(domain.pose, np.zeros(m), np.zeros(m))]
        for _ in range(n_points):
            points.append(tuple(rng.uniform(lo, hi) for lo, hi in _box(domain)))
        for q, qdot, qddot in points:
            v = loop.inverse_dynamics(q, qdot, qddot)[0]
            A, B = loop.jacobians_batch(q[None], qdot[None], v[None])
            Acl, C = closed_loop(A[0], B[0], K)
            real = float(np.max(np.linalg.eigvals(Acl).real))
            worst_real = max(worst_real, real)
            total += 1
            if real >= 0:
                unstable += 1
            else:
                norms.append(weighted_norm(A[0], B[0], C, frequency_responses))
    return {
        "loops": total,
        "unstable": unstable,
        "worst_pole_real_part": round(worst_real, 4),
        "weighted_norm_median": round(float(np.median(norms)), 4) if norms else None,
        "weighted_norm_worst": round(float(np.max(norms)), 4) if norms else None,
    }


def _box(domain):
    return (
        (domain.q_lower, domain.q_upper),
        (domain.qdot_lower, domain.qdot_upper),
        (domain.qddot_lower, domain.qddot_upper),
    )


def controllers_for(robot, domain, h, fractions, files):
    """``{name: (K, words)}``: the file given for this robot, else the stand-in PIDs."""
    if robot.name in files:
        import control

        from polyrob.io.controller import load_controller

        return {"file": (control.ss(load_controller(files[robot.name])), f"controller file {files[robot.name]}")}
    wbt = float(np.min(h["omega_bt"]))
    out = {}
    for f in fractions:
        wc = f * wbt
        K = pid_controller(pid_gains(wc, 16.0, 10.0, np.ones(robot.m)))
        out[f"pid_{f:g}"] = (K, f"stand-in per-joint PID, crossover {wc:.3g} rad/s ({f:g} x omega_BT {wbt:.3g})")
    return out


def measure(name: str, n: int, fractions, files, seed: int) -> dict:
    robot = load_robot(name)
    domain = default_task_domain(robot)
    h = default_hyperparameters(robot.m, automatic_hyperparameters(robot.m, domain, {}))
    WS, WT = paper_weights(h)
    rng = np.random.default_rng(seed)
    # (a) the project's set: one factor on all links, payload 0-1 % of the link mass at the flange
    common = default_task_robot(robot, DEFAULT_TASK)
    common_loops = [common.drawn(rng) for _ in range(n)]
    # (b) issue 38's set, the inner layer on the nominal links and the middle payload (0.75 kg at the flange);
    # and its two halves, to tell which one moves the loops: the links alone, the payload alone
    sets = {
        "issue_set": issue_set(),
        "issue_links_only": RobotUncertainty(link_error=0.10),
        "issue_payload_only": replace(issue_set(), link_error=None),
    }
    drawn_sets, words = {}, {}
    for key, raw in sets.items():
        spec = raw.bound(robot)
        words[key] = spec.words()
        payload = None if spec.payload is None else PayloadRange(spec.payload.mass_lower, spec.payload.mass_upper)
        model = inner_loop(robot, "computed-torque", payload=payload)
        drawn_sets[key] = []
        for _ in range(n):
            true = draw_true_robot(robot, spec, rng)
            drawn_sets[key].append(replace(model, true_robot=true.robot, scenario=true.words(), _scenarios=()))
    nominal_model = inner_loop(robot, "computed-torque").with_true(0.0, np.zeros(3), 1.0)
    rows = {}
    for key, (K, words_k) in controllers_for(robot, domain, h, fractions, files).items():
        nominal = frozen_row([nominal_model], K, WS, WT, rng, domain)
        rows[key] = {
            "controller": words_k,
            "nominal_stable": nominal["unstable"] == 0,
            "common_factor_set": frozen_row(common_loops, K, WS, WT, rng, domain),
            **{name: frozen_row(loops, K, WS, WT, rng, domain) for name, loops in drawn_sets.items()},
        }
    return {
        "robot": name,
        "true_robots_per_set": n,
        "sets": {"common_factor_set": common.words(), **words},
        "omega_bt": [round(float(x), 4) for x in h["omega_bt"]],
        "rows": rows,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", default="ur5,panda")
    ap.add_argument("--robots-per-set", type=int, default=200)
    ap.add_argument("--fractions", default="0.2,0.4,0.75", help="stand-in PID crossovers, fractions of omega_BT")
    ap.add_argument("--controller", action="append", default=[], help="ROBOT=FILE: a controller file for ROBOT")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    files = dict(item.split("=", 1) for item in args.controller)
    fractions = [float(x) for x in args.fractions.split(",") if x.strip()]
    start = time.perf_counter()
    results = [measure(r.strip(), args.robots_per_set, fractions, files, args.seed) for r in args.robots.split(",")]
    doc = {
        "benchmark": "uncertainty_set",
        "machine": f"{platform.machine()}, Python {platform.python_version()}",
        "seconds": round(time.perf_counter() - start, 1),
        "results": results,
    }
    print(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
