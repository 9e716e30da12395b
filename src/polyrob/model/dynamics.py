"""The state-space dynamics ``xdot = f(x, u)`` of a URDF robot and its Jacobians.

With ``x = (q, qdot)`` (the paper's eq. 3)::

    qddot = M(q)^-1 (u - C(q, qdot) qdot - g(q) - D qdot)
    A = df/dx = [[0, I], [d qddot/dq, d qddot/dqdot]]      (2m x 2m)
    B = df/du = [[0], [M(q)^-1]]                           (2m x m)

The derivatives come from Pinocchio's analytic ABA derivatives
(``computeABADerivatives``), not from finite differences.  Pinocchio's ``aba``
ignores ``model.damping``, so the damping ``D = diag(d)`` of the URDF is added
here: the acceleration is evaluated at ``tau = u - D qdot`` and ``-M^-1 D`` is
added to ``d qddot / d qdot``.

Continuous joints are stored by Pinocchio as ``(cos q, sin q)``; polyrob's
coordinate is the angle ``q`` and Pinocchio's derivatives are taken in the
tangent space, which for such a joint is exactly ``d/dq``.

Examples
--------
>>> import numpy as np
>>> from polyrob import load_robot
>>> robot = load_robot("planar_2r")
>>> A, B = robot.jacobians([0.0, 0.5], [0.0, 0.0], [0.0, 0.0])
>>> A.shape, B.shape
((4, 4), (4, 2))
>>> bool(np.allclose(B[2:], np.linalg.inv(robot.mass_matrix([0.0, 0.5]))))
True
"""

from __future__ import annotations

import numpy as np
import pinocchio

__all__ = ["to_configuration", "acceleration", "inverse_dynamics", "jacobians_batch"]


def _layout(robot):
    """Index of each joint in Pinocchio's configuration vector, and which are continuous."""
    model = robot.model
    idx_q = np.array([model.joints[i].idx_q for i in range(1, model.njoints)])
    continuous = np.array([k == "continuous" for k in robot.joint_kinds])
    return idx_q, continuous


def to_configuration(robot, q) -> np.ndarray:
    """Pinocchio configuration vector(s) for joint coordinates ``q`` (..., m)."""
    q = np.asarray(q, dtype=float)
    idx_q, continuous = _layout(robot)
    out = np.zeros(q.shape[:-1] + (robot.model.nq,))
    plain = ~continuous
    out[..., idx_q[plain]] = q[..., plain]
    out[..., idx_q[continuous]] = np.cos(q[..., continuous])
    out[..., idx_q[continuous] + 1] = np.sin(q[..., continuous])
    return out


def acceleration(robot, q, qdot, u) -> np.ndarray:
    """``qddot`` of the robot with its damping (Pinocchio's ``aba`` has none)."""
    qdot = np.asarray(qdot, dtype=float)
    tau = np.asarray(u, dtype=float) - robot.damping * qdot
    return pinocchio.aba(robot.model, robot._data, to_configuration(robot, q), qdot, tau).copy()


def inverse_dynamics(robot, q, qdot, qddot) -> np.ndarray:
    """The torques ``u`` (n, m) that give accelerations ``qddot`` at ``(q, qdot)`` (arrays (n, m)).

    ``u = rnea(q, qdot, qddot) + D qdot``: Pinocchio's recursive Newton-Euler
    (with the armature of ``model.armature``) plus the damping ``aba`` leaves out.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, m = q.shape
    qdot = np.ascontiguousarray(np.broadcast_to(np.asarray(qdot, dtype=float), (n, m)))
    qddot = np.ascontiguousarray(np.broadcast_to(np.asarray(qddot, dtype=float), (n, m)))
    model, data = robot.model, robot._data
    config = to_configuration(robot, q)
    u = np.empty((n, m))
    for k in range(n):
        u[k] = pinocchio.rnea(model, data, config[k], qdot[k], qddot[k])
    return u + robot.damping * qdot


def jacobians_batch(robot, q, qdot, u, *, blocks=False):
    """``A`` and ``B`` at ``n`` points given as arrays of shape (n, m).

    The loop over samples is the only Python-level loop: the configuration
    vectors, the damping correction and the assembly are vectorised, and each
    iteration only calls ``computeABADerivatives`` and copies its three views
    (they are overwritten by the next call) into preallocated arrays.

    Parameters
    ----------
    q, qdot, u : array_like, shape (n, m)
    blocks : bool
        Return the raw blocks ``(d qddot/dq, d qddot/dqdot, M^-1)`` of shape
        (n, m, m) each instead of the assembled ``(A, B)``.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    qdot = np.atleast_2d(np.asarray(qdot, dtype=float))
    u = np.atleast_2d(np.asarray(u, dtype=float))
    n, m = q.shape
    qdot = np.broadcast_to(qdot, (n, m))
    u = np.broadcast_to(u, (n, m))
    model, data = robot.model, robot._data
    config = to_configuration(robot, q)
    tau = np.ascontiguousarray(u - robot.damping * qdot)
    qdot = np.ascontiguousarray(qdot)
    # Write each sample straight into its place in A and B: one copy of
    # Pinocchio's views (overwritten by the next call), no later assembly.
    A = np.zeros((n, 2 * m, 2 * m))
    B = np.zeros((n, 2 * m, m))
    A[:, :m, m:] = np.eye(m)
    ddq_dq, ddq_dv, minv = A[:, m:, :m], A[:, m:, m:], B[:, m:, :]
    derivatives = pinocchio.computeABADerivatives
    for k in range(n):
        dq, dv, mi = derivatives(model, data, config[k], qdot[k], tau[k])
        ddq_dq[k] = dq
        ddq_dv[k] = dv
        minv[k] = mi
    # -M^-1 D: scale the columns of M^-1 by the damping coefficients.
    if np.any(robot.damping):
        ddq_dv -= minv * robot.damping[None, None, :]
    if blocks:
        return ddq_dq.copy(), ddq_dv.copy(), minv.copy()
    return A, B
