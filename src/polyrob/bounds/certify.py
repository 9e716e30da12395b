"""Guaranteed (interval-arithmetic) bounds on the Jacobians of robot dynamics.

For a fixed-base serial robot with dynamics ``M(q) qdd + h(q, qd) + D qd = u``
and ``f(x, u) = (qd, M^-1 (u - h - D qd))``, :func:`certified_jacobian_bounds`
returns entrywise intervals ``[A_lo, A_hi]``, ``[B_lo, B_hi]`` that provably
contain ``A = df/dx`` and ``B = df/du`` for *every* ``(q, qd, u)`` in a box.

Method (see :mod:`polyrob.bounds.interval_rbd` for the dynamics themselves):

* On a q-box every entry is a polynomial in ``(qd, u)`` of degree <= 2 whose
  coefficients ``c(q)`` are enclosed by order-2 *Taylor models* in
  ``d = q - qc``: thin value, gradient and Hessian at the box centre plus a
  rigorous third-order remainder.  Plain interval (or mean-value) forms
  over-estimate badly here, because ``M^-1`` of an ill-conditioned ``M``
  multiplies the widths of everything it touches.
* The Taylor model's linear part is maximised exactly (at a vertex of the
  q-box, jointly with ``qd`` below); only its quadratic part and remainder are
  enclosed, so the over-estimation is second order with the true curvature
  as constant and the branch and bound needs few boxes.
* ``u`` enters affinely (and ``d qdd/d qd`` is affine in ``qd``), so the
  extremes are at vertices of the u-box (qd-box): they are enumerated, not
  split.  The quadratic dependence of ``d qdd/d q`` on ``qd`` is maximised
  exactly over a qd-box (enumeration of its faces, in ``arb``); the qd-box is
  bisected only when the enclosed Taylor terms depend mostly on its extent.
* Branch and bound on outer bounds: for each entry we keep the best inner
  value (attained at evaluated points, by Pinocchio) and refine a box only
  while its enclosure sticks out beyond it by more than ``rel_tol`` x the
  current width.  Inner values only steer the search; the result is the union
  of the enclosures of all leaves, so it is rigorous whatever they are.
* Coordinates the dynamics do not depend on (structurally, from the exact
  polynomials, and numerically, by Pinocchio) are never bisected, and an
  entry independent of a bisected coordinate follows one half only.

Floats: every ``arb`` result is converted outward (``arb_upper``/``arb_lower``:
``float()`` rounds to nearest, so the result is moved one ulp outward when an
exact comparison shows it fell inside).
"""

from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass

import numpy as np
from flint import arb, arb_mat

from polyrob.errors import CertificationError, DomainError
from polyrob.bounds.interval_rbd import (SymbolicDynamics, _sq, arb_lower, arb_upper, box_coefficients, entry_list,
                                  entry_depends, entry_terms)

__all__ = ["CertifiedEnclosure", "certified_jacobian_bounds", "reference_jacobians"]


@dataclass(frozen=True, eq=False)
class CertifiedEnclosure:
    """Guaranteed entrywise bounds ``A_lo <= A <= A_hi``, ``B_lo <= B <= B_hi``.

    Attributes
    ----------
    A_lo, A_hi : numpy.ndarray, shape (2m, 2m)
    B_lo, B_hi : numpy.ndarray, shape (2m, m)
    n_boxes : int
        Number of q-boxes evaluated by the branch and bound.
    seconds : float
        Wall time.
    max_depth : int
        Deepest bisection level reached.
    """

    A_lo: np.ndarray
    A_hi: np.ndarray
    B_lo: np.ndarray
    B_hi: np.ndarray
    n_boxes: int
    seconds: float
    max_depth: int


