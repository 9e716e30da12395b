"""Jets of first-order Taylor models: each value and derivative an affine polynomial in the box offset plus a ball.

A :class:`TaylorJet` holds, like :class:`~polyrob.bounds.certified.ball_jets.BallJet`,
a value and its derivatives (up to the second; the third on inputs) with
respect to ``n`` variables, for every point of a box ``x = c + d``,
``|d_p| <= r_p``; but where a ball jet holds each component as one ball over
the whole box, here each is a *Taylor model* in the first ``k`` box
variables::

    f(c + d) in  const + sum_{p < k} lin_p d_p + [-rest, rest]     for every |d| <= r

with float (thin) ``const`` and ``lin``.  Products keep the linear parts
exact: ``(a0 + a.d)(b0 + b.d) = a0 b0 + (a0 b + a b0).d + (a.d)(b.d)``, and
only the last term (second order in ``r``) goes into the ball, bounded by
the magnitudes of the linear parts.  Ball arithmetic over the box instead
multiplies two balls each as wide as the function's whole variation, and
the cancellations of ``Y dM Y dM Y`` (``Y = M_hat^-1``, entries of tens on
the arms' wrists) are lost: the dependency problem this module is for
(:mod:`polyrob.bounds.certified.factors.hessian`).

Outward rounding as in :mod:`~polyrob.bounds.certified.ball_jets`: every
float error of ``const`` (at most ``GAMMA`` times the magnitude summed) and
of each ``lin_p`` (the same, times ``r_p``) is added to ``rest``, so the
statement above holds for the floats stored.

Examples
--------
>>> import numpy as np
>>> x = TaylorJet.variables(np.array([[0.5]]), np.array([[0.1]]), 1)   # x on [0.4, 0.6], one variable, order 0
>>> y = x * x                                                          # 0.25 + 1.0 d + d^2
>>> float(y.c[0, 0, 0]), float(y.L[0, 0, 0, 0]), bool(0.01 <= y.R[0, 0, 0] < 0.0100001)
(0.25, 1.0, True)
"""

from __future__ import annotations

from functools import partial

import numpy as np

from polyrob.bounds.certified.ball_jets import (
    FORMS,
    GAMMA,
    TINY,
    BallJet,
    jet_layout,
    sum_terms,
    symmetric_indices,
)

__all__ = ["TaylorJet", "from_ball_jets", "taylor_sin_cos"]

#: Relative margin of a float sum of up to a few thousand nonnegative terms (``k u``, ``u = 2^-53``, ``k <= 9000``).
SUM_MARGIN = 1e-12


def _inflate(rad, mag):
    return (rad + GAMMA * mag) * (1.0 + GAMMA) + TINY


def _product(f, fa, lin, x, y):
    """``(c, L, R, magnitude)`` of one product-rule term of two pieces ``(c, L, R, spread)`` (before rounding margins)."""
    (xc, xL, xR, xS), (yc, yL, yR, yS) = x, y
    xA, yA = np.abs(xc) + xS, np.abs(yc) + yS
    c = f(xc, yc)
    L = lin(xL, yc, xc, yL)
    R = fa(xS, yS)
    R += fa(xA, yR)  # (in place: the floats of the sum)
    R += fa(xR, yA + yR)
    return c, L, R, fa(xA, yA)


