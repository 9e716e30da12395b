"""Guaranteed enclosures of an analytic robot's Jacobians over a box: ball arithmetic with forward derivatives.

An :class:`~polyrob.model.analytic.AnalyticRobot` is given by numpy callables
``M(q)``, ``C(q, qdot)``, ``g(q)`` that also work on object arrays.  Fed
:class:`Jet` numbers -- an ``arb`` ball and the balls of its first
derivatives -- they return enclosures of ``M``, ``C``, ``g`` and of their
derivatives over the whole box at once, and Gaussian elimination on those
encloses ``qddot = M^-1 (u - C qdot - g - D qdot)``, its derivatives (the
rows of ``A = df/dx``) and ``M^-1`` (``B``); with ``order=3`` also the
second derivatives of ``A`` and ``B``.  Written here because no maintained
Python library does interval forward-mode differentiation of user callables
(``arb`` does balls, not derivatives; the Pinocchio route of
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

import functools
import itertools
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
    "task_jacobian_enclosure",
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


@functools.cache
def _sym(k: int, r: int):
    """The sorted index ``r``-tuples of ``range(k)`` in lexicographic order and their positions, shape ``(k,) * r``.

    The layout of a symmetric tensor stored once per entry (``Jet.third``: ``r = 3``):
    ``flat[pos]`` is the full tensor.
    """
    t = tuple(itertools.combinations_with_replacement(range(k), r))
    pos = np.empty((k,) * r, dtype=np.intp)
    for n, idx in enumerate(t):
        for perm in itertools.permutations(idx):
            pos[perm] = n
    return t, pos


class Jet:
    """A ball ``value``, the balls ``grad`` of its first and ``hess`` of its second derivatives (forward mode).

    Supports ``+ - * /``, ``cos`` and ``sin`` (which numpy calls for object
    arrays), with floats and ints on either side.  ``hess`` is a tuple of rows.
    ``third`` is None (not tracked) or the third derivatives ``T[a, b, c]``
    for ``a <= b <= c`` in lexicographic order, a flat tuple (read one with
    :meth:`d3`); an operation tracks it when every Jet operand does.
    """

    __slots__ = ("value", "grad", "hess", "third")

    def __init__(self, value, grad, hess=None, third=None):
        self.value = _arb(value)
        self.grad = tuple(grad)
        k = len(self.grad)
        self.hess = tuple(tuple(r) for r in hess) if hess is not None else ((arb(0),) * k,) * k
        self.third = tuple(third) if third is not None else None

    @staticmethod
    def _lift(other, k, third=False):
        if isinstance(other, Jet):
            return other
        if third:  # a constant inside third-order arithmetic: zero third derivatives
            z = arb(0)
            return Jet(_arb(other), (z,) * k, None, (z,) * len(_sym(k, 3)[0]))
        return Jet(_arb(other), (arb(0),) * k)

    def _up(self, other):
        return self._lift(other, len(self.grad), self.third is not None)

    def d3(self, a, b, c):
        """The ball of ``d^3 / dx_a dx_b dx_c`` (any order of the indices)."""
        return self.third[_sym(len(self.grad), 3)[1][a, b, c]]

    def _chain(self, f0, f1, f2, f3=None):
        """``phi(self)`` from ``phi``'s value ``f0`` and derivatives ``f1, f2, f3`` at the ball."""
        g, H = self.grad, self.hess
        k = len(g)
        H2 = tuple(tuple(f1 * H[i][j] + f2 * g[i] * g[j] for j in range(k)) for i in range(k))
        if self.third is None:
            return Jet(f0, tuple(f1 * a for a in g), H2)
        T = tuple(
            f1 * t + f2 * (g[a] * H[b][c] + g[b] * H[a][c] + g[c] * H[a][b]) + f3 * g[a] * g[b] * g[c]
            for (a, b, c), t in zip(_sym(k, 3)[0], self.third)
        )
        return Jet(f0, tuple(f1 * a for a in g), H2, T)

    def __add__(self, other):
        o = self._up(other)
        H = tuple(tuple(a + b for a, b in zip(r, t)) for r, t in zip(self.hess, o.hess))
        T = None if self.third is None or o.third is None else tuple(a + b for a, b in zip(self.third, o.third))
        return Jet(self.value + o.value, tuple(a + b for a, b in zip(self.grad, o.grad)), H, T)

    __radd__ = __add__

    def __neg__(self):
        T = None if self.third is None else tuple(-a for a in self.third)
        return Jet(-self.value, tuple(-a for a in self.grad), tuple(tuple(-a for a in r) for r in self.hess), T)

    def __sub__(self, other):
        return self + (-self._up(other))

    def __rsub__(self, other):
        return self._up(other) - self

    def __mul__(self, other):
        o = self._up(other)
        a, b, ga, gb = self.value, o.value, self.grad, o.grad
        k = len(ga)
        Ha, Hb = self.hess, o.hess
        H = tuple(
            tuple(a * Hb[i][j] + b * Ha[i][j] + ga[i] * gb[j] + gb[i] * ga[j] for j in range(k)) for i in range(k)
        )
        if self.third is None or o.third is None:
            return Jet(a * b, tuple(a * y + b * x for x, y in zip(ga, gb)), H)
        if o is not other:  # a constant c: (c u)_abc = c u_abc, the other seven terms are exact zeros
            return Jet(a * b, tuple(a * y + b * x for x, y in zip(ga, gb)), H, tuple(b * t for t in self.third))
        T = tuple(
            a * w + b * t + ga[i] * Hb[j][l] + ga[j] * Hb[i][l] + ga[l] * Hb[i][j]
            + gb[l] * Ha[i][j] + gb[j] * Ha[i][l] + gb[i] * Ha[j][l]
            for (i, j, l), t, w in zip(_sym(k, 3)[0], self.third, o.third)
        )  # fmt: skip
        return Jet(a * b, tuple(a * y + b * x for x, y in zip(ga, gb)), H, T)

    __rmul__ = __mul__

    def reciprocal(self):
        if not (self.value > 0 or self.value < 0):
            raise CertificationError("division by a ball that contains 0 (the box is too large to enclose)")
        inv = 1 / self.value
        f3 = None if self.third is None else -6 * inv * inv * inv * inv
        return self._chain(inv, -inv * inv, 2 * inv * inv * inv, f3)

    def __truediv__(self, other):
        return self * self._up(other).reciprocal()

    def __rtruediv__(self, other):
        return self._up(other) * self.reciprocal()

    def cos(self):
        c, s = interval_cos(self.value), interval_sin(self.value)
        return self._chain(c, -s, -c, s)

    def sin(self):
        c, s = interval_cos(self.value), interval_sin(self.value)
        return self._chain(s, c, -s, -c)