def _pin_config(model, q):
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
    res = pin.computeABADerivatives(model, data, _pin_config(model, q), qd, np.asarray(u, float) - d * qd)
    dq, dv, Minv = (np.array(x) for x in res)  # copies: Pinocchio returns views into data
    Minv = np.triu(Minv) + np.triu(Minv, 1).T
    A = np.zeros((2 * m, 2 * m))
    A[:m, m:] = np.eye(m)
    A[m:, :m] = dq
    A[m:, m:] = dv - Minv * d[None, :]
    B = np.zeros((2 * m, m))
    B[m:] = Minv
    return A, B


def _relevant_dims(model, damping, lo, hi, vlo, vhi, ulo, uhi, sd, rng):
    """Joints whose coordinate changes A or B (numerically, via Pinocchio).

    Only decides which coordinates get bisected: enclosures always use the
    full range of every coordinate, so a wrong answer costs time, not rigour.
    """
    m = len(lo)
    rel = np.array(sd.depends) & (np.asarray(hi) > np.asarray(lo))
    data = model.createData()
    varies = np.zeros(m, dtype=bool)
    for _ in range(6):
        q, v, u = rng.uniform(lo, hi), rng.uniform(vlo, vhi), rng.uniform(ulo, uhi)
        A0, B0 = reference_jacobians(model, damping, q, v, u, data)
        scale = np.abs(A0).max() + np.abs(B0).max()
        for p in np.flatnonzero(rel & ~varies):
            q2 = q.copy()
            q2[p] = rng.uniform(lo[p], hi[p])
            A1, B1 = reference_jacobians(model, damping, q2, v, u, data)
            if max(np.abs(A1 - A0).max(), np.abs(B1 - B0).max()) > 1e-9 * scale:
                varies[p] = True
    return rel & varies


def _ball(lo, hi):
    return arb(lo) if lo == hi else arb(lo).union(arb(hi))


def _neg_definite(H, F):
    """Is ``H[F, F]`` negative definite?  True / False / None (undecided).

    Sylvester's criterion on ``-H[F, F]``: all leading minors > 0.
    """
    N = arb_mat([[-H[j][l] for l in F] for j in F])
    minors = [N[0, 0]]
    if len(F) >= 2:
        minors.append(N[0, 0] * N[1, 1] - N[0, 1] * N[1, 0])
    if len(F) == 3:
        minors.append(N.det())
    if any(mn <= 0 for mn in minors):
        return False
    return True if all(mn > 0 for mn in minors) else None