class TaylorJet:
    """Taylor models ``c + L.d ± R`` of a value and its derivatives (order 0 to 3 in ``n`` variables), vectorised.

    ``c`` and ``R`` have shape ``(C, B, ...)`` (components as in
    :class:`~polyrob.bounds.certified.ball_jets.BallJet`, then the boxes);
    ``L`` has shape ``(k, C, B, ...)``: the coefficients of the first ``k``
    box variables, whose half-widths are ``r`` ``(k, B)``.
    """

    __slots__ = ("c", "L", "R", "r", "n", "order", "packed", "_S", "_live")

    def __init__(self, c, L, R, r, n: int, order: int, packed: bool = False):
        self.c, self.L, self.R, self.r, self.n, self.order = c, L, R, r, int(n), int(order)
        self.packed = bool(packed) and self.order >= 2  # the layout of BallJet.pack
        self._S = None  # spread(), computed once: a jet's arrays are never changed after it is made
        self._live = None  # live(), likewise

    # ------------------------------------------------------------------ construction and conversion
    @classmethod
    def variables(cls, centre, radius, order: int, k: int | None = None) -> TaylorJet:
        """The ``n`` variables themselves on the boxes ``centre ± radius`` ``(B, n)``, linear in the first ``k`` (all)."""
        centre, radius = np.asarray(centre, float), np.asarray(radius, float)
        B, n = centre.shape
        k = n if k is None else k
        ball = BallJet.variables(centre, np.zeros_like(radius), order)
        L = np.zeros((k, *ball.mid.shape))
        for p in range(k):
            L[p, 0, :, p] = 1.0
        R = np.zeros_like(ball.mid)
        R[0, :, k:] = radius[:, k:]  # the other variables' offsets: in the ball
        return cls(ball.mid, L, R, radius[:, :k].T.copy(), n, order)

    def _rr(self, ndim: int):
        """The half-widths ``r`` shaped against an array ``(k, C, B, ...)`` of ``ndim`` axes."""
        k, B = self.r.shape
        return self.r.reshape(k, 1, B, *([1] * (ndim - 3)))

    def spread(self):
        """An upper bound of ``sum_p |L_p| r_p`` (shape of ``c``)."""
        if self._S is None:
            if self.L.shape[0] == 0:
                self._S = np.zeros_like(self.c)
            else:
                self._S = (np.abs(self.L) * self._rr(self.L.ndim)).sum(0) * (1 + GAMMA)
        return self._S

    def live(self) -> int:
        """How many leading box variables the linear parts may depend on: ``L_p`` is exactly zero for ``p >= live()``.

        (``M_hat`` and ``Y`` depend on ``q`` alone: their models' ``qdot``
        coefficients are zeros, and a product need not compute them.)
        """
        if self._live is None:
            k = self.L.shape[0]
            nonzero = np.flatnonzero(np.any(self.L != 0, axis=tuple(range(1, self.L.ndim)))) if k else []
            self._live = int(nonzero[-1]) + 1 if len(nonzero) else 0
        return self._live

    def to_ball(self) -> BallJet:
        """The ball jet holding every component over the whole box: ``c ± (R + sum_p |L_p| r_p)``."""
        return BallJet(self.c, _inflate(self.R + self.spread(), np.abs(self.c)), self.n, self.order)

    # ------------------------------------------------------------------ array manipulation (as BallJet's)
    def _with(self, c, L, R, n=None, order=None) -> TaylorJet:
        order = self.order if order is None else order
        return TaylorJet(c, L, R, self.r, self.n if n is None else n, order, self.packed)

    def pack(self) -> TaylorJet:
        """The same models of the distinct components only, as :meth:`BallJet.pack <polyrob.bounds.certified.ball_jets.BallJet.pack>`."""
        if self.packed or self.order < 2:
            return self
        keep = jet_layout(self.n, self.order).distinct
        return TaylorJet(self.c[keep], self.L[:, keep], self.R[keep], self.r, self.n, self.order, True)

    def unpack(self) -> TaylorJet:
        """The whole jet of a packed one (each derivative's model copied to its permuted multi-indices)."""
        if not self.packed:
            return self
        full = jet_layout(self.n, self.order).full
        out = TaylorJet(self.c[full], self.L[:, full], self.R[full], self.r, self.n, self.order)
        out._S = None if self._S is None else self._S[full]
        return out

    def extended(self, r) -> TaylorJet:
        """The same models linear in more variables: ``r`` ``(k', B)`` the half-widths of all ``k' >= k`` (this jet's first)."""
        k = self.L.shape[0]
        L = np.zeros((len(r), *self.L.shape[1:]))
        L[:k] = self.L
        return TaylorJet(self.c, L, self.R, np.asarray(r, float), self.n, self.order, self.packed)

    def _on_components(self, fn) -> TaylorJet:
        """Apply a BallJet operation that acts on the component axis only (to ``c``, ``R`` and each ``L_p``)."""
        if self.packed:
            raise ValueError("a packed jet: unpack() it first")
        cr = fn(BallJet(self.c, self.R, self.n, self.order))
        moved = np.moveaxis(self.L, 0, -1)
        lin = fn(BallJet(moved, moved, self.n, self.order))
        return TaylorJet(cr.mid, np.moveaxis(lin.mid, -1, 0), cr.rad, self.r, cr.n, cr.order)

    def lowered(self, index: int | None, nvars: int) -> TaylorJet:
        """As :meth:`BallJet.lowered <polyrob.bounds.certified.ball_jets.BallJet.lowered>`."""
        return self._on_components(lambda j: j.lowered(index, nvars))

    def padded(self, nvars: int) -> TaylorJet:
        """As :meth:`BallJet.padded <polyrob.bounds.certified.ball_jets.BallJet.padded>`."""
        return self._on_components(lambda j: j.padded(nvars))

    def truncated(self, order: int) -> TaylorJet:
        """The same jet up to ``order``."""
        C = BallJet.size(self.n, order, self.packed)  # packed too: its components go by order
        return self._with(self.c[:C], self.L[:, :C], self.R[:C], order=order)

    def component(self, index: int) -> TaylorJet:
        """Component ``index`` (0: the value, ``1 + p``: the derivative ``p``, ...) as an order-0 jet."""
        s = slice(index, index + 1)
        return self._with(self.c[s], self.L[:, s], self.R[s], order=0)

    @staticmethod
    def concatenate(jets, n: int, order: int) -> TaylorJet:
        """Order-0 jets of one shape, in component order, as one jet of ``order`` in ``n`` variables."""
        first = jets[0]
        return TaylorJet(
            np.concatenate([j.c for j in jets]),
            np.concatenate([j.L for j in jets], 1),
            np.concatenate([j.R for j in jets]),
            first.r,
            n,
            order,
        )

    @property
    def shape(self):
        return self.c.shape[1:]

    def __getitem__(self, key) -> TaylorJet:
        key = key if isinstance(key, tuple) else (key,)
        return self._with(
            self.c[(slice(None), *key)], self.L[(slice(None), slice(None), *key)], self.R[(slice(None), *key)]
        )

    def transpose(self, *axes: int) -> TaylorJet:
        """Permute the array's own axes (its first, the boxes, stays first)."""
        full = (0, *(1 + a for a in axes))
        return self._with(
            np.transpose(self.c, full), np.transpose(self.L, (0, *(1 + a for a in full))), np.transpose(self.R, full)
        )

    def reshape(self, *shape: int) -> TaylorJet:
        """The array's own axes reshaped (the boxes' axis kept first)."""
        C = self.c.shape[0]
        return self._with(
            self.c.reshape(C, *shape), self.L.reshape(self.L.shape[0], C, *shape), self.R.reshape(C, *shape)
        )

    @staticmethod
    def stack(jets, axis: int) -> TaylorJet:
        """Stack jets of one shape along a new own axis (``axis >= 1``: the boxes' axis stays first)."""
        first = jets[0]
        return first._with(
            np.stack([j.c for j in jets], 1 + axis),
            np.stack([j.L for j in jets], 2 + axis),
            np.stack([j.R for j in jets], 1 + axis),
        )

    def constant_like(self, mid, rad) -> TaylorJet:
        """A ball ``mid ± rad`` (shape ``(B, ...)``) with zero derivatives and no linear part, in this jet's variables."""
        ball = BallJet.constant(mid, rad, self.n, self.order, self.packed)
        return self._with(ball.mid, np.zeros((self.L.shape[0], *ball.mid.shape)), ball.rad)

    def expand(self, axis: int) -> TaylorJet:
        """Insert a unit axis into the array's own axes (negative: from the end)."""
        return self._with(np.expand_dims(self.c, axis), np.expand_dims(self.L, axis), np.expand_dims(self.R, axis))

    def swap(self, a: int, b: int) -> TaylorJet:
        """Swap two of the array's own axes (negative indices only: from the end)."""
        return self._with(np.swapaxes(self.c, a, b), np.swapaxes(self.L, a, b), np.swapaxes(self.R, a, b))

    def const_form(self, form: str, cmid, crad=0.0, *, left: bool = True) -> TaylorJet:
        """``f(C, self)`` (``left``) or ``f(self, C)`` for a constant ball ``C = cmid ± crad`` and a bilinear form."""
        f, fa = FORMS[form]
        cmid = np.asarray(cmid, float)
        crad = np.broadcast_to(np.asarray(crad, float), cmid.shape)
        S = self.spread()
        A = np.abs(self.c) + S

        def g(fn, c, x):
            return fn(c, x) if left else fn(x, c)

        c = g(f, cmid, self.c)
        L = g(f, cmid, self.L)
        R = g(fa, np.abs(cmid), self.R) + g(fa, crad, A + self.R)
        return self._with(c, L, _inflate(R, g(fa, np.abs(cmid), A)))

    # ------------------------------------------------------------------ arithmetic
    def _same_box(self, other: TaylorJet) -> None:
        """Refuse to combine models over different boxes (their linear parts would be bounded with the wrong ``r``)."""
        if self.r is not other.r and not np.array_equal(self.r, other.r):
            raise ValueError("Taylor models over different boxes (or linear in different variables)")

    def __add__(self, other: TaylorJet) -> TaylorJet:
        self._same_box(other)
        mag = np.abs(self.c) + self.spread() + np.abs(other.c) + other.spread()
        return self._with(self.c + other.c, self.L + other.L, _inflate(self.R + other.R, mag))

    def __sub__(self, other: TaylorJet) -> TaylorJet:
        self._same_box(other)
        mag = np.abs(self.c) + self.spread() + np.abs(other.c) + other.spread()
        return self._with(self.c - other.c, self.L - other.L, _inflate(self.R + other.R, mag))

    def __neg__(self) -> TaylorJet:
        return self._with(-self.c, -self.L, self.R)

    def _pieces(self):
        """``[(c, L, R, S)]`` of the value, the gradient ``(n, ...)`` and the Hessian ``(n, n, ...)``."""
        if self.packed:
            raise ValueError("a packed jet: unpack() it first")
        n, S = self.n, self.spread()
        out = []
        for start, size, lead in ((0, 1, (1,)), (1, n, (n,)), (1 + n, n * n, (n, n)), (1 + n + n * n, n**3, (n, n, n))):
            if start > 0 and self.order < len(lead):
                break
            s = slice(start, start + size)
            tail = self.c.shape[1:]
            out.append(
                (
                    self.c[s].reshape(*lead, *tail) if len(lead) > 1 else self.c[s],
                    self.L[:, s].reshape(self.L.shape[0], *lead, *tail) if len(lead) > 1 else self.L[:, s],
                    self.R[s].reshape(*lead, *tail) if len(lead) > 1 else self.R[s],
                    S[s].reshape(*lead, *tail) if len(lead) > 1 else S[s],
                )
            )
        return out

    def form(self, form: str, other: TaylorJet) -> TaylorJet:
        """``f(self, other)`` for a bilinear form of :data:`~polyrob.bounds.certified.ball_jets.FORMS` (orders up to 2).

        Each product of two Taylor models ``(a, A, ra)`` and ``(b, B, rb)``
        (``A``, ``B`` the linear parts, ``sa = sum_p |A_p| r_p``)::

            f(a, b) + (f(A_p, b) + f(a, B_p)).d  ±  (|f|(sa, sb) + |f|(|a| + sa, rb) + |f|(ra, |b| + sb + rb))

        Of two packed jets (:meth:`pack`): the product rule at the distinct
        multi-indices only, a packed jet.
        """
        self._same_box(other)
        if self.packed or other.packed:
            return self._packed_form(form, other)
        f, fa = FORMS[form]
        order, n = min(self.order, other.order), self.n

        def at(piece, key):
            c, L, R, S = piece
            return c[key], L[(slice(None), *key)], R[key], S[key]

        lin, live = _linear_part(f, self, other)
        prod = partial(_product, f, fa, lin)
        a, b = self._pieces(), other._pieces()
        groups = [[prod(a[0], b[0])]]
        if order >= 1:
            groups.append([prod(a[0], b[1]), prod(a[1], b[0])])
        if order >= 2:
            groups.append(
                [
                    prod(at(a[0], (None,)), b[2]),
                    prod(a[2], at(b[0], (None,))),
                    prod(at(a[1], (slice(None), None)), at(b[1], (None, slice(None)))),
                    prod(at(a[1], (None, slice(None))), at(b[1], (slice(None), None))),
                ]
            )
        if order >= 3:  # d_pqr (ab): a T^b + T^a b + the three g H and the three H g pairings (as BallJet.form)
            P, Q, Rr = (slice(None), None, None), (None, slice(None), None), (None, None, slice(None))
            QR, PR, PQ = (
                (None, slice(None), slice(None)),
                (slice(None), None, slice(None)),
                (slice(None), slice(None), None),
            )
            terms = [prod(at(a[0], (None, None)), b[3]), prod(a[3], at(b[0], (None, None)))]
            for gi, Hi in ((P, QR), (Q, PR), (Rr, PQ)):
                terms.append(prod(at(a[1], gi), at(b[2], Hi)))
                terms.append(prod(at(a[2], Hi), at(b[1], gi)))
            groups.append(terms)
        cs, Ls, Rs = [], [], []
        for j, g in enumerate(groups):
            c, L, R, mag = (sum_terms(t[i] for t in g) for i in range(4))
            lead = max(j, 1)  # the derivative axes of this group, flattened into the component axis
            cs.append(c.reshape(-1, *c.shape[lead:]))
            Ls.append(L.reshape(L.shape[0], -1, *L.shape[1 + lead :]))
            Rs.append(_inflate(R, mag).reshape(-1, *R.shape[lead:]))
        c, L, R = np.concatenate(cs), np.concatenate(Ls, 1), np.concatenate(Rs)
        out = TaylorJet(c, L, R, self.r, n, order)
        out._live = live
        return out

    def _packed_form(self, form: str, other: TaylorJet) -> TaylorJet:
        """:meth:`form` of two packed jets: the whole product rule's floats at the sorted multi-indices (as BallJet's)."""
        if not (self.packed and other.packed):
            raise ValueError("a product of a packed and a whole jet")
        f, fa = FORMS[form]
        order, n = min(self.order, other.order), self.n

        def blocks(jet):
            """Each order's distinct components ``(c, L, R, S)``, one component axis: the whole tensors' floats there."""
            S = jet.spread()
            return [(jet.c[k], jet.L[:, k], jet.R[k], S[k]) for k in jet_layout(n, jet.order).blocks]

        def at(piece, key):
            c, L, R, S = piece
            return c[key], L[:, key], R[key], S[key]

        lin, live = _linear_part(f, self, other)
        prod = partial(_product, f, fa, lin)
        a, b = blocks(self), blocks(other)
        groups = [[prod(a[0], b[0])]]
        groups.append([prod(a[0], b[1]), prod(a[1], b[0])])
        if order >= 2:  # d_pl (ab) at p <= l (packed jets are of order 2 or more)
            P, L2 = symmetric_indices(n, 2)[0]
            groups.append([prod(a[0], b[2]), prod(a[2], b[0]), prod(at(a[1], P), at(b[1], L2)),
                           prod(at(a[1], L2), at(b[1], P))])  # fmt: skip
        if order >= 3:  # d_pqr (ab): a T^b + T^a b + the three g H and the three H g pairings, at p <= q <= r
            terms = [prod(a[0], b[3]), prod(a[3], b[0])]
            for gi, hi in zip(symmetric_indices(n, 3)[0], jet_layout(n, 3).pairs):
                terms.append(prod(at(a[1], gi), at(b[2], hi)))
                terms.append(prod(at(a[2], hi), at(b[1], gi)))
            groups.append(terms)
        cs, Ls, Rs = [], [], []
        for g in groups:
            c, L, R, mag = (sum_terms(t[i] for t in g) for i in range(4))
            cs.append(c)
            Ls.append(L)
            Rs.append(_inflate(R, mag))
        out = TaylorJet(np.concatenate(cs), np.concatenate(Ls, 1), np.concatenate(Rs), self.r, n, order, True)
        out._live = live
        return out

    def __mul__(self, other: TaylorJet) -> TaylorJet:
        return self.form("mul", other)

    def __matmul__(self, other: TaylorJet) -> TaylorJet:
        return self.form("matmul", other)