@dataclass(frozen=True, eq=False)
class AnalyticEnclosure:
    """Guaranteed entrywise bounds over a box: ``A_lo <= A <= A_hi``, ``B_lo <= B <= B_hi``, ``qddot_lo <= qddot <= qddot_hi``.

    ``dA_lo <= dA <= dA_hi`` ``(2m, 2m, 2m)`` and ``dB_lo <= dB <= dB_hi``
    ``(2m, m, 2m)`` bound the derivatives ``dA[r, c] / dx_l``, ``dB[r, c] / dx_l``
    (``x = (q, qdot)``) over the box: what a mean-value form needs.  With
    ``order=3``, ``d2A_lo <= d2A <= d2A_hi`` ``(2m, 2m, 2m, 2m)`` and
    ``d2B_lo <= d2B <= d2B_hi`` ``(2m, m, 2m, 2m)`` bound
    ``d^2 A[r, c] / dx_l1 dx_l2`` and ``d^2 B[r, c] / dx_l1 dx_l2`` (None otherwise).
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
    d2A_lo: np.ndarray = None
    d2A_hi: np.ndarray = None
    d2B_lo: np.ndarray = None
    d2B_hi: np.ndarray = None


def _coordinate_jets(lo, hi, t3: bool) -> list:
    """The box's coordinates as jets: each its ball, a unit gradient, and (``t3``) zero third derivatives."""
    k = len(lo)
    unit = [tuple(arb(1.0 if i == j else 0.0) for j in range(k)) for i in range(k)]
    z3 = (arb(0),) * len(_sym(k, 3)[0]) if t3 else None
    return [Jet(ball(lo[i], hi[i]), unit[i], None, z3) for i in range(k)]