def _quad_max(a0, a, H, lo, hi, stop=None):
    """Rigorous max of ``a0 + a.x + x^T H x`` over the box ``[lo, hi]``.

    ``a0``, ``a``, ``H`` (symmetric) are thin balls, ``lo``/``hi`` floats.
    The maximum lies in the relative interior of some face of the box: on a
    face it is either a vertex, or the stationary point of the restriction
    when that is provably negative definite (otherwise the maximum is on the
    face's boundary), or, when definiteness cannot be decided, we bound the
    face by naive interval evaluation.  Returns ``(upper bound, point)`` where
    ``point`` is where the (approximate) maximum is attained, for inner bounds.
    With ``stop``, returns early (with a partial, too low bound) once the
    bound exceeds it: callers then only need to know that it does.
    """
    m = len(a)
    free = [j for j in range(m) if lo[j] < hi[j]]
    # definiteness depends only on the set of free coordinates of a face
    status = {F: _neg_definite(H, F) for r in range(1, len(free) + 1)
              for F in itertools.combinations(free, r)}
    best_ub, best_val, best_x = -np.inf, -np.inf, None
    ends = [(arb(lo[j]), arb(hi[j])) for j in range(m)]
    for choice in itertools.product((0, 1, 2), repeat=len(free)):
        F = tuple(j for j, c in zip(free, choice) if c == 2)
        if F and status[F] is False:
            continue  # not negative definite: no interior maximum on this face
        x = [ends[j][0] for j in range(m)]
        for j, c in zip(free, choice):
            if c == 1:
                x[j] = ends[j][1]
        X = [j for j in range(m) if j not in F]
        # f = const + lin . x_F + x_F^T H_FF x_F on the face
        hx = {j: sum((H[j][l] * x[l] for l in X), arb(0)) for j in range(m)}
        const = a0 + sum((x[j] * (a[j] + hx[j]) for j in X), arb(0))
        val = const if not F else None
        sol = None
        if F:
            lin = [a[j] + 2 * hx[j] for j in F]
        if F and status[F]:
            k = len(F)
            try:
                xs = (-2 * arb_mat([[H[j][l] for l in F] for j in F])).solve(arb_mat([[c] for c in lin]))
                sol = [xs[n, 0] for n in range(k)]
            except ZeroDivisionError:
                sol = None
            if sol is not None:
                if any(sol[n] < lo[j] or sol[n] > hi[j] for n, j in enumerate(F)):
                    continue  # stationary point outside the face
                val = const + sum((lin[n] * sol[n] for n in range(k)), arb(0)) / 2
        if val is None:  # undecided: naive enclosure over the face
            B = [_ball(lo[j], hi[j]) for j in F]
            val = const + sum((lin[n] * B[n] for n in range(len(F))), arb(0))
            for n, j in enumerate(F):
                val += H[j][j] * _sq(B[n])
                for n2 in range(n + 1, len(F)):
                    val += 2 * H[j][F[n2]] * B[n] * B[n2]
        ub = arb_upper(val)
        best_ub = max(best_ub, ub)
        vm = float(val.mid())
        if vm > best_val:
            best_val = vm
            best_x = [float(x[j].mid()) for j in range(m)]
            for n, j in enumerate(F):
                best_x[j] = 0.5 * (lo[j] + hi[j]) if sol is None else min(max(float(sol[n].mid()), lo[j]), hi[j])
        if stop is not None and best_ub > stop:
            break
    return best_ub, best_x


def _quad_naive(a0, a, H, S):
    """Interval enclosure of ``a0 + a.x + x^T H x`` for ``x`` in the balls ``S``."""
    m = len(a)
    val = a0 + sum((a[j] * S[j] for j in range(m)), arb(0))
    for j in range(m):
        val += H[j][j] * _sq(S[j]) + 2 * sum((H[j][l] * S[j] * S[l] for l in range(j + 1, m)), arb(0))
    return val