def _linear_part(f, x: TaylorJet, y: TaylorJet):
    """``(lin, live)``: ``lin(xL, yc, xc, yL) = f(xL, yc) + f(xc, yL)`` on pieces of ``x`` and ``y``, and its :meth:`~TaylorJet.live`.

    Why only the live rows are computed: where ``xL_p`` is zero and ``yc``
    finite, ``f(xL_p, yc)`` is exactly zero (a bilinear form of zeros), and
    adding it changes no float (``a + 0 = a``, ``a + b = b + a``); so the rows
    are the ones the whole sum gives.  Where a constant part is not finite
    the whole sum is taken.
    """
    k, kx, ky = x.L.shape[0], x.live(), y.live()
    if min(kx, ky) == k or not (np.isfinite(x.c).all() and np.isfinite(y.c).all()):
        return (lambda xL, yc, xc, yL: f(xL, yc[None]) + f(xc[None], yL)), None

    def lin(xL, yc, xc, yL):
        a, b = f(xc[None], yL[:ky]), f(xL[:kx], yc[None])
        ka, kb = ky, kx
        if kx > ky:
            a, b, ka, kb = b, a, kx, ky
        shape = (k, *np.broadcast_shapes(a.shape[1:], b.shape[1:]))
        if a.shape != shape:  # padded with the exact zeros of the rows beyond both (no copy when a has all k rows)
            a = np.concatenate([np.broadcast_to(a, (ka, *shape[1:])), np.zeros((k - ka, *shape[1:]))])
        a[:kb] += b
        return a

    return lin, max(kx, ky)


