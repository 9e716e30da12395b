"""What unmodelled Coulomb friction asks of a joint's loop, against what its encoders allow (JSON).

    python benchmarks/friction_floor.py [ARM ...] [--results PATH]

Issue 39's bar closes each arm's controller at 1 kHz with Coulomb friction
of 2 N m per joint that the inner layer does not compensate, and asks every
run to settle *and* to keep ``|qddot|`` within the task's bound (2 rad/s^2
on the default task).  This script measures, per arm (default ur5 and
panda), on the joint with the smallest inertia at the task's start (the one
friction moves most), two things that do not depend on any controller
polyrob synthesises:

* **the friction floor**: the loop in the most favourable setting a
  controller can have -- continuous time, exact position and velocity, no
  delay, exact computed torque on that joint (its own inertia ``M_jj``,
  nothing coupled), the reference's acceleration fed forward -- and a PID on
  the error (``kp = w^2``, ``kd = 2 w``, ``ki = w^3 / k`` for ``k`` in 3, 8,
  32, the best of the three kept) on the validation's own trajectory
  (:func:`polyrob.validate.at_rate.runs.task_references`: half the way to the
  task's bound, peak velocity and acceleration half the task's) and its own
  friction (:func:`polyrob.validate.at_rate.loop.joint_friction`, viscous 1 N m
  s/rad, Coulomb 2 N m over 0.01 rad/s).  For each crossover ``w``: the peak
  ``|qddot|`` against the bound and whether the run settles in the
  validation's band (2 % of the move, held the last 0.5 s of 3 s after the
  move).  The smallest ``w`` that does both is what this loop needs.
* **the encoder ceiling**: a reading that moves by one count (``LSB =
  2 pi / 2^18``) moves ``v`` by at least ``kp LSB = w^2 LSB`` through the
  proportional term alone (the derivative term adds ``kd LSB / h`` at the
  rate ``1/h``), so above ``w = sqrt(a / LSB)`` one count alone leaves the
  acceleration bound ``a``.

When the floor lies above the ceiling, no PID closed at this rate with
these encoders meets the bar on this joint, whatever its tuning; the
figures are of this idealised single joint, a measurement, not a proof for
every controller.  Nothing here is timed by a test.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
from _results import add_results_option, save_run
from scipy.integrate import solve_ivp

DEFAULT_ARMS = ("ur5", "panda")
CROSSOVERS = (10, 20, 30, 50, 100, 150, 200, 300, 400, 500, 700, 1000, 1500)
INTEGRAL_DIVISORS = (3.0, 8.0, 32.0)


def joint_problem(arm: str) -> dict:
    """The lightest joint of ``arm`` at its default task's start, its move and the validation's conditions."""
    import polyrob
    from polyrob.domains.default_task import default_task_domain
    from polyrob.validate.at_rate.figures import SETTLED_HOLD, SETTLING_BAND
    from polyrob.validate.at_rate.loop import RealLoopConditions
    from polyrob.validate.at_rate.runs import task_references

    robot = polyrob.load_robot(arm)
    dom = default_task_domain(robot)
    q0 = np.clip(np.asarray(dom.pose, float), dom.q_lower, dom.q_upper)  # where the validation starts
    inertia = np.diag(np.asarray(robot.mass_matrix(q0), float))
    j = int(np.argmin(inertia))
    (_, _, _, _), (_, traj, t_final, move_end) = task_references(dom, q0)
    conditions = RealLoopConditions()
    move = float(traj.target[j] - q0[j])
    return {
        "arm": arm,
        "joint": j,
        "joint_name": robot.joint_names[j] if hasattr(robot, "joint_names") else str(j),
        "inertia": float(inertia[j]),
        "effort_limit": float(np.asarray(robot.effort_limit, float)[j]),
        "qddot_bound": float(max(abs(dom.qddot_lower[j]), abs(dom.qddot_upper[j]))),
        "reference": traj.bind(q0),
        "q0": float(q0[j]),
        "move": move,
        "duration": float(move_end),
        "t_final": float(t_final),
        "band_fraction": SETTLING_BAND,
        "hold": SETTLED_HOLD,
        "conditions": conditions,
    }


def ideal_run(p: dict, w: float, divisor: float) -> dict:
    """The idealised loop of the module's docstring at crossover ``w``: peak ``|qddot|``, settled or not."""
    from polyrob.validate.at_rate.loop import joint_friction

    c = p["conditions"]
    j, inertia, r_of_t = p["joint"], p["inertia"], p["reference"]
    kp, kd, ki = w**2, 2.0 * w, w**3 / divisor

    def ref(t):
        # the reference's position, velocity and acceleration on joint j (central differences of r(t))
        dt = 1e-5
        r0, rp, rm = (float(np.asarray(r_of_t(s), float)[j]) for s in (t, t + dt, t - dt))
        return r0, (rp - rm) / (2 * dt), (rp - 2 * r0 + rm) / dt**2

    def rhs(t, x):
        q, qd, z = x
        r, rd, rdd = ref(t)
        e = r - q
        v = rdd + kp * e + kd * (rd - qd) + ki * z
        tau_f = float(joint_friction(np.array([qd]), viscous=c.friction_viscous, coulomb=c.friction_coulomb,
                                     velocity_scale=c.coulomb_velocity)[0])  # fmt: skip
        return [qd, v + tau_f / inertia, e]

    step = min(2e-4, 0.2 / w)
    sol = solve_ivp(rhs, (0.0, p["t_final"]), [p["q0"], 0.0, 0.0], method="LSODA", max_step=step, rtol=1e-8,
                    atol=1e-11)  # fmt: skip
    acc = np.array([rhs(t, x)[1] for t, x in zip(sol.t, sol.y.T)])
    err = np.array([ref(t)[0] for t in sol.t]) - sol.y[0]
    band = max(p["band_fraction"] * abs(p["move"]), 2.0 * c.lsb)
    late = sol.t >= sol.t[-1] - p["hold"]
    return {
        "crossover_rad_s": w,
        "integral_divisor": divisor,
        "qddot_peak": float(np.abs(acc).max()),
        "qddot_fraction": float(np.abs(acc).max() / p["qddot_bound"]),
        "settled": bool(sol.success and np.abs(err[late]).max() <= band),
        "final_error_rad": float(abs(err[-1])),
        "band_rad": band,
    }