class _Problem:
    """State of one branch and bound run (see :func:`certified_jacobian_bounds`)."""

    def __init__(self, sd, damping, vlo, vhi, rel_tol, model=None, ulo=None, uhi=None):
        self.sd, self.m, self.d = sd, sd.m, damping
        self.model = model
        self.data = model.createData() if model is not None else None
        self.uc = None if ulo is None else 0.5 * (np.asarray(ulo) + np.asarray(uhi))
        self.qc = self.qlo = self.qhi = None
        self.vlo, self.vhi, self.rel_tol = vlo, vhi, rel_tol
        self.entries = entry_list(sd.m)
        n = len(self.entries)
        self.in_hi, self.in_lo = np.full(n, -np.inf), np.full(n, np.inf)
        self.out_hi, self.out_lo = np.full(n, -np.inf), np.full(n, np.inf)
        self.pairs = sd.pairs

    def tol(self, e):
        w = self.in_hi[e] - self.in_lo[e]
        if not np.isfinite(w):
            return 1e-300
        # absolute floor for entries that are (nearly) constant
        return max(self.rel_tol * w, 1e-12 * max(abs(self.in_hi[e]), abs(self.in_lo[e])), 1e-300)

    def monos(self, U, S):
        """Basis values ``[1, u, v, v_j v_l]`` with ``v`` in the balls ``S``."""
        return [arb(1)] + [arb(x) for x in U] + list(S) + [
            _sq(S[j]) if j == l else S[j] * S[l] for j, l in self.pairs]

    def fold(self, c, U):
        """Coefficients ``(a0, a, H)`` of ``a0 + a.v + v^T H v`` at the u-vertex ``U``."""
        m = self.m
        a0 = c[0] + sum((c[1 + j] * U[j] for j in range(m) if U[j] != 0), arb(0))
        H = [[None] * m for _ in range(m)]
        for n, (j, l) in enumerate(self.pairs):
            H[j][l] = H[l][j] = c[1 + 2 * m + n] if j == l else c[1 + 2 * m + n] / 2
        return a0, c[1 + m:1 + 2 * m], H

    def remainder(self, e, c2, R, delta2, U, S):
        """Terms ``{(p, q): c2_pq(S) d_p d_q, "R": R(S)}`` of the Taylor model beyond
        the linear part, as balls (thin c2 and a third-order remainder R)."""
        mv = self.monos(U, S)

        def ev(row):
            return sum((c * x for c, x in zip(row, mv) if not c.is_zero()), arb(0))

        out = {k: ev(rows[e]) * delta2[k] for k, rows in c2.items()}
        out["R"] = ev(R[e])
        return out

    def evaluate(self, it, tm, exact=False):
        """Bounds of sub-problem ``it`` on the current q-box; updates inner values.

        Order-2 Taylor model in ``q``: ``f(qc + d, v) in P(v) + sum_p d_p G_p(v)
        + sum_{p<=q} d_p d_q C_pq(v) + R(v)`` (``P``, ``G``, ``C`` thin).  The
        linear part is affine in ``d``, so its maximum over the box is at a
        vertex of the d-box; at each vertex the quadratic in ``v`` is
        maximised exactly (:func:`_quad_max`); the rest is enclosed.
        """
        c0, c1, c2, R, delta, delta2 = tm
        e, U, Slo, Shi = it[0], it[1], it[2], it[3]
        base = self.fold(c0[e], U)
        lin = {p: self.fold(rows[e], U) for p, rows in c1.items() if not all(c.is_zero() for c in rows[e])}
        verts = [dict(zip(lin, d)) for d in itertools.product(*[(delta[p].lower(), delta[p].upper()) for p in lin])]
        if R is None:
            terms, rem = None, None
        else:
            terms = self.remainder(e, c2, R, delta2, U, [_ball(x, y) for x, y in zip(Slo, Shi)])
            rem = sum(terms.values(), arb(0))
        out, partial = [], set()
        cheap = None
        if rem is not None:
            # cheap enclosure first: when it already settles a side, skip the
            # exact vertex/face enumeration
            S = [_ball(x, y) for x, y in zip(Slo, Shi)]
            mv = self.monos(U, S)
            cheap = sum((c * x for c, x in zip(c0[e], mv) if not c.is_zero()), arb(0)) + rem
            for p, rows in c1.items():
                cheap += sum((c * x for c, x in zip(rows[e], mv) if not c.is_zero()), arb(0)) * delta[p]
            xc = [0.5 * (x + y) for x, y in zip(Slo, Shi)]
            val = self._value(*base, xc)
            self.in_hi[e], self.in_lo[e] = max(self.in_hi[e], val), min(self.in_lo[e], val)
        for side, sgn in ((4, 1), (5, -1)):
            if not it[side]:
                out.append(None)
                continue
            if cheap is not None:
                if sgn > 0 and arb_upper(cheap) <= self.in_hi[e] + self.tol(e):
                    out.append(arb_upper(cheap))
                    continue
                if sgn < 0 and arb_lower(cheap) >= self.in_lo[e] - self.tol(e):
                    out.append(arb_lower(cheap))
                    continue
            # Only the decision "settled or not" needs the exact maximum: stop as
            # soon as it is clearly open (its bound then only orders the queue),
            # and skip corners whose naive bound cannot beat the best so far.
            stop = None
            if rem is not None and not exact:
                stop = (self.in_hi[e] + self.tol(e) - arb_upper(rem) if sgn > 0
                        else -self.in_lo[e] + self.tol(e) + arb_lower(rem))
            best = -np.inf
            S = [_ball(x, y) for x, y in zip(Slo, Shi)]
            for dv in sorted(verts, key=lambda dv: -sgn * sum(float((dv[p] * lin[p][0]).mid()) for p in lin)):
                a0, a, H = base
                if dv:
                    a0 = a0 + sum((dv[p] * lin[p][0] for p in lin), arb(0))
                    a = [a[j] + sum((dv[p] * lin[p][1][j] for p in lin), arb(0)) for j in range(self.m)]
                    H = [[H[j][l] + sum((dv[p] * lin[p][2][j][l] for p in lin), arb(0)) for l in range(self.m)]
                         for j in range(self.m)]
                if sgn < 0:
                    a0, a, H = -a0, [-x for x in a], [[-x for x in r] for r in H]
                if best > -np.inf and arb_upper(_quad_naive(a0, a, H, S)) <= best:
                    continue
                ub, x = _quad_max(a0, a, H, Slo, Shi, stop)
                best = max(best, ub)
                # inner candidates (they only steer the search): the value at the
                # box centre, and Pinocchio's value at the q-box corner where the
                # linearised bound peaks -- the extremes of monotone entries are
                # at such corners, which box centres only approach slowly
                val = self._value(*base, x)
                if dv:
                    q = list(self.qc)
                    for p in dv:
                        q[p] = min(max(self.qc[p] + float(dv[p].mid()), self.qlo[p]), self.qhi[p])
                    tv = self.true_value(e, q, x, U)
                    val = max(val, tv) if sgn > 0 else min(val, tv)
                if sgn > 0:
                    self.in_hi[e] = max(self.in_hi[e], val)
                else:
                    self.in_lo[e] = min(self.in_lo[e], val)
                if stop is not None and best > stop:
                    partial.add(side)  # open: the exact maximum is not needed
                    break
            if rem is None:
                out.append(sgn * np.inf)
            elif sgn > 0:
                out.append(arb_upper(arb(best) + rem))
            else:
                out.append(arb_lower(rem - arb(best)))
        return out[0], out[1], terms, partial

    def true_value(self, e, q, v, U):
        """Pinocchio's (floating-point) value of entry ``e`` at one point."""
        m = self.m
        blk, i, j = self.entries[e]
        u = np.asarray(U, float) if any(U) else self.uc
        A, B = reference_jacobians(self.model, self.d, np.asarray(q), np.asarray(v, float), u, self.data)
        return float(B[m + i, j] if blk == "B" else A[m + i, m + j] if blk == "Av" else A[m + i, j])

    def finalize(self, it, hi, lo):
        e = it[0]
        if hi is not None:
            self.out_hi[e] = max(self.out_hi[e], hi)
        if lo is not None:
            self.out_lo[e] = min(self.out_lo[e], lo)

    def excess(self, it, hi, lo):
        """How far (in tolerances) the sub-problem sticks out of the inner bounds."""
        e, t = it[0], self.tol(it[0])
        x = 0.0
        if it[4]:
            x = max(x, (hi - self.in_hi[e]) / t)
        if it[5]:
            x = max(x, (self.in_lo[e] - lo) / t)
        return min(x, 1e300)

    def qdot_split(self, it, tm, terms):
        """qdot-coordinate to bisect, or None if the q-box should be split instead.

        Only the Taylor remainder depends on the extent of the qdot-box (the
        rest is maximised exactly), so split qdot when most of the remainder
        comes from that extent rather than from the q-box.
        """
        Slo, Shi, U, e = it[2], it[3], it[1], it[0]
        free = [j for j in range(self.m) if Slo[j] < Shi[j]]
        if not free or not terms:
            return None
        full = float(sum(x.abs_upper() for x in terms.values()))
        if full < 0.25 * self.tol(e):
            return None
        S = [_ball(x, y) for x, y in zip(Slo, Shi)]
        c = [arb(0.5 * (x + y)) for x, y in zip(Slo, Shi)]
        c0, c1, c2, R, delta, delta2 = tm
        at_c = float(sum(x.abs_upper() for x in self.remainder(e, c2, R, delta2, U, c).values()))
        if not full - at_c > at_c:  # the q-extent dominates
            return None
        gain = {}
        for j in free:
            Sj = list(S)
            Sj[j] = c[j]
            gain[j] = full - float(sum(x.abs_upper() for x in self.remainder(e, c2, R, delta2, U, Sj).values()))
        return max(free, key=lambda j: gain[j])

    def _value(self, a0, a, H, x):
        m = self.m
        v = float(a0.mid()) + sum(float(a[j].mid()) * x[j] for j in range(m))
        return v + sum(float(H[j][l].mid()) * x[j] * x[l] for j in range(m) for l in range(m))


