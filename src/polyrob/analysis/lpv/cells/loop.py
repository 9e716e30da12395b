"""What every cell test shares: the loop as an affine function of the robot's Jacobians, their enclosures, the accelerations.

Examples
--------
>>> import numpy as np
>>> spectral_norms(np.array([np.eye(2), 3 * np.eye(2)])).tolist()
[1.0, 3.0]
"""

from __future__ import annotations

import numpy as np

_U = np.finfo(float).eps  # twice the unit roundoff, as the cells' other rounding bounds

__all__ = [
    "AffineLoop",
    "PlantEnclosure",
    "TaskPlantEnclosure",
    "plant_enclosure",
    "derivative_columns",
    "spectral_norms",
    "symmetric_norms",
    "acceleration_check",
    "SimilarTransform",
    "similarity_allowance",
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
        self.A0, self.B0 = np.array(A0, float), np.array(B0, float)
        #: a bound of what the float loop's LMI may differ by from the exact one's
        #: (:func:`similarity_allowance`; 0: the loop's matrices are exact images of the robot's)
        self.allowance = 0.0
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


class SimilarTransform:
    """``of_plant`` in the coordinates ``x = T x~``: ``(Ti A T, Ti B, C T, D)``, ``Ti`` the float inverse of ``T``.

    The cells check a searched ``X`` in the coordinates it was searched in:
    on a stiff loop (the main job's with ``--as 0.3``) the same
    ``X`` moved back to the loop's own coordinates spans many decades, and its
    LMI's margin sinks below the float check's rounding allowance there.
    ``Ti`` is not the exact inverse: :func:`similarity_allowance` bounds what
    that and the products' rounding change in the LMI.
    """

    def __init__(self, of_plant, T):
        self.of_plant = of_plant
        self.T = np.asarray(T, dtype=float)
        self.Ti = np.linalg.inv(self.T)

    def __call__(self, Ap, Bp):
        A, B, C, D = self.of_plant(Ap, Bp)
        return (self.Ti @ A) @ self.T, self.Ti @ B, C @ self.T, D


def _gamma(k: int) -> float:
    """Higham's ``gamma_k = k u / (1 - k u)``: the relative error bound of a float dot product of length ``k``."""
    return k * _U / (1.0 - k * _U)


def similarity_allowance(transform, original, loop, enc, Xs, f_max) -> float:
    """A bound of ``||L_exact(rho) - L_float(rho)||`` over the box, for the loop checked in ``transform``'s coordinates.

    The loop the cells check, ``loop`` (``transform``'s float matrices, time
    scaled by ``c`` and balanced by ``S = diag(sc)``), differs from one
    *exactly* similar to the robot's loop in two ways: ``Ti T = I + R`` is
    not the identity (the loop similar through ``Ti^-1`` is
    ``(Ã (I+R)^-1, B̃, C̃ (I+R)^-1)``), and the products are rounded
    (``|fl(Ti A T) - Ti A T| <= gamma_2n |Ti| |A| |T|``).  With ``||X(rho)||``
    at most ``sum_j f_max_j ||X_j||``, the bounded-real LMI moves by at most
    ``2 ||X|| (||dA|| + ||dB||) + 2 ||dC||``; the cells add it to their own
    rounding allowance.

    Parameters
    ----------
    transform : SimilarTransform
    original : AffineLoop
        The loop in its own coordinates, unscaled (``c = 1``, ``sc = 1``).
    loop : AffineLoop
        The loop the cells check.
    enc : enclosure
        The robot's Jacobians over the whole box (``A_lo``, ``A_hi``, ``B_lo``, ``B_hi``).
    Xs : ndarray
        ``(k, n, n)`` in ``loop``'s coordinates.
    f_max : ndarray
        ``(k,)`` bounds of ``|f_j|`` over the box.

    Returns
    -------
    float
        ``inf`` when ``Ti T`` is too far from the identity to bound.
    """
    T, Ti = transform.T, transform.Ti
    n = T.shape[0]
    sc, c = loop.sc, loop.c
    ratio = sc[None, :] / sc[:, None]  # (S^-1 M S)_ij = M_ij sc_j / sc_i
    R = np.abs(Ti @ T - np.eye(n)) + _gamma(n) * (np.abs(Ti) @ np.abs(T))
    r = float(np.linalg.norm(R * ratio)) * (1 + 1e-9) + 4 * n * _U
    if not r < 0.5:
        return float("inf")
    eps = r / (1.0 - r)  # ||(I + S^-1 R S)^-1 - I||
    P_mid = np.array([0.5 * (getattr(enc, f"{kd}_lo")[i, j] + getattr(enc, f"{kd}_hi")[i, j])
                      for kd, i, j in original.entries])  # fmt: skip
    P_rad = np.array([0.5 * (getattr(enc, f"{kd}_hi")[i, j] - getattr(enc, f"{kd}_lo")[i, j])
                      for kd, i, j in original.entries]) * (1 + 1e-9)  # fmt: skip
    Am, Bm = _plant_at(original, P_mid)

    def abs_bound(t, base):  # |M(rho)| elementwise over the box, the original loop's matrix t
        return np.abs(base) + sum(r_e * np.abs(g[t]) for r_e, g in zip(P_rad, original.G))

    orig_mid = original.at(Am, Bm)
    absA, absB, absC = (abs_bound(t, orig_mid[t]) for t in range(3))
    round_A = _gamma(2 * n) * np.abs(Ti) @ absA @ np.abs(T) / c * ratio
    round_B = _gamma(n) * (np.abs(Ti) @ absB) / c / sc[:, None]
    round_C = _gamma(n) * (absC @ np.abs(T)) * sc[None, :]
    mid = loop.at(Am, Bm)

    def norm_bound(t):  # ||M(rho)|| over the box, the checked loop's matrix t
        return float(np.linalg.norm(mid[t])) + sum(r_e * float(np.linalg.norm(g[t])) for r_e, g in zip(P_rad, loop.G))

    nA = norm_bound(0) + float(np.linalg.norm(round_A))
    nC = norm_bound(2) + float(np.linalg.norm(round_C))
    nX = float(np.asarray(f_max, float) @ np.linalg.norm(np.asarray(Xs, float), axis=(1, 2)))
    dA = nA * eps + float(np.linalg.norm(round_A))
    dB = float(np.linalg.norm(round_B))
    dC = nC * eps + float(np.linalg.norm(round_C))
    return (2.0 * nX * (dA + dB) + 2.0 * dC) * (1 + 1e-6)


def _plant_at(loop, P):
    """The robot's ``(A, B)`` at the varying entries ``P`` (the loop's order of entries), the rest as at ``A0, B0``."""
    A, B = loop.A0.copy(), loop.B0.copy()
    for value, (kd, i, j) in zip(P, loop.entries):
        (A if kd == "A" else B)[i, j] = value
    return A, B


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
