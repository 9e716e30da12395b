"""Guaranteed enclosures of an analytic robot's Jacobians over a box: ball arithmetic with forward derivatives.

An :class:`~polyrob.model.analytic.AnalyticRobot` is given by numpy callables
``M(q)``, ``C(q, qdot)``, ``g(q)`` that also work on object arrays.  Fed
:class:`Jet` numbers -- an ``arb`` ball and the balls of its first
derivatives -- they return enclosures of ``M``, ``C``, ``g`` and of their
derivatives over the whole box at once, and Gaussian elimination on those
encloses ``qddot = M^-1 (u - C qdot - g - D qdot)``, its derivatives (the
rows of ``A = df/dx``) and ``M^-1`` (``B``).  Written here because no
maintained Python library does interval forward-mode differentiation of
user callables (``arb`` does balls, not derivatives; the Pinocchio route of
:func:`~polyrob.bounds.certified.enclosure.certified_jacobian_bounds` needs a
URDF, and the paper's 2R exists only as formulas).

The enclosures are rigorous (outward-rounded ``arb`` balls converted to
floats outward) but not tight: plain ball arithmetic over-estimates by the
dependency effect, by a factor that shrinks to 1 with the box.  ``cos`` and
``sin`` of a wide ball are taken from the end points and the extrema inside
(``arb``'s own are loose on wide balls).

Examples
--------
>>> import numpy as np, polyrob
>>> robot = polyrob.load_robot("paper_2r")
>>> enc = analytic_jacobian_enclosure(robot, [0, 0.4], [0, 0.5], [1, -2], [1.1, -1.9], [0, 0])
>>> A, B = robot.jacobians([0, 0.45], [1.05, -1.95], [0, 0])
>>> bool(np.all(enc.A_lo <= A) and np.all(A <= enc.A_hi) and np.all(enc.B_lo <= B) and np.all(B <= enc.B_hi))
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from flint import arb

from polyrob.bounds.certified.balls import arb_lower, arb_upper, ball
from polyrob.errors import CertificationError, DomainError

__all__ = [
    "Jet",
    "AnalyticEnclosure",
    "analytic_jacobian_enclosure",
    "interval_cos",
    "interval_sin",
    "function_balls",
    "distance_up",
]

_U = np.finfo(float).eps


def _hull(values) -> arb:
    out = values[0]
    for v in values[1:]:
        out = out.union(v)
    return out


def _trig(x: arb, shift: float, fn) -> arb:
    """``fn`` (cos or sin) of ``x``: its end points and the extrema ``±1`` at ``shift + k pi`` inside."""
    lo, hi = arb_lower(x), arb_upper(x)
    if hi - lo >= 2 * math.pi:
        return ball(-1.0, 1.0)
    vals = [fn(arb(lo)), fn(arb(hi))]
    # extrema at t = shift + k pi; include one when it may lie in [lo, hi] (floats: widen the test by 1e-12)
    k0, k1 = math.ceil((lo - shift) / math.pi - 1e-12), math.floor((hi - shift) / math.pi + 1e-12)
    for k in range(k0, k1 + 1):
        vals.append(arb(1.0 if k % 2 == 0 else -1.0))
    return _hull(vals)


def interval_cos(x: arb) -> arb:
    """Enclosure of ``cos`` over the ball ``x`` (extrema at ``k pi``)."""
    return _trig(x, 0.0, lambda t: t.cos())


def interval_sin(x: arb) -> arb:
    """Enclosure of ``sin`` over the ball ``x`` (extrema at ``pi/2 + k pi``)."""
    return _trig(x, 0.5 * math.pi, lambda t: t.sin())


def _arb(x) -> arb:
    return x if isinstance(x, arb) else arb(float(x))


class Jet:
    """A ball ``value``, the balls ``grad`` of its first and ``hess`` of its second derivatives (forward mode).

    Supports ``+ - * /``, ``cos`` and ``sin`` (which numpy calls for object
    arrays), with floats and ints on either side.  ``hess`` is a tuple of rows.
    """

    __slots__ = ("value", "grad", "hess")

    def __init__(self, value, grad, hess=None):
        self.value = _arb(value)
        self.grad = tuple(grad)
        k = len(self.grad)
        self.hess = tuple(tuple(r) for r in hess) if hess is not None else ((arb(0),) * k,) * k

    @staticmethod
    def _lift(other, k):
        if isinstance(other, Jet):
            return other
        return Jet(_arb(other), (arb(0),) * k)

    def _chain(self, f0, f1, f2):
        """``phi(self)`` from ``phi``'s value ``f0`` and derivatives ``f1, f2`` at the ball."""
        g, H = self.grad, self.hess
        k = len(g)
        return Jet(f0, tuple(f1 * a for a in g), tuple(tuple(f1 * H[i][j] + f2 * g[i] * g[j] for j in range(k))
                                                      for i in range(k)))  # fmt: skip

    def __add__(self, other):
        o = self._lift(other, len(self.grad))
        H = tuple(tuple(a + b for a, b in zip(r, t)) for r, t in zip(self.hess, o.hess))
        return Jet(self.value + o.value, tuple(a + b for a, b in zip(self.grad, o.grad)), H)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.value, tuple(-a for a in self.grad), tuple(tuple(-a for a in r) for r in self.hess))

    def __sub__(self, other):
        return self + (-self._lift(other, len(self.grad)))

    def __rsub__(self, other):
        return self._lift(other, len(self.grad)) - self

    def __mul__(self, other):
        o = self._lift(other, len(self.grad))
        a, b, ga, gb = self.value, o.value, self.grad, o.grad
        k = len(ga)
        H = tuple(
            tuple(a * o.hess[i][j] + b * self.hess[i][j] + ga[i] * gb[j] + gb[i] * ga[j] for j in range(k))
            for i in range(k)
        )
        return Jet(a * b, tuple(a * y + b * x for x, y in zip(ga, gb)), H)

    __rmul__ = __mul__

    def reciprocal(self):
        if not (self.value > 0 or self.value < 0):
            raise CertificationError("division by a ball that contains 0 (the box is too large to enclose)")
        inv = 1 / self.value
        return self._chain(inv, -inv * inv, 2 * inv * inv * inv)

    def __truediv__(self, other):
        return self * self._lift(other, len(self.grad)).reciprocal()

    def __rtruediv__(self, other):
        return self._lift(other, len(self.grad)) * self.reciprocal()

    def cos(self):
        c, s = interval_cos(self.value), interval_sin(self.value)
        return self._chain(c, -s, -c)

    def sin(self):
        c, s = interval_cos(self.value), interval_sin(self.value)
        return self._chain(s, c, -s)