def _dynamics_on_balls(robot, q, qd, k: int, t3: bool):
    """``(M as lifted jets, C, g)`` of ``robot`` at the jet arrays ``q``, ``qd`` (shape ``(1, m)``)."""
    m = robot.m
    try:
        Mq = robot.M(q)[0]
        Cq = robot.C(q, qd)[0]
        gq = robot.g(q)[0] if robot.g is not None else [0.0] * m
    except (TypeError, ValueError, AttributeError) as exc:
        raise CertificationError(f"{robot.name}: its M, C, g do not evaluate on balls ({exc})") from exc
    return [[Jet._lift(Mq[i][j], k, t3) for j in range(m)] for i in range(m)], Cq, gq


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


def analytic_jacobian_enclosure(robot, q_lo, q_hi, qdot_lo, qdot_hi, u, order=2) -> AnalyticEnclosure:
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
    order : {2, 3}
        3 also tracks third derivatives, for ``d2A`` and ``d2B`` (about
        twice the cost for two joints).

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
    if order not in (2, 3):
        raise DomainError(f"analytic_jacobian_enclosure: order must be 2 or 3, not {order!r}")
    ql, qh, vl, vh, uu = box
    k = 2 * m
    t3 = order == 3
    z = _coordinate_jets(np.r_[ql, vl], np.r_[qh, vh], t3)
    q, qd = np.array([z[:m]], dtype=object), np.array([z[m:]], dtype=object)
    lift, Cq, gq = _dynamics_on_balls(robot, q, qd, k, t3)
    rhs = []
    for i in range(m):
        s = Jet._lift(float(uu[i]), k, t3) - float(robot.damping[i]) * qd[0][i] - gq[i]
        for j in range(m):
            s = s - Cq[i][j] * qd[0][j]
        rhs.append(s)
    acc = _solve(lift, rhs)
    Minv_cols = [_solve(lift, [Jet._lift(1.0 if i == j else 0.0, k, t3) for i in range(m)]) for j in range(m)]
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
    if not t3:
        return AnalyticEnclosure(Alo, Ahi, Blo, Bhi, qlo, qhi, dA[0], dA[1], dB[0], dB[1])
    # d2A[m+i, c, l1, l2] = d^3 qddot_i / dx_c dx_l1 dx_l2 and the Hessians of B are symmetric: each
    # distinct entry is converted once (conversions are a good part of the cost)
    pos3, (pairs, pos2) = _sym(k, 3)[1], _sym(k, 2)
    d2A, d2B = np.zeros((2, k, k, k, k)), np.zeros((2, k, m, k, k))
    for i in range(m):
        T = acc[i].third
        d2A[:, m + i] = np.array([[arb_lower(t) for t in T], [arb_upper(t) for t in T]])[:, pos3]
        for j in range(m):
            up = [Minv_cols[j][i].hess[a][b] for a, b in pairs]
            d2B[:, m + i, j] = np.array([[arb_lower(t) for t in up], [arb_upper(t) for t in up]])[:, pos2]
    return AnalyticEnclosure(Alo, Ahi, Blo, Bhi, qlo, qhi, dA[0], dA[1], dB[0], dB[1], d2A[0], d2A[1], d2B[0], d2B[1])