def _vertices(lo, hi):
    return sorted(set(itertools.product(*[(a,) if a == b else (a, b) for a, b in zip(lo, hi)])))


def _as_vec(name, x, m):
    a = np.asarray(x, dtype=float).reshape(-1)
    if a.shape != (m,) or not np.all(np.isfinite(a)):
        raise DomainError(f"{name} must be {m} finite numbers, got {x!r}")
    return a


def certified_jacobian_bounds(model, damping, q_lo, q_hi, qdot_lo, qdot_hi, u_lo, u_hi, *,
                              max_joints=3, rel_tol=1e-3, time_limit=120.0, progress=False):
    """Guaranteed entrywise bounds of ``A = df/dx`` and ``B = df/du`` over a box.

    For every ``q in [q_lo, q_hi]``, ``qdot in [qdot_lo, qdot_hi]`` and
    ``u in [u_lo, u_hi]``: ``A_lo <= A(q, qdot, u) <= A_hi`` and
    ``B_lo <= B(q) <= B_hi``, proved with outward-rounded interval arithmetic
    (``arb``) and converted to floats outward.  The bounds are tight up to
    ``rel_tol`` times each entry's width (branch and bound over ``q``, and
    over ``qdot`` where it pays off).

    Parameters
    ----------
    model : pinocchio.Model
        Fixed-base serial chain of revolute, continuous or prismatic joints.
    damping : array_like, shape (m,)
        Viscous joint damping ``D = diag(damping)``.
    q_lo, q_hi, qdot_lo, qdot_hi, u_lo, u_hi : array_like, shape (m,)
        The box (angle for continuous joints).  ``lo == hi`` is allowed.
    max_joints : int, default 3
        Robots with more joints are refused at once.
    rel_tol : float, default 1e-3
        Stop refining a box when it cannot widen an entry's bound by more than
        ``rel_tol`` times the entry's current width.
    time_limit : float, default 120
        Seconds; past it :class:`~polyrob.errors.CertificationError` is raised.
    progress : bool, default False
        Show a tqdm bar (boxes processed / processed + queued).

    Returns
    -------
    CertifiedEnclosure

    Raises
    ------
    CertificationError
        Too many joints, unsupported joint, ``M`` not provably invertible,
        or time limit reached.
    DomainError
        Malformed box.

    Examples
    --------
    >>> import numpy as np, pinocchio as pin
    >>> model = pin.buildModelFromUrdf("urdf/planar_2r.urdf")
    >>> q = [0.0, np.pi]                       # a single point: a tight enclosure
    >>> enc = certified_jacobian_bounds(model, [0, 0], q, q, [1, 2], [1, 2], [0, 0], [0, 0])
    >>> bool(np.all(enc.B_hi - enc.B_lo < 1e-12))
    True
    >>> float(np.round(enc.B_hi[2, 0], 4))    # 13.125 / det M(pi)
    0.0312
    """
    t0 = time.perf_counter()
    m = model.nv
    name = getattr(model, "name", "") or "the robot"
    if m > max_joints:
        raise CertificationError(f"certified bounds support robots of up to {max_joints} joints; {name} has {m}: "
                                 "use sampled bounds (drop --certify)")
    d = _as_vec("damping", damping, m)
    box = [_as_vec(n, x, m) for n, x in
           (("q_lo", q_lo), ("q_hi", q_hi), ("qdot_lo", qdot_lo), ("qdot_hi", qdot_hi), ("u_lo", u_lo), ("u_hi", u_hi))]
    qlo, qhi, vlo, vhi, ulo, uhi = box
    for n, (lo, hi) in zip(("q", "qdot", "u"), ((qlo, qhi), (vlo, vhi), (ulo, uhi))):
        if np.any(lo > hi):
            raise DomainError(f"{n}: lower bound above upper bound ({lo} > {hi})")
    sd = SymbolicDynamics(model)
    split = _relevant_dims(model, d, qlo, qhi, vlo, vhi, ulo, uhi, sd, np.random.default_rng(0))
    prob = _Problem(sd, d, vlo, vhi, rel_tol, model, ulo, uhi)
    deps = entry_depends(sd)
    root_w = np.where(qhi > qlo, qhi - qlo, 1.0)

    # sub-problem: [entry, u-vertex, qdot-box lo, qdot-box hi, hi side open, lo side open]
    # Each entry is affine in u, and affine in qdot unless it has qdot_j qdot_l
    # terms: so the u-box (qdot-box) extremes are at its vertices; only the
    # vertices of the variables an entry actually has (structurally) are used.
    items = []
    vc = tuple(0.5 * (vlo + vhi))
    for e, terms in enumerate(entry_terms(sd, d)):
        Us = _vertices(ulo, uhi) if terms & set(range(1, 1 + m)) else [(0.0,) * m]
        if terms & set(range(1 + 2 * m, 1 + 2 * m + len(sd.pairs))):
            Ss = [(tuple(vlo), tuple(vhi))]
        elif terms & set(range(1 + m, 1 + 2 * m)):
            Ss = [(v, v) for v in _vertices(vlo, vhi)]
        else:
            Ss = [(vc, vc)]
        items += [[e, U, S0, S1, True, True] for U in Us for S0, S1 in Ss]

    try:
        from tqdm import tqdm
        bar = tqdm(total=1, disable=not progress, desc="certify", unit="box")
    except ImportError:  # pragma: no cover
        bar = None
    heap = [(0.0, 0, 0, tuple(qlo), tuple(qhi), items)]
    counter, n_boxes, max_depth = itertools.count(1), 0, 0
    while heap:
        if time.perf_counter() - t0 > time_limit:
            open_items = sum(len(h[5]) for h in heap)
            if bar is not None:
                bar.close()
            raise CertificationError(
                f"certified bounds: time limit of {time_limit:g} s reached after {n_boxes} boxes "
                f"(depth {max_depth}) with {open_items} sub-problems still open in {len(heap)} boxes; "
                "raise time_limit or rel_tol, or shrink the domain")
        _, _, depth, lo, hi, items = heapq.heappop(heap)
        n_boxes += 1
        max_depth = max(max_depth, depth)
        c0, c1, c2, R, delta = box_coefficients(sd, d, lo, hi)
        if c0 is None:
            raise CertificationError(f"mass matrix not provably invertible at q = {np.add(lo, hi) / 2}")
        delta2 = {(p, q): _sq(delta[p]) if p == q else delta[p] * delta[q] for p, q in c2}
        tm = (c0, c1, c2, R, delta, delta2)
        prob.qlo, prob.qhi = lo, hi
        prob.qc = [min(max(0.5 * (a + b), a), b) for a, b in zip(lo, hi)]
        alive = _process_box(prob, items, tm)
        cand = [p for p in range(m) if split[p] and hi[p] - lo[p] > 1e-9 * root_w[p]]
        if alive and not cand:  # cannot refine further: keep these enclosures
            for it, _, _, _ in alive:
                h, l, _, _ = prob.evaluate(it, tm, exact=True)
                prob.finalize(it, h if it[4] else None, l if it[5] else None)
            alive = []
        if alive:
            if R is None:
                p = max(cand, key=lambda p: (hi[p] - lo[p]) / root_w[p])
            else:  # the coordinate carrying most of the non-linear Taylor terms
                score = {p: 0.0 for p in cand}
                for it, _, _, terms in alive:
                    t = prob.tol(it[0])
                    for k, x in terms.items():
                        for p in (set(k) if k != "R" else set(cand)) & score.keys():
                            score[p] += float(x.abs_upper()) / t
                p = max(cand, key=lambda p: (score[p], hi[p] - lo[p]))
            prio = -max(prob.excess(it, h, l) for it, h, l, _ in alive)
            mid = 0.5 * (lo[p] + hi[p])
            its = [it for it, _, _, _ in alive]
            for half, (a, b) in enumerate(((lo[p], mid), (mid, hi[p]))):
                clo, chi = list(lo), list(hi)
                clo[p], chi[p] = a, b
                # an entry independent of q_p has the same range on both halves
                sub = [list(it) for it in its if half == 0 or p in deps[it[0]]]
                if sub:
                    heapq.heappush(heap, (prio, next(counter), depth + 1, tuple(clo), tuple(chi), sub))
        if bar is not None:
            bar.total = n_boxes + len(heap)
            bar.update(1)
    if bar is not None:
        bar.close()
    return _assemble(prob, m, n_boxes, time.perf_counter() - t0, max_depth)