@dataclass(frozen=True, eq=False)
class AnalyticEnclosure:
    """Guaranteed entrywise bounds over a box: ``A_lo <= A <= A_hi``, ``B_lo <= B <= B_hi``, ``qddot_lo <= qddot <= qddot_hi``.

    ``dA_lo <= dA <= dA_hi`` ``(2m, 2m, 2m)`` and ``dB_lo <= dB <= dB_hi``
    ``(2m, m, 2m)`` bound the derivatives ``dA[r, c] / dx_l``, ``dB[r, c] / dx_l``
    (``x = (q, qdot)``) over the box: what a mean-value form needs.
    """

    A_lo: np.ndarray
    A_hi: np.ndarray
    B_lo: np.ndarray
    B_hi: np.ndarray
    qddot_lo: np.ndarray
    qddot_hi: np.ndarray
    dA_lo: np.ndarray = None
    dA_hi: np.ndarray = None
    dB_lo: np.ndarray = None
    dB_hi: np.ndarray = None


def _solve(M, b):
    """Gaussian elimination without pivoting on ``M x = b`` (``M`` symmetric positive definite: pivots > 0)."""
    m = len(b)
    M = [list(row) for row in M]
    b = list(b)
    for k in range(m):
        piv = M[k][k].value if isinstance(M[k][k], Jet) else M[k][k]
        if not piv > 0:
            raise CertificationError("M(q) is not provably positive definite on the box (a pivot may be <= 0)")
        for i in range(k + 1, m):
            f = M[i][k] / M[k][k]
            M[i] = [M[i][j] - f * M[k][j] for j in range(m)]
            b[i] = b[i] - f * b[k]
    x = [None] * m
    for i in reversed(range(m)):
        s = b[i]
        for j in range(i + 1, m):
            s = s - M[i][j] * x[j]
        x[i] = s / M[i][i]
    return x