def task_jacobian_enclosure(robot, q_lo, q_hi, qdot_lo, qdot_hi, a_lo, a_hi, order=2) -> AnalyticEnclosure:
    """Guaranteed bounds of ``A``, ``B`` over a box of a task: the torque by inverse dynamics of the motion.

    On a task domain the torque is ``u = tau(q, qdot, a) = M(q) a + C(q, qdot) qdot
    + D qdot + g(q)`` (``a = qddot``), so the forward dynamics' Jacobians at
    ``(q, qdot, u)`` follow from ``M(q) f = u - h`` differentiated at fixed ``u``
    with ``f = a``: ``M df/dx_l = -(dM/dx_l a + dh/dx_l) = -dtau/dx_l``, i.e.
    ``A = [[0, I], [-M^-1 dtau/dq, -M^-1 dtau/dqdot]]`` and ``B = [0; M^-1]``,
    exact functions of ``(q, qdot, a)``, affine in ``a``.  The derivatives
    ``dA``, ``dB`` (and with ``order=3`` ``d2A``, ``d2B``) are taken with respect to
    ``z = (q, qdot, a)``: their last axes have ``3m`` entries; ``qddot_lo, qddot_hi``
    are ``a``'s box.

    Parameters
    ----------
    robot : AnalyticRobot
    q_lo, q_hi, qdot_lo, qdot_hi, a_lo, a_hi : array_like, shape (m,)
        The box (``lo == hi`` allowed).
    order : {2, 3}

    Returns
    -------
    AnalyticEnclosure

    Raises
    ------
    CertificationError, DomainError
        As :func:`analytic_jacobian_enclosure`.

    Examples
    --------
    >>> import numpy as np, polyrob
    >>> robot = polyrob.load_robot("paper_2r")
    >>> enc = task_jacobian_enclosure(robot, [0, 1.4], [0, 1.5], [0.5, -1], [0.6, -0.9], [1, -2], [1.2, -1.8])
    >>> q, qd, a = np.array([0, 1.45]), np.array([0.55, -0.95]), np.array([1.1, -1.9])
    >>> A, B = robot.jacobians(q, qd, robot.inverse_dynamics(q, qd, a)[0])
    >>> bool(np.all(enc.A_lo <= A) and np.all(A <= enc.A_hi) and np.all(enc.B_lo <= B) and np.all(B <= enc.B_hi))
    True
    >>> enc.dA_lo.shape                             # d A / d (q, qdot, a)
    (4, 4, 6)
    """
    m = robot.m
    box = [np.asarray(x, float).reshape(-1) for x in (q_lo, q_hi, qdot_lo, qdot_hi, a_lo, a_hi)]
    if any(x.shape != (m,) or not np.all(np.isfinite(x)) for x in box) or any(
        np.any(box[i] > box[i + 1]) for i in (0, 2, 4)
    ):
        raise DomainError(f"task_jacobian_enclosure: a box of {m} finite values per bound, lo <= hi")
    if order not in (2, 3):
        raise DomainError(f"task_jacobian_enclosure: order must be 2 or 3, not {order!r}")
    k, n = 3 * m, 2 * m
    t3 = order == 3
    z = _coordinate_jets(np.r_[box[0], box[2], box[4]], np.r_[box[1], box[3], box[5]], t3)
    q, qd, a = (np.array([z[g * m : (g + 1) * m]], dtype=object) for g in range(3))
    lift, Cq, gq = _dynamics_on_balls(robot, q, qd, k, t3)
    tau = []
    for i in range(m):
        s = Jet._lift(0.0, k, t3) + float(robot.damping[i]) * qd[0][i] + gq[i]
        for j in range(m):
            s = s + lift[i][j] * a[0][j] + Cq[i][j] * qd[0][j]
        tau.append(s)
    # dtau_i/dx_l as a jet in z: its value, gradient and (order 3) Hessian are tau's derivatives one order up
    dtau = [[Jet(t.grad[l], t.hess[l], [[t.d3(l, b, c) for c in range(k)] for b in range(k)] if t3 else None)
             for l in range(n)] for t in tau]  # fmt: skip
    plain = [[Jet(x.value, x.grad, x.hess) for x in row] for row in lift]  # M^-1 needs no third derivatives
    Minv_cols = [_solve(plain, [Jet._lift(1.0 if i == j else 0.0, k) for i in range(m)]) for j in range(m)]
    Alo, Ahi = np.zeros((n, n)), np.zeros((n, n))
    Alo[:m, m:] = Ahi[:m, m:] = np.eye(m)
    Blo, Bhi = np.zeros((n, m)), np.zeros((n, m))
    dA, dB = np.zeros((2, n, n, k)), np.zeros((2, n, m, k))
    d2A, d2B = (np.zeros((2, n, n, k, k)), np.zeros((2, n, m, k, k))) if t3 else (None, None)
    for i in range(m):
        for col in range(n):
            y = -Minv_cols[0][i] * dtau[0][col]
            for j in range(1, m):
                y = y - Minv_cols[j][i] * dtau[j][col]
            _fill(y, (m + i, col), Alo, Ahi, dA, d2A)
        for j in range(m):
            _fill(Minv_cols[j][i], (m + i, j), Blo, Bhi, dB, d2B)
    out = (Alo, Ahi, Blo, Bhi, box[4].copy(), box[5].copy(), dA[0], dA[1], dB[0], dB[1])
    return AnalyticEnclosure(*out, *((d2A[0], d2A[1], d2B[0], d2B[1]) if t3 else ()))


