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

With ``pairs = kq`` the models are of second order in the first ``kq``
variables (the joint angles): the monomials ``w_pl = d_p d_l`` (``p <= l <
kq``, ``|w_pl| <= r_p r_l``; ``w_pp = d_p^2`` in ``[0, r_p^2]``) are symbols of
their own, as rows of ``lin`` after the ``k`` variables', and a product
puts ``(a_q.d_q)(b_q.d_q) = sum_pl a_p b_l w_pl`` there instead of into
the ball: only third-order terms are bounded by magnitudes.  On ur5's
boxes those quadratic terms are most of what the Hessians' balls hold
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

__all__ = ["TaylorJet", "monomials", "pair_radii", "SUM_MARGIN"]

#: Relative margin of a float sum of up to a few thousand nonnegative terms (``k u``, ``u = 2^-53``, ``k <= 9000``).
SUM_MARGIN = 1e-12


def _inflate(rad, mag):
    return (rad + GAMMA * mag) * (1.0 + GAMMA) + TINY


def monomials(kq: int):
    """``(p, l)``: the monomials ``d_p d_l``, ``p <= l < kq``, in the order of their rows: by ``l``, then ``p``.

    So the monomials of the first ``j`` variables are the first ``j (j + 1) / 2``
    rows: a chain's first links depend on its first angles only, and their
    models' live rows stay leading blocks (:func:`_linear_part`).

    >>> [(int(p), int(l)) for p, l in zip(*monomials(3))]
    [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)]
    """
    ell, p = np.tril_indices(kq)
    return p, ell


def pair_radii(r, kq: int):
    """Half-widths ``(P, B)`` of the :func:`monomials` of the first ``kq`` variables from their ``r`` ``(k, B)``."""
    p, ell = monomials(kq)
    return np.asarray(r, float)[p] * np.asarray(r, float)[ell]