def measure(arm: str) -> dict:
    p = joint_problem(arm)
    rows = []
    for w in CROSSOVERS:
        runs = [ideal_run(p, float(w), k) for k in INTEGRAL_DIVISORS]
        meets = [r for r in runs if r["settled"] and r["qddot_fraction"] <= 1.0]
        settled = [r for r in runs if r["settled"]]
        best = min(meets or settled or runs, key=lambda r: r["qddot_fraction"])
        rows.append({**best, "meets": bool(meets)})
    lsb = p["conditions"].lsb
    ceiling = math.sqrt(p["qddot_bound"] / lsb)
    floor = next((r["crossover_rad_s"] for r in rows if r["meets"]), None)
    return {
        "arm": arm,
        "joint": p["joint_name"],
        "inertia_kg_m2": p["inertia"],
        "effort_limit_n_m": p["effort_limit"],
        "qddot_bound": p["qddot_bound"],
        "move_rad": p["move"],
        "duration_s": p["duration"],
        "coulomb_n_m": p["conditions"].friction_coulomb,
        "coulomb_over_inertia": p["conditions"].friction_coulomb / p["inertia"],
        "encoder_lsb_rad": lsb,
        "encoder_ceiling_rad_s": ceiling,
        "friction_floor_rad_s": floor,
        "floor_above_ceiling": floor is None or floor > ceiling,
        "runs": rows,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("arms", nargs="*", default=list(DEFAULT_ARMS))
    add_results_option(parser)
    args = parser.parse_args()
    out = {"arms": [measure(arm) for arm in args.arms]}
    print(json.dumps(out, indent=1))
    rows = []
    for a in out["arms"]:
        floor = "none up to 1500" if a["friction_floor_rad_s"] is None else f"{a['friction_floor_rad_s']:g}"
        at = {r["crossover_rad_s"]: r for r in a["runs"]}
        rows.append([
            a["arm"], a["joint"], f"{a['inertia_kg_m2']:.3g}", f"{a['coulomb_over_inertia']:.0f}",
            f"{at[100]['qddot_fraction']:.2f}" + ("" if at[100]["settled"] else " (not settled)"),
            floor, f"{a['encoder_ceiling_rad_s']:.0f}",
        ])  # fmt: skip
    table = {
        "columns": ["arm", "lightest joint", "M_jj [kg m²]", "Coulomb / M_jj [rad/s²]",
                    "ideal loop at 100 rad/s: peak q̈ / bound", "friction floor: least crossover [rad/s]",
                    "encoder ceiling √(a/LSB) [rad/s]"],
        "rows": rows,
    }  # fmt: skip
    figure = "; ".join(
        f"{a['arm']} {a['joint']}: floor "
        + ("above 1500" if a["friction_floor_rad_s"] is None else f"{a['friction_floor_rad_s']:g}")
        + f" rad/s, ceiling {a['encoder_ceiling_rad_s']:.0f} rad/s"
        for a in out["arms"]
    )
    save_run(args.results, "friction_floor", "What unmodelled Coulomb friction asks of the lightest joint's loop",
             figure, out, table)  # fmt: skip


if __name__ == "__main__":
    main()