def _fill(y: Jet, at, lo, hi, d, d2) -> None:
    """Write the jet ``y``'s value, gradient and (``d2`` given) Hessian balls outward into the arrays at ``at``."""
    lo[at], hi[at] = arb_lower(y.value), arb_upper(y.value)
    d[(0, *at)] = [arb_lower(g) for g in y.grad]
    d[(1, *at)] = [arb_upper(g) for g in y.grad]
    if d2 is not None:
        d2[(0, *at)] = [[arb_lower(h) for h in row] for row in y.hess]
        d2[(1, *at)] = [[arb_upper(h) for h in row] for row in y.hess]


def function_balls(functions, lo, hi, order=1):
    """Enclosures ``[f_lo, f_hi] (2, k)`` and ``[g_lo, g_hi] (2, k, p)`` of ``f_j`` and their gradients over a box.

    ``functions``: pairs ``(f, grad)`` (only ``f`` is used: on :class:`Jet` balls, or a constant).
    ``order=2`` also returns the Hessians' enclosures ``[h_lo, h_hi] (2, k, p, p)``
    as a third element, ``order=3`` the third derivatives' ``(2, k, p, p, p)`` as a fourth.
    """

    if order not in (1, 2, 3):
        raise DomainError(f"function_balls: order must be 1, 2 or 3, not {order!r}")
    p = len(lo)
    unit = [tuple(arb(1.0 if i == j else 0.0) for j in range(p)) for i in range(p)]
    zero3 = (arb(0),) * len(_sym(p, 3)[0]) if order == 3 else None
    rho = np.array([Jet(ball(lo[i], hi[i]), unit[i], None, zero3) for i in range(p)], dtype=object)
    k = len(functions)
    f = np.zeros((2, k))
    g = np.zeros((2, k, p))
    pairs, pos2 = _sym(p, 2) if order >= 2 else ((), None)
    triples, pos3 = _sym(p, 3) if order == 3 else ((), None)
    hu = np.zeros((2, k, len(pairs))) if order >= 2 else None  # the Hessians are symmetric: a triangle each
    tu = np.zeros((2, k, len(triples))) if order == 3 else None
    for j, (fn, _) in enumerate(functions):
        v = fn(rho)
        if isinstance(v, Jet):
            f[:, j] = arb_lower(v.value), arb_upper(v.value)
            g[0, j] = [arb_lower(x) for x in v.grad]
            g[1, j] = [arb_upper(x) for x in v.grad]
            if hu is not None:
                hu[0, j] = [arb_lower(v.hess[a][b]) for a, b in pairs]
                hu[1, j] = [arb_upper(v.hess[a][b]) for a, b in pairs]
            if tu is not None:
                tu[0, j] = [arb_lower(x) for x in v.third]
                tu[1, j] = [arb_upper(x) for x in v.third]
        else:  # a constant function
            f[:, j] = float(v)
    if hu is None:
        return f, g
    return (f, g, hu[:, :, pos2]) if tu is None else (f, g, hu[:, :, pos2], tu[:, :, pos3])


def distance_up(lo, hi, c):
    """Largest distance of ``[lo, hi]`` from ``c``, rounded up."""
    d = np.maximum(hi - c, c - lo)
    return np.maximum(d, 0.0) * (1 + 4 * _U) + 4 * np.finfo(float).tiny
