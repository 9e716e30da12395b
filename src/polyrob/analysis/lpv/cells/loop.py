"""What every cell test shares: the loop as an affine function of the robot's Jacobians, their enclosures, the accelerations.

Examples
--------
>>> import numpy as np
>>> spectral_norms(np.array([np.eye(2), 3 * np.eye(2)])).tolist()
[1.0, 3.0]
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "AffineLoop",
    "PlantEnclosure",
    "TaskPlantEnclosure",
    "plant_enclosure",
    "derivative_columns",
    "spectral_norms",
    "symmetric_norms",
    "acceleration_check",
]


def plant_enclosure(model, order: int = 2):
    """``(lo, hi) box of rho -> enclosure`` of the robot's ``A, B, qddot`` over it, or ``None`` when unavailable.

    An analytic robot's own callables; a URDF robot of at most three joints through its exact polynomials
    (:class:`~polyrob.bounds.certified.symbolic_rbd.SymbolicTwin`); none for larger ones.

    ``order=3`` adds the second derivatives of ``A`` and ``B`` (what a second-order cell test needs).
    """
    from polyrob.errors import NotApplicable
    from polyrob.model.analytic import AnalyticRobot

    dynamics = model.robot
    if not isinstance(dynamics, AnalyticRobot):
        from polyrob.bounds.certified.symbolic_rbd import SymbolicTwin

        try:  # a URDF chain of at most three joints: its dynamics as exact polynomials
            dynamics = SymbolicTwin(model.robot)
        except NotApplicable:
            return None
    if hasattr(model, "motion"):  # a task: the torque is the inverse dynamics of (q, qdot, qddot)
        return TaskPlantEnclosure(model, order, dynamics)
    return PlantEnclosure(model, order, dynamics)


def derivative_columns(model) -> list[int]:
    """Per parameter ``rho_i``, its column in the enclosure's derivative axis: ``x = (q, qdot)``, and on a task
    ``z = (q, qdot, qddot)`` (:func:`~polyrob.bounds.certified.analytic.task_jacobian_enclosure`)."""
    offset = {"q": 0, "qdot": 1, "qddot": 2}
    return [offset[kind] * model.robot.m + j for kind, j in zip(model.kinds, model.joints)]


class PlantEnclosure:
    """``enclose(lo, hi, order)`` of :func:`plant_enclosure` (a class, not a closure: the cells' workers pickle it)."""

    def __init__(self, model, order: int = 2, dynamics=None):
        self.model, self.order = model, order
        self.dynamics = model.robot if dynamics is None else dynamics  # the robot, or its polynomial twin

    def __call__(self, lo, hi, order=None):
        from polyrob.bounds.certified.analytic import analytic_jacobian_enclosure

        (ql, vl), (qh, vh) = self.model.state(lo), self.model.state(hi)
        return analytic_jacobian_enclosure(self.dynamics, ql, qh, vl, vh, self.model.u,
                                           order=self.order if order is None else order)  # fmt: skip


class TaskPlantEnclosure:
    """``enclose(lo, hi, order)`` of a task model (:mod:`polyrob.analysis.lpv.task`): the robot's ``A, B`` over the
    box of ``rho = (q_i, qdot, qddot)``, derivatives with respect to ``(q, qdot, qddot)``; picklable."""

    def __init__(self, model, order: int = 2, dynamics=None):
        self.model, self.order = model, order
        self.dynamics = model.robot if dynamics is None else dynamics

    def __call__(self, lo, hi, order=None):
        from polyrob.bounds.certified.analytic import task_jacobian_enclosure

        (ql, vl, al), (qh, vh, ah) = self.model.motion(lo), self.model.motion(hi)
        return task_jacobian_enclosure(self.dynamics, ql, qh, vl, vh, al, ah,
                                       order=self.order if order is None else order)  # fmt: skip


class AffineLoop:
    """The time-scaled, balanced closed loop as an affine function of the robot's varying ``(A, B)`` entries.

    ``c`` and the balancing ``sc`` are powers of two: the loop's matrices are exact images of the robot's.
    """

    def __init__(self, of_plant, c, sc, A0, B0):
        self.c, self.sc = c, sc
        base = self._cond(*of_plant(A0, B0))
        m2 = A0.shape[0]
        m = m2 // 2
        self.entries = [("A", i, j) for i in range(m, m2) for j in range(m2)] + [
            ("B", i, j) for i in range(m, m2) for j in range(B0.shape[1])
        ]
        G = []
        for kind, i, j in self.entries:
            A1, B1 = A0.copy(), B0.copy()
            (A1 if kind == "A" else B1)[i, j] += 1.0
            one = self._cond(*of_plant(A1, B1))
            A2, B2 = A0.copy(), B0.copy()
            (A2 if kind == "A" else B2)[i, j] += 2.0
            two = self._cond(*of_plant(A2, B2))
            d1 = [x - y for x, y in zip(one, base)]
            d2 = [x - y for x, y in zip(two, base)]
            if any(np.abs(b - 2 * a).max() > 1e-8 * (1 + np.abs(b).max()) for a, b in zip(d1, d2)):
                raise ValueError("the closed loop is not affine in the robot's Jacobians")
            G.append(d1)
        self.G = G
        self.of_plant = of_plant

    def _cond(self, A, B, C, D):
        A, B, s = A / self.c, B / self.c, self.sc
        return A / s[:, None] * s[None, :], B / s[:, None], C * s[None, :], D

    def at(self, Ap, Bp):
        return self._cond(*self.of_plant(Ap, Bp))


def spectral_norms(stack) -> np.ndarray:
    """Spectral norms of a stack of matrices (float SVD: the caller rounds the sum up)."""
    return np.linalg.norm(stack, 2, axis=(-2, -1)) if len(stack) else np.zeros(0)


def symmetric_norms(stack) -> np.ndarray:
    """Spectral norms of a stack of symmetric matrices: largest ``|eigenvalue|`` (float, cheaper than an
    SVD; the caller rounds the sum up)."""
    if not len(stack):
        return np.zeros(0)
    return np.abs(np.linalg.eigvalsh(stack)[..., [0, -1]]).max(axis=-1)


def acceleration_check(model, enclose, bounds):
    """``box -> (relative margin, |qddot| bound, why)``: the robot's accelerations inside ``bounds`` there."""
    fin = np.isfinite(bounds)

    def evaluate(lo, hi):
        q, qdot = model.state(0.5 * (lo + hi))
        at_centre = np.abs(model.robot.acceleration(q, qdot, model.u))
        if np.any(at_centre[fin] > bounds[fin]):
            return (
                -np.inf,
                at_centre,
                f"the robot's acceleration {at_centre} exceeds the rate bounds at rho = {0.5 * (lo + hi)}",
            )
        enc = enclose(lo, hi)
        qdd = np.maximum(np.abs(enc.qddot_lo), np.abs(enc.qddot_hi))
        margin = float(np.min((bounds[fin] - qdd[fin]) / bounds[fin])) if np.any(fin) else 1.0
        return margin, qdd, "the robot's accelerations may exceed the rate bounds"

    return evaluate
