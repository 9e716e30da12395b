"""One branch-and-bound run of the certified bounds: its state and the work on one q-box.

:class:`BoxProblem` holds the inner (attained) and outer (proved) values of
every entry and evaluates the open sub-problems on a q-box from the Taylor
models of :func:`polyrob.bounds.certified.interval_rbd.box_coefficients`;
:func:`process_box` settles what it can and returns the rest.  The driver is
:func:`polyrob.bounds.certified.enclosure.certified_jacobian_bounds`.
"""

from __future__ import annotations

import itertools

import numpy as np
from flint import arb

from polyrob.bounds.certified.balls import arb_lower, arb_upper, ball, sq
from polyrob.bounds.certified.interval_rbd import entry_list
from polyrob.bounds.certified.quadratic_max import quad_max, quad_naive
from polyrob.bounds.reference import reference_jacobians

__all__ = ["BoxProblem", "process_box"]


class BoxProblem:
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
        return [arb(1)] + [arb(x) for x in U] + list(S) + [sq(S[j]) if j == l else S[j] * S[l] for j, l in self.pairs]

    def fold(self, c, U):
        """Coefficients ``(a0, a, H)`` of ``a0 + a.v + v^T H v`` at the u-vertex ``U``."""
        m = self.m
        a0 = c[0] + sum((c[1 + j] * U[j] for j in range(m) if U[j] != 0), arb(0))
        H = [[None] * m for _ in range(m)]
        for n, (j, l) in enumerate(self.pairs):
            H[j][l] = H[l][j] = c[1 + 2 * m + n] if j == l else c[1 + 2 * m + n] / 2
        return a0, c[1 + m : 1 + 2 * m], H

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
            terms = self.remainder(e, c2, R, delta2, U, [ball(x, y) for x, y in zip(Slo, Shi)])
            rem = sum(terms.values(), arb(0))
        out, partial = [], set()
        cheap = None
        if rem is not None:
            # cheap enclosure first: when it already settles a side, skip the
            # exact vertex/face enumeration
            S = [ball(x, y) for x, y in zip(Slo, Shi)]
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
                stop = (
                    self.in_hi[e] + self.tol(e) - arb_upper(rem)
                    if sgn > 0
                    else -self.in_lo[e] + self.tol(e) + arb_lower(rem)
                )
            best = -np.inf
            S = [ball(x, y) for x, y in zip(Slo, Shi)]
            for dv in sorted(verts, key=lambda dv: -sgn * sum(float((dv[p] * lin[p][0]).mid()) for p in lin)):
                a0, a, H = base
                if dv:
                    a0 = a0 + sum((dv[p] * lin[p][0] for p in lin), arb(0))
                    a = [a[j] + sum((dv[p] * lin[p][1][j] for p in lin), arb(0)) for j in range(self.m)]
                    H = [
                        [H[j][l] + sum((dv[p] * lin[p][2][j][l] for p in lin), arb(0)) for l in range(self.m)]
                        for j in range(self.m)
                    ]
                if sgn < 0:
                    a0, a, H = -a0, [-x for x in a], [[-x for x in r] for r in H]
                if best > -np.inf and arb_upper(quad_naive(a0, a, H, S)) <= best:
                    continue
                ub, x = quad_max(a0, a, H, Slo, Shi, stop)
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
        S = [ball(x, y) for x, y in zip(Slo, Shi)]
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


def process_box(prob, items, tm):
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