def from_ball_jets(centre: BallJet, box: BallJet, radii, k: int) -> TaylorJet:
    """The order-3 :class:`TaylorJet` of a function from its jets at a box's centre and over the box (both order 3).

    For a component ``X_j`` (the ``j``-th derivatives, ``j <= 3``), Taylor's
    theorem on the segment from the centre ``c`` gives, for ``|d| <= r``::

        X_0(c + d) in X_0(c) + X_1(c).d + 1/2 X_2(Q)[d, d]
        X_1(c + d) in X_1(c) + X_2(c).d + 1/2 X_3(Q)[d, d]
        X_2(c + d) in X_2(c) + X_3(c).d + (X_3(Q) - X_3(c)).d
        X_3(c + d) in X_3(Q)

    with ``Q`` the box.  The linear coefficients kept are the midpoints of
    ``X_{j+1}(c)`` in the first ``k`` variables; their radii, the
    coefficients of the other variables and the second-order terms go into
    the ball.  ``radii``: ``(B, N)`` half-widths of the box's variables
    (the jets' ``n`` are its first ones); ``centre``, ``box``: ``(C, B, ...)``.
    """
    n = box.n
    B = box.mid.shape[1]
    tail = box.mid.shape[1:]
    extra = len(tail) - 1
    r = np.asarray(radii, float)[:, :n].T.reshape(n, B, *([1] * extra))  # (n, B, 1, ...)
    kk = min(k, n)

    def parts(J):
        out, start = [], 0
        for j in range(4):
            size = n**j
            out.append(
                (
                    J.mid[start : start + size].reshape(*(n,) * j, *tail),
                    J.rad[start : start + size].reshape(*(n,) * j, *tail),
                )
            )
            start += size
        return out

    cen, bx = parts(centre), parts(box)

    def absq(part):
        return np.abs(part[0]) + part[1]

    comps_c, comps_L, comps_R = [], [], []
    # order 0: value
    v, g, H, T = cen
    Hq, Tq = absq(bx[2]), absq(bx[3])
    r2 = r[:, None] * r[None, :]  # (n, n, B, 1...)
    lin_other = (np.abs(g[0][kk:]) * r[kk:]).sum(0) if kk < n else 0.0
    R0 = v[1] + (g[1] * r).sum(0) + lin_other + 0.5 * (Hq * r2).sum((0, 1))
    comps_c.append(v[0])
    comps_L.append(g[0][:kk])  # (k, B, ...)
    comps_R.append(R0)
    # order 1: gradient component q
    lin_other = (np.abs(H[0][:, kk:]) * r[kk:][None]).sum(1) if kk < n else 0.0
    R1 = g[1] + (H[1] * r[None]).sum(1) + lin_other + 0.5 * (Tq * r2[None]).sum((1, 2))
    comps_c.append(g[0])
    comps_L.append(np.moveaxis(H[0][:, :kk], 1, 0))  # (k, n, B, ...)
    comps_R.append(R1)
    # order 2: Hessian component (q, s)
    dev = np.abs(bx[3][0] - T[0]) + bx[3][1]
    lin_other = (np.abs(T[0][:, :, kk:]) * r[kk:][None, None]).sum(2) if kk < n else 0.0
    R2 = H[1] + (dev * r[None, None]).sum(2) + lin_other
    comps_c.append(H[0])
    comps_L.append(np.moveaxis(T[0][:, :, :kk], 2, 0))  # (k, n, n, B, ...)
    comps_R.append(R2)
    # order 3: the box's ball
    comps_c.append(bx[3][0])
    comps_L.append(np.zeros((kk, *bx[3][0].shape)))
    comps_R.append(bx[3][1])
    c = np.concatenate([x.reshape(-1, *tail) for x in comps_c])
    L = np.concatenate([x.reshape(kk, -1, *tail) for x in comps_L], 1)
    R = np.concatenate([(x * (1 + SUM_MARGIN) + TINY).reshape(-1, *tail) for x in comps_R])
    return TaylorJet(c, L, R, np.asarray(radii, float)[:, :kk].T.copy(), n, 3)