def _process_box(prob, items, tm):
    """Evaluate the open sub-problems on one q-box; return those still open.

    A sub-problem whose Taylor remainder comes mostly from the extent of its
    qdot-box is split in qdot right here (same q-box, no new dynamics).
    """
    alive, work = [], list(items)
    while work:
        it = work.pop()
        hi, lo, terms, partial = prob.evaluate(it, tm)
        e = it[0]
        # a partial bound (search stopped early) is too low: it never settles a side
        if it[4] and 4 not in partial and hi <= prob.in_hi[e] + prob.tol(e):
            prob.finalize(it, hi, None)
            it[4] = False
        if it[5] and 5 not in partial and lo >= prob.in_lo[e] - prob.tol(e):
            prob.finalize(it, None, lo)
            it[5] = False
        if not (it[4] or it[5]):
            continue
        j = prob.qdot_split(it, tm, terms) if terms is not None else None
        if j is not None:
            mid = 0.5 * (it[2][j] + it[3][j])
            a, b = list(it[3]), list(it[2])
            a[j], b[j] = mid, mid
            work += [[e, it[1], it[2], tuple(a), it[4], it[5]], [e, it[1], tuple(b), it[3], it[4], it[5]]]
            continue
        alive.append((it, hi, lo, terms))
    return alive


def _assemble(prob, m, n_boxes, seconds, max_depth):
    if not (np.all(np.isfinite(prob.out_hi)) and np.all(np.isfinite(prob.out_lo))):
        raise CertificationError("certified bounds: some entry could not be bounded (M not provably invertible)")
    A_lo, A_hi = np.zeros((2 * m, 2 * m)), np.zeros((2 * m, 2 * m))
    A_lo[:m, m:] = A_hi[:m, m:] = np.eye(m)
    B_lo, B_hi = np.zeros((2 * m, m)), np.zeros((2 * m, m))
    for e, (blk, i, j) in enumerate(prob.entries):
        lo, hi = prob.out_lo[e], prob.out_hi[e]
        if blk == "B":
            B_lo[m + i, j] = B_lo[m + j, i] = lo  # M^-1 is symmetric
            B_hi[m + i, j] = B_hi[m + j, i] = hi
        elif blk == "Av":
            A_lo[m + i, m + j], A_hi[m + i, m + j] = lo, hi
        else:
            A_lo[m + i, j], A_hi[m + i, j] = lo, hi
    return CertifiedEnclosure(A_lo, A_hi, B_lo, B_hi, n_boxes, seconds, max_depth)