def analytic_jacobian_enclosure(robot, q_lo, q_hi, qdot_lo, qdot_hi, u) -> AnalyticEnclosure:
    """Guaranteed bounds of ``A = df/dx``, ``B = df/du`` and ``qddot`` of ``robot`` over a box, at a fixed torque.

    Parameters
    ----------
    robot : AnalyticRobot
        Its ``M``, ``C``, ``g`` callables must work on object arrays (numpy
        arithmetic, ``np.cos``, ``np.sin``; no ``np.linalg``).
    q_lo, q_hi, qdot_lo, qdot_hi : array_like, shape (m,)
        The box (``lo == hi`` allowed).
    u : array_like, shape (m,)
        The torque.

    Returns
    -------
    AnalyticEnclosure

    Raises
    ------
    CertificationError
        ``M`` not provably positive definite on the box, or a callable that
        does not evaluate on balls.
    DomainError
        A malformed box.
    """
    m = robot.m
    box = [np.asarray(x, float).reshape(-1) for x in (q_lo, q_hi, qdot_lo, qdot_hi, u)]
    if (
        any(x.shape != (m,) or not np.all(np.isfinite(x)) for x in box)
        or np.any(box[0] > box[1])
        or np.any(box[2] > box[3])
    ):
        raise DomainError(f"analytic_jacobian_enclosure: a box of {m} finite values per bound, lo <= hi")
    ql, qh, vl, vh, uu = box
    k = 2 * m
    unit = [tuple(arb(1.0 if i == j else 0.0) for j in range(k)) for i in range(k)]
    q = np.array([[Jet(ball(ql[i], qh[i]), unit[i]) for i in range(m)]], dtype=object)
    qd = np.array([[Jet(ball(vl[i], vh[i]), unit[m + i]) for i in range(m)]], dtype=object)
    try:
        Mq = robot.M(q)[0]
        Cq = robot.C(q, qd)[0]
        gq = robot.g(q)[0] if robot.g is not None else [0.0] * m
    except (TypeError, ValueError, AttributeError) as exc:
        raise CertificationError(f"{robot.name}: its M, C, g do not evaluate on balls ({exc})") from exc
    lift = [[Jet._lift(Mq[i][j], k) for j in range(m)] for i in range(m)]
    rhs = []
    for i in range(m):
        s = Jet._lift(float(uu[i]), k) - float(robot.damping[i]) * qd[0][i] - gq[i]
        for j in range(m):
            s = s - Cq[i][j] * qd[0][j]
        rhs.append(s)
    acc = _solve(lift, rhs)
    Minv_cols = [_solve(lift, [Jet._lift(1.0 if i == j else 0.0, k) for i in range(m)]) for j in range(m)]
    Alo, Ahi = np.zeros((k, k)), np.zeros((k, k))
    Alo[:m, m:] = Ahi[:m, m:] = np.eye(m)
    Blo, Bhi = np.zeros((k, m)), np.zeros((k, m))
    dA, dB = np.zeros((2, k, k, k)), np.zeros((2, k, m, k))
    for i in range(m):
        for j in range(k):
            Alo[m + i, j], Ahi[m + i, j] = arb_lower(acc[i].grad[j]), arb_upper(acc[i].grad[j])
            for l in range(k):
                dA[:, m + i, j, l] = arb_lower(acc[i].hess[j][l]), arb_upper(acc[i].hess[j][l])
        for j in range(m):
            y = Minv_cols[j][i]
            Blo[m + i, j], Bhi[m + i, j] = arb_lower(y.value), arb_upper(y.value)
            for l in range(k):
                dB[:, m + i, j, l] = arb_lower(y.grad[l]), arb_upper(y.grad[l])
    qlo = np.array([arb_lower(a.value) for a in acc])
    qhi = np.array([arb_upper(a.value) for a in acc])
    return AnalyticEnclosure(Alo, Ahi, Blo, Bhi, qlo, qhi, dA[0], dA[1], dB[0], dB[1])


def function_balls(functions, lo, hi):
    """Enclosures ``[f_lo, f_hi] (2, k)`` and ``[g_lo, g_hi] (2, k, p)`` of ``f_j`` and their gradients over a box.

    ``functions``: pairs ``(f, grad)`` (only ``f`` is used: on :class:`Jet` balls, or a constant).
    """

    p = len(lo)
    unit = [tuple(arb(1.0 if i == j else 0.0) for j in range(p)) for i in range(p)]
    rho = np.array([Jet(ball(lo[i], hi[i]), unit[i]) for i in range(p)], dtype=object)
    k = len(functions)
    f = np.zeros((2, k))
    g = np.zeros((2, k, p))
    for j, (fn, _) in enumerate(functions):
        v = fn(rho)
        if isinstance(v, Jet):
            f[:, j] = arb_lower(v.value), arb_upper(v.value)
            g[0, j] = [arb_lower(x) for x in v.grad]
            g[1, j] = [arb_upper(x) for x in v.grad]
        else:  # a constant function
            f[:, j] = float(v)
    return f, g


def distance_up(lo, hi, c):
    """Largest distance of ``[lo, hi]`` from ``c``, rounded up."""
    d = np.maximum(hi - c, c - lo)
    return np.maximum(d, 0.0) * (1 + 4 * _U) + 4 * np.finfo(float).tiny
