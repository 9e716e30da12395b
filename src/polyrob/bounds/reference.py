"""Floating-point reference Jacobians from Pinocchio, in the certified bounds' conventions.

The branch and bound of :mod:`polyrob.bounds.certified.enclosure` steers its search by
values attained at evaluated points (they never enter the enclosure).
"""

from __future__ import annotations

import numpy as np

__all__ = ["reference_jacobians", "pinocchio_configuration"]


def pinocchio_configuration(model, q):
    import pinocchio as pin

    qp = pin.neutral(model)
    for i in range(1, model.njoints):
        j = model.joints[i]
        if j.nq == 2:  # continuous joint: (cos, sin) of the angle
            qp[j.idx_q], qp[j.idx_q + 1] = np.cos(q[j.idx_v]), np.sin(q[j.idx_v])
        else:
            qp[j.idx_q] = q[j.idx_v]
    return qp


def reference_jacobians(model, damping, q, qdot, u, data=None):
    """Floating-point ``(A, B)`` at one point, from Pinocchio's ABA derivatives.

    Parameters
    ----------
    model : pinocchio.Model
    damping : array_like, shape (m,)
    q, qdot, u : array_like, shape (m,)
        Joint coordinates (angles for continuous joints), velocities, torques.
    data : pinocchio.Data, optional
        Reused if given.

    Returns
    -------
    A : numpy.ndarray, shape (2m, 2m)
    B : numpy.ndarray, shape (2m, m)

    Examples
    --------
    >>> import pinocchio as pin
    >>> model = pin.buildModelFromUrdf("urdf/planar_2r.urdf")
    >>> A, B = reference_jacobians(model, [0, 0], [0, 3.14159], [0, 0], [0, 0])
    >>> A.shape, B.shape
    ((4, 4), (4, 2))
    >>> float(round(B[2, 0], 4))
    0.0312
    """
    import pinocchio as pin

    data = model.createData() if data is None else data
    m = model.nv
    d = np.asarray(damping, dtype=float)
    qd = np.asarray(qdot, dtype=float)
    # the torque Pinocchio sees is u - D qd; D qd does not depend on q
    res = pin.computeABADerivatives(model, data, pinocchio_configuration(model, q), qd, np.asarray(u, float) - d * qd)
    dq, dv, Minv = (np.array(x) for x in res)  # copies: Pinocchio returns views into data
    Minv = np.triu(Minv) + np.triu(Minv, 1).T
    A = np.zeros((2 * m, 2 * m))
    A[:m, m:] = np.eye(m)
    A[m:, :m] = dq
    A[m:, m:] = dv - Minv * d[None, :]
    B = np.zeros((2 * m, m))
    B[m:] = Minv
    return A, B
