"""Step-response figures of a closed-loop simulation, and its domain check.

:func:`step_metrics` gives per joint the rise time, overshoot, settling time,
steady-state error and peak torque (:class:`JointMetrics`);
:func:`domain_check` says what left the PLDI's domain and when.  Both are
used by :func:`polyrob.validate.simulate.simulate`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SETTLING_BAND", "DOMAIN_RTOL", "JointMetrics", "step_metrics", "domain_check"]

#: Band of the settling time (fraction of the step).
SETTLING_BAND = 0.02
#: Relative tolerance of the domain check (a point on the boundary is inside).
DOMAIN_RTOL = 1e-9


@dataclass(frozen=True)
class JointMetrics:
    """Step-response figures of one joint (NaN where they do not apply).

    ``rise_time`` 10-90 % of the step, ``overshoot`` in % of the step,
    ``settling_time`` into a 2 % band that is not left again,
    ``steady_state_error`` ``|r - q|`` at the end, ``peak_torque`` ``max |u|``,
    ``effort_limit`` from the robot (NaN if none), ``max_tracking_error``.
    """

    joint: str
    step: float
    rise_time: float
    overshoot: float
    settling_time: float
    steady_state_error: float
    max_tracking_error: float
    peak_torque: float
    effort_limit: float

    @property
    def torque_within_limit(self) -> bool:
        return bool(not np.isfinite(self.effort_limit) or self.peak_torque <= self.effort_limit)


def step_metrics(robot, t, q, r, u, q0) -> tuple:
    """Per joint :class:`JointMetrics` of a simulated move from ``q0`` to the reference's final value.

    Written here rather than with python-control's ``step_info`` (which gives
    the same rise, overshoot and 2 % settling figures on a full response)
    because ``step_info`` raises ``IndexError`` on a response that never
    reaches 90 % of its step, as a simulation cut by its time budget does;
    here those figures are NaN.
    """
    out = []
    tail = max(1, len(t) // 50)
    for j, name in enumerate(robot.joint_names):
        target = r[j, -1]
        step = float(target - q0[j])
        err = np.abs(r[j] - q[j])
        sse = float(np.mean(err[-tail:]))
        rise = overshoot = settle = float("nan")
        if abs(step) > 1e-12:
            frac = (q[j] - q0[j]) / step
            i10 = np.flatnonzero(frac >= 0.1)
            i90 = np.flatnonzero(frac >= 0.9)
            if i10.size and i90.size:
                rise = float(t[i90[0]] - t[i10[0]])
            overshoot = float(max(0.0, 100.0 * (frac.max() - 1.0)))
            outside = np.flatnonzero(np.abs(q[j] - target) > SETTLING_BAND * abs(step))
            if not outside.size:
                settle = 0.0
            elif outside[-1] < len(t) - 1:
                settle = float(t[outside[-1] + 1])
        out.append(
            JointMetrics(
                joint=name,
                step=step,
                rise_time=rise,
                overshoot=overshoot,
                settling_time=settle,
                steady_state_error=sse,
                max_tracking_error=float(err.max()),
                peak_torque=float(np.abs(u[j]).max()),
                effort_limit=float(robot.effort_limit[j]),
            )
        )
    return tuple(out)


def domain_check(domain, robot, t, q, qdot, u):
    """What left the domain and when: ``(exits, first time, fraction of samples outside)``; arrays (m, T).

    A task domain (``domain.kind == "task"``) bounds the accelerations, not
    the torques: ``qddot`` of the robot at ``(q, qdot, u)`` is checked instead of ``u``.
    """
    z = {"q": q, "qdot": qdot, "u": u}
    groups = ("q", "qdot", "u")
    if getattr(domain, "kind", "box") == "task":
        z["qddot"] = np.array([robot.acceleration(q[:, k], qdot[:, k], u[:, k]) for k in range(len(t))]).T
        groups = ("q", "qdot", "qddot")
    exits, bad_any, first = [], np.zeros(len(t), bool), None
    for group in groups:
        lo, hi = getattr(domain, f"{group}_lower"), getattr(domain, f"{group}_upper")
        for j, name in enumerate(robot.joint_names):
            tol = DOMAIN_RTOL * (1.0 + max(abs(lo[j]), abs(hi[j])))
            bad = (z[group][j] < lo[j] - tol) | (z[group][j] > hi[j] + tol)
            if bad.any():
                k = int(np.argmax(bad))
                peak = float(z[group][j][bad][np.argmax(np.abs(z[group][j][bad]))])
                exits.append(f"{group}[{name}] = {peak:.4g} outside [{lo[j]:.4g}, {hi[j]:.4g}] from t = {t[k]:.4g} s")
                first = float(t[k]) if first is None else min(first, float(t[k]))
                bad_any |= bad
    return tuple(exits), first, float(bad_any.mean())