def _product(f, fa, lin, pairs, x, y):
    """``(c, L, R, magnitude)`` of one product-rule term of two pieces ``(c, L, R, spread, q spread, other spread)`` (before rounding margins).

    ``pairs``: None, or :meth:`TaylorJet._pair_rows`'s ``(kq, ix, iy, gathers)``:
    the rows of ``x`` and ``y`` among the first ``kq`` that may be nonzero,
    and where each product ``f(x_p, y_l)`` goes among the monomials' rows.
    """
    (xc, xL, xR, xS, xSq, xSo), (yc, yL, yR, yS, ySq, ySo) = x, y
    xA, yA = np.abs(xc) + xS, np.abs(yc) + yS
    c = f(xc, yc)
    L = lin(xL, yc, xc, yL)
    if pairs is None:
        R = fa(xS, yS)
    else:  # (a_q.d_q + a_o.d_o)(b.d): the q-q products as monomials, the rest bounded
        kq, ix, iy, gathers = pairs
        R = fa(xSo, yS)
        R += fa(xSq, ySo)
        if len(ix) and len(iy):  # f(x_p, y_l) of the live rows only: an arm's first links depend on few angles
            W = f(_leading(xL, ix)[:, None], _leading(yL, iy)[None])  # (|ix|, |iy|, ...)
            for rows, at_x, at_y in gathers:  # f(x_p, y_l) to the monomial d_p d_l (p <= l), then f(x_l, y_p)
                L[rows] += W[at_x, at_y]
            R += 2 * GAMMA * fa(xSq, ySq)  # the floats of W and of its sums
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

    __slots__ = ("c", "L", "R", "r", "n", "order", "packed", "pairs", "_S", "_live")

    def __init__(self, c, L, R, r, n: int, order: int, packed: bool = False, pairs: int = 0):
        self.c, self.L, self.R, self.r, self.n, self.order = c, L, R, r, int(n), int(order)
        self.packed = bool(packed) and self.order >= 2  # the layout of BallJet.pack
        self.pairs = int(pairs)  # kq: the monomials of the first kq variables are the last rows of L
        self._S = None  # spreads(), computed once: a jet's arrays are never changed after it is made
        self._live = None  # live_rows(), likewise

    # ------------------------------------------------------------------ construction and conversion
    @classmethod
    def variables(cls, centre, radius, order: int, k: int | None = None, pairs: int = 0) -> TaylorJet:
        """The ``n`` variables themselves on the boxes ``centre ± radius`` ``(B, n)``, linear in the first ``k`` (all), with the monomials of the first ``pairs``."""
        centre, radius = np.asarray(centre, float), np.asarray(radius, float)
        B, n = centre.shape
        k = n if k is None else k
        ball = BallJet.variables(centre, np.zeros_like(radius), order)
        L = np.zeros((k, *ball.mid.shape))
        for p in range(k):
            L[p, 0, :, p] = 1.0
        R = np.zeros_like(ball.mid)
        R[0, :, k:] = radius[:, k:]  # the other variables' offsets: in the ball
        return cls(ball.mid, L, R, radius[:, :k].T.copy(), n, order).extended(radius[:, :k].T, pairs)

    @property
    def linear_r(self):
        """The half-widths ``(k, B)`` of the variables (``r`` without the monomials' rows)."""
        return self.r[: len(self.r) - self.pairs * (self.pairs + 1) // 2]

    def _rr(self, ndim: int):
        """The half-widths ``r`` shaped against an array ``(k, C, B, ...)`` of ``ndim`` axes."""
        k, B = self.r.shape
        return self.r.reshape(k, 1, B, *([1] * (ndim - 3)))

    def spreads(self):
        """Upper bounds ``(S, Sq, So)`` of ``sum_p |L_p| r_p`` over all rows, the first ``pairs`` and the others (shape of ``c``; ``Sq``, ``So`` None without pairs)."""
        if self._S is None:
            if self.L.shape[0] == 0:
                self._S = (np.zeros_like(self.c), None, None)
            elif not self.pairs:
                self._S = ((np.abs(self.L) * self._rr(self.L.ndim)).sum(0) * (1 + GAMMA), None, None)
            else:
                terms = np.abs(self.L) * self._rr(self.L.ndim)
                Sq, So = terms[: self.pairs].sum(0) * (1 + GAMMA), terms[self.pairs :].sum(0) * (1 + GAMMA)
                self._S = ((Sq + So) * (1 + GAMMA), Sq, So)
        return self._S

    def spread(self):
        """An upper bound of ``sum_p |L_p| r_p`` (shape of ``c``)."""
        return self.spreads()[0]

    def live_rows(self):
        """Which rows of ``L`` may be nonzero (bool ``(k,)``): a product need not compute the others.

        (``M_hat`` and ``Y`` depend on ``q`` alone: their models' ``qdot``
        coefficients are zeros.)
        """
        if self._live is None:
            k = self.L.shape[0]
            self._live = np.any(self.L != 0, axis=tuple(range(1, self.L.ndim))) if k else np.zeros(0, bool)
        return self._live

    def to_ball(self) -> BallJet:
        """The ball jet holding every component over the whole box: ``c ± (R + sum_p |L_p| r_p)``."""
        return BallJet(self.c, _inflate(self.R + self.spread(), np.abs(self.c)), self.n, self.order)

    # ------------------------------------------------------------------ array manipulation (as BallJet's)
    def _with(self, c, L, R, n=None, order=None) -> TaylorJet:
        order = self.order if order is None else order
        return TaylorJet(c, L, R, self.r, self.n if n is None else n, order, self.packed, self.pairs)

    def pack(self) -> TaylorJet:
        """The same models of the distinct components only, as :meth:`BallJet.pack <polyrob.bounds.certified.ball_jets.BallJet.pack>`."""
        if self.packed or self.order < 2:
            return self
        keep = jet_layout(self.n, self.order).distinct
        return TaylorJet(self.c[keep], self.L[:, keep], self.R[keep], self.r, self.n, self.order, True, self.pairs)

    def unpack(self) -> TaylorJet:
        """The whole jet of a packed one (each derivative's model copied to its permuted multi-indices)."""
        if not self.packed:
            return self
        full = jet_layout(self.n, self.order).full
        out = TaylorJet(self.c[full], self.L[:, full], self.R[full], self.r, self.n, self.order, False, self.pairs)
        out._S = None if self._S is None else tuple(None if S is None else S[full] for S in self._S)
        return out

    def extended(self, r, pairs: int | None = None) -> TaylorJet:
        """The same models linear in more variables: ``r`` ``(k', B)`` the half-widths of all ``k' >= k`` (this jet's first).

        ``pairs``: with the monomials of the first ``pairs`` variables (rows of
        zeros if this jet has none; by default as many as it has).
        """
        pairs = self.pairs if pairs is None else int(pairs)
        if self.pairs and pairs != self.pairs:
            raise ValueError("a jet's monomials are of its own first variables")
        r = np.asarray(r, float)
        rows = np.concatenate([r, pair_radii(r, pairs)])
        k, P = len(self.linear_r), len(self.r) - len(self.linear_r)
        L = np.zeros((len(rows), *self.L.shape[1:]))
        L[:k] = self.L[:k]
        L[len(r) : len(r) + P] = self.L[k:]
        return TaylorJet(self.c, L, self.R, rows, self.n, self.order, self.packed, pairs)

    def _on_components(self, fn) -> TaylorJet:
        """Apply a BallJet operation that acts on the component axis only (to ``c``, ``R`` and each ``L_p``)."""
        if self.packed:
            raise ValueError("a packed jet: unpack() it first")
        cr = fn(BallJet(self.c, self.R, self.n, self.order))
        moved = np.moveaxis(self.L, 0, -1)
        lin = fn(BallJet(moved, moved, self.n, self.order))
        return TaylorJet(cr.mid, np.moveaxis(lin.mid, -1, 0), cr.rad, self.r, cr.n, cr.order, False, self.pairs)

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
            pairs=first.pairs,
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
        """``[(c, L, R, S, Sq, So)]`` of the value, the gradient ``(n, ...)``, the Hessian ``(n, n, ...)`` and the third derivatives (:meth:`spreads`)."""
        if self.packed:
            raise ValueError("a packed jet: unpack() it first")
        n, spreads = self.n, self.spreads()
        out = []
        for start, size, lead in ((0, 1, (1,)), (1, n, (n,)), (1 + n, n * n, (n, n)), (1 + n + n * n, n**3, (n, n, n))):
            if start > 0 and self.order < len(lead):
                break
            s = slice(start, start + size)
            tail = self.c.shape[1:]
            shaped = [self.c[s], self.R[s], *(None if S is None else S[s] for S in spreads)]
            if len(lead) > 1:
                shaped = [None if a is None else a.reshape(*lead, *tail) for a in shaped]
            L = self.L[:, s].reshape(self.L.shape[0], *lead, *tail) if len(lead) > 1 else self.L[:, s]
            out.append((shaped[0], L, *shaped[1:]))
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
            c, L, *rest = piece
            return c[key], L[(slice(None), *key)], *(None if x is None else x[key] for x in rest)

        lin, live = _linear_part(f, self, other)
        prod = partial(_product, f, fa, lin, self._pair_rows(other))
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
        out = TaylorJet(c, L, R, self.r, n, order, pairs=self.pairs)
        out._live = None if self.pairs else live  # the products of q rows fill the monomials' rows
        return out

    def _packed_form(self, form: str, other: TaylorJet) -> TaylorJet:
        """:meth:`form` of two packed jets: the whole product rule's floats at the sorted multi-indices (as BallJet's)."""
        if not (self.packed and other.packed):
            raise ValueError("a product of a packed and a whole jet")
        f, fa = FORMS[form]
        order, n = min(self.order, other.order), self.n

        def blocks(jet):
            """Each order's distinct components ``(c, L, R, S, Sq, So)``, one component axis: the whole tensors' floats there."""
            spreads = jet.spreads()
            return [
                (jet.c[k], jet.L[:, k], jet.R[k], *(None if S is None else S[k] for S in spreads))
                for k in jet_layout(n, jet.order).blocks
            ]

        def at(piece, key):
            c, L, *rest = piece
            return c[key], L[:, key], *(None if x is None else x[key] for x in rest)

        lin, live = _linear_part(f, self, other)
        prod = partial(_product, f, fa, lin, self._pair_rows(other))
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
        out = TaylorJet(
            np.concatenate(cs), np.concatenate(Ls, 1), np.concatenate(Rs), self.r, n, order, True, self.pairs
        )
        out._live = None if self.pairs else live  # the products of q rows fill the monomials' rows
        return out

    def _pair_rows(self, other: TaylorJet):
        """``(kq, ix, iy, gathers)`` of :func:`_product` for a product with ``other`` (None without monomials)."""
        if self.pairs != other.pairs:
            raise ValueError("a product of jets with monomials of different variables")
        kq = self.pairs
        if not kq:
            return None
        ix, iy = np.flatnonzero(self.live_rows()[:kq]), np.flatnonzero(other.live_rows()[:kq])
        at_x, at_y = np.full(kq, -1), np.full(kq, -1)
        at_x[ix], at_y[iy] = np.arange(len(ix)), np.arange(len(iy))
        p, ell = monomials(kq)
        first = len(self.linear_r)
        gathers = []
        for a, b, keep in ((p, ell, True), (ell, p, p != ell)):  # W[p, l], then W[l, p] off the diagonal
            take = keep & (at_x[a] >= 0) & (at_y[b] >= 0)
            gathers.append((first + np.flatnonzero(take), at_x[a[take]], at_y[b[take]]))
        return kq, ix, iy, gathers

    def __mul__(self, other: TaylorJet) -> TaylorJet:
        return self.form("mul", other)

    def __matmul__(self, other: TaylorJet) -> TaylorJet:
        return self.form("matmul", other)


def _linear_part(f, x: TaylorJet, y: TaylorJet):
    """``(lin, live)``: ``lin(xL, yc, xc, yL) = f(xL, yc) + f(xc, yL)`` on pieces of ``x`` and ``y``, and its :meth:`~TaylorJet.live_rows`.

    Why only the live rows are computed: where ``xL_p`` is zero and ``yc``
    finite, ``f(xL_p, yc)`` is exactly zero (a bilinear form of zeros), and
    adding it changes no float (``a + 0 = a``, ``a + b = b + a``); so the rows
    are the ones the whole sum gives.  Where a constant part is not finite
    the whole sum is taken.
    """
    mx, my = x.live_rows(), y.live_rows()
    if (mx.all() and my.all()) or not (np.isfinite(x.c).all() and np.isfinite(y.c).all()):
        return (lambda xL, yc, xc, yL: f(xL, yc[None]) + f(xc[None], yL)), None
    runs_x, runs_y = _runs(mx), _runs(my)

    def lin(xL, yc, xc, yL):
        a = [(s, f(xc[None], yL[s])) for s in runs_y]
        b = [(s, f(xL[s], yc[None])) for s in runs_x]
        shapes = [t.shape[1:] for _, t in a + b] or [f(xc[None], yL[:1]).shape[1:]]  # (no live row: zeros)
        out = np.zeros((len(mx), *np.broadcast_shapes(*shapes)))
        for s, t in a:
            out[s] = t
        for s, t in b:
            out[s] += t
        return out

    return lin, mx | my


def _runs(mask):
    """The slices of the runs of ``True`` in a bool vector."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return [slice(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def _leading(L, rows):
    """``L[rows]``, a view where the rows are a leading block (an arm's chain: the usual case)."""
    return L[: len(rows)] if rows[-1] == len(rows) - 1 else L[rows]