def taylor_sin_cos(centre, radius, order: int, k: int, box_radius=None):
    """``(sin, cos)`` :class:`TaylorJet` s of the variables ``centre ± radius`` ``(B, n)``, linear in the first ``k``.

    ``box_radius`` (default ``radius``): the half-widths of the box's
    variables the models are linear in (a variable whose sine is not taken
    may have radius 0 here and its own half-width there).

    Every component of ``sin`` and ``cos`` of ``x_p = c_p + d_p`` is ``±sin``
    or ``±cos``, so ``f'' = -f`` and ``|f'''| <= 1``: by Taylor's theorem
    ``f(c + d) = f(c) + f'(c) d - f(c) d^2 / 2 + t``, ``|t| <= r^3 / 6``, and
    with ``d^2`` in ``[0, r^2]``::

        f(c_p + d_p) in f(c_p) (1 - r_p^2 / 4) + f'(c_p) d_p ± (|f(c_p)| r_p^2 / 4 + r_p^3 / 6)

    (for ``p < k``; else the linear term goes into the ball too), plus the
    library's error on ``f(c_p)`` and ``f'(c_p)`` (:data:`~polyrob.bounds.certified.ball_jets.TRIG_MARGIN`
    each) and the rounding of the product.  Near ``sin(c_p) = 0`` (an arm's
    zero pose) the sine's ball is of third order in ``r_p``, not of second.
    """
    from polyrob.bounds.certified.ball_jets import TRIG_MARGIN

    c, r = np.asarray(centre, float), np.asarray(radius, float)
    B, n = c.shape
    s0, c0 = np.sin(c), np.cos(c)
    # the derivatives of sin: sin, cos, -sin, -cos, sin; of cos: cos, -sin, -cos, sin, cos
    sin_seq, cos_seq = (s0, c0, -s0, -c0, s0), (c0, -s0, -c0, s0, c0)
    linear = np.arange(n) < k
    out = []
    for seq in (sin_seq, cos_seq):
        C = BallJet.size(n, order)
        cm, R, L = np.zeros((C, B, n)), np.zeros((C, B, n)), np.zeros((k, C, B, n))
        for j in range(order + 1):  # component j of variable p: index of d^j / dx_p^j
            for p in range(n):
                idx = 0 if j == 0 else 1 + sum(n**i for i in range(1, j)) + p * sum(n**i for i in range(j))
                f, rp = seq[j][:, p], r[:, p]
                cm[idx, :, p] = f * (1.0 - 0.25 * rp * rp)
                rest = 0.25 * np.abs(f) * rp**2 + rp**3 / 6 + TRIG_MARGIN * (1 + rp + rp * rp) + 4 * GAMMA * np.abs(f)
                if linear[p]:
                    L[p, idx, :, p] = seq[j + 1][:, p]
                    R[idx, :, p] = rest
                else:
                    R[idx, :, p] = np.abs(seq[j + 1][:, p]) * r[:, p] + rest
        r_box = r if box_radius is None else np.asarray(box_radius, float)
        out.append(TaylorJet(cm, L, (R * (1 + GAMMA) + TINY) * (R > 0), r_box[:, :k].T.copy(), n, order))
    return tuple(out)
