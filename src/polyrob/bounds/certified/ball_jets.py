"""Vectorised ball arithmetic with derivatives: enclosures of a value and its derivatives up to the third over a box.

A :class:`BallJet` holds, for every element of an array, balls (midpoint,
radius) enclosing a function's value and its first, (``order=2``) second
and (``order=3``) third derivatives with respect to ``n`` variables, *over a box* of those
variables: evaluating a computation on jets seeded at a box encloses the
derivatives of its result at every point of the box (interval automatic
differentiation); seeded at one point it encloses the derivatives there.
The jet components sit on the first axis (``value, gradient (n),
Hessian (n x n), third derivatives (n x n x n)``), so that numpy's broadcasting and ``einsum`` act on the
array's own axes after it.

Outward rounding is by directed margins (no change of the FPU's rounding
mode): every result's radius is the exact-arithmetic radius formula
(``|a| r_b + r_a |b| + r_a r_b`` for a product), plus
:data:`GAMMA` times the magnitude ``|a| |b|`` of what was summed (the
rounding error of a float sum of ``k`` products is at most ``k u`` times
that, ``u = 2^-53``; :data:`GAMMA` covers ``k`` up to 90), then times
``1 + GAMMA`` (the radius' own rounding) plus :data:`TINY` (underflow).
``sin`` and ``cos`` of a ball use the Taylor bound
``|sin x - sin c| <= |cos c| r + r^2 / 2`` and a margin of 4 ulps for the
library's own error.

A jet may be *packed* (:meth:`BallJet.pack`): its second and third
derivatives held at the sorted multi-indices only (``D_pl``, ``p <= l``), as
the Newton-Euler recursion (:mod:`~polyrob.bounds.certified.jet_rnea`) runs:
the product rule there reads sorted multi-indices only, so the floats are
the whole computation's, for a fifth of the third derivatives' work.

Examples
--------
>>> import numpy as np
>>> x = BallJet.variables(np.array([0.1]), np.array([0.0]), order=1)   # x = 0.1 exactly, dx/dx = 1
>>> y = x * x                                                          # y = x^2, dy/dx = 2x
>>> bool(y.mid[0, 0] - y.rad[0, 0] <= 0.1 * 0.1 <= y.mid[0, 0] + y.rad[0, 0]), float(y.mid[1, 0])
(True, 0.2)
"""

from __future__ import annotations

from functools import cache, partial
from types import SimpleNamespace

import numpy as np

from polyrob.errors import CertificationError

__all__ = [
    "BallJet",
    "GAMMA",
    "TINY",
    "ball_sin_cos",
    "ball_inverse",
    "intersect",
    "upper",
    "lower",
    "centre_radius",
    "symmetric_indices",
    "jet_layout",
    "sum_terms",
]

#: Relative margin added to every result for the rounding of float sums (``k u`` for ``k`` terms, ``k <= 90``).
GAMMA = 1e-14
#: Absolute margin added to every radius (underflow of tiny products).
TINY = 1e-300
#: Margin of the library's sin/cos beyond the exact value (4 ulps of a number of modulus <= 1).
TRIG_MARGIN = 4.5e-16


def _cross(x, y):
    return _cross_terms(x, y, np.subtract)


def _cross_abs(x, y):
    """The bilinear form with the absolute coefficients of the cross product (bounds ``|x × y|``)."""
    return _cross_terms(x, y, np.add)


def _cross_terms(x, y, sign):
    """``x_a y_b sign x_b y_a`` for each component: the floats of ``np.stack`` of those expressions, without its copies."""
    out = np.empty(np.broadcast_shapes(x.shape, y.shape), np.result_type(x, y))
    for i, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):
        o = out[..., i]
        np.multiply(x[..., a], y[..., b], out=o)
        sign(o, x[..., b] * y[..., a], out=o)
    return out


def _mul(x, y):
    return x * y


def _matvec(x, y):
    # a sum over the (short) last axis, not einsum: einsum's broadcasting over the jets' many leading axes is slow;
    # accumulated in place (the first product has the result's whole shape): the same floats, no temporary sums
    out = x[..., 0] * y[..., None, 0]
    for j in range(1, x.shape[-1]):
        out += x[..., j] * y[..., None, j]
    return out


#: Bilinear forms ``name: (f, |f|)``: ``|f|`` has the absolute values of ``f``'s coefficients.
FORMS = {
    "mul": (_mul, _mul),
    "cross": (_cross, _cross_abs),
    "matvec": (_matvec, _matvec),
    "matmul": (lambda x, y: x @ y, lambda x, y: x @ y),
    "dot": (lambda x, y: np.einsum("...i,...i->...", x, y), lambda x, y: np.einsum("...i,...i->...", x, y)),
}


def _inflate(rad, mag):
    return (rad + GAMMA * mag) * (1.0 + GAMMA) + TINY


def _ball_form(f, fa, x, y, xr, yr):
    """``(mid, rad, mag)`` of a bilinear form on balls ``x ± xr``, ``y ± yr``, before the rounding margins."""
    xm, ym = np.abs(x), np.abs(y)
    rad = fa(xm, yr)
    rad += fa(xr, ym + yr)  # in place: the floats of the sum
    return f(x, y), rad, fa(xm, ym)


def sum_terms(terms):
    """The float sum ``((t0 + t1) + t2) + ...`` of arrays (``sum``'s floats but a zero's sign), the terms unchanged."""
    terms = iter(terms)
    total = next(terms)
    for k, term in enumerate(terms):
        if k == 0 or total.shape != np.broadcast_shapes(total.shape, np.shape(term)):
            total = total + term  # a new array (the first term is the caller's)
        else:
            total += term
    return total


@cache
def symmetric_indices(n: int, order: int):
    """``(reps, spread)``: the sorted multi-indices ``p <= l <= ...`` of one order (row-major), and each component's among them.

    ``reps``: ``order`` index arrays; ``spread``: for each of the ``n**order``
    components (row-major), the position in ``reps`` of its sorted multi-index.
    Why a computation may run on the ``reps`` alone (:meth:`BallJet.pack`):
    the product rule at a sorted multi-index reads its operands at sorted
    multi-indices only (``D_pl`` reads ``D_pl``; ``D_pqr``, ``p <= q <= r``,
    reads ``D_qr``, ``D_pr``, ``D_pq``), so there it gives the whole
    computation's floats; and a smooth function's derivatives are symmetric,
    so the enclosure of ``D_pl f`` is one of ``D_lp f``, which
    :meth:`BallJet.unpack` copies there (the whole computation's ``D_lp``
    differs only in the order of its float sums).

    >>> reps, spread = symmetric_indices(2, 2)
    >>> [r.tolist() for r in reps], spread.tolist()
    ([[0, 0, 1], [0, 1, 1]], [0, 1, 1, 2])
    """
    full = np.indices((n,) * order).reshape(order, -1)
    ordered = np.sort(full, axis=0)
    is_rep = np.all(full == ordered, axis=0)
    position = np.full(n**order, -1)
    position[is_rep] = np.arange(int(is_rep.sum()))
    out = tuple(row[is_rep] for row in full), position[np.ravel_multi_index(tuple(ordered), (n,) * order)]
    for arr in (*out[0], out[1]):
        arr.setflags(write=False)  # cached: shared by every caller
    return out


@cache
def jet_layout(n: int, order: int) -> SimpleNamespace:
    """Indices of a jet's distinct components (:func:`symmetric_indices`), for :meth:`BallJet.pack` and its products.

    ``distinct``: their positions on a whole jet's component axis;
    ``full``: each whole component's position among them (``unpack``);
    ``blocks[j]``: the slice of the distinct derivatives of order ``j`` in a
    packed jet; ``pairs`` (order 3): for each distinct ``(p, q, r)``, the
    positions of ``(q, r)``, ``(p, r)`` and ``(p, q)`` among the distinct
    second derivatives.
    """
    g = 1 + (n if order >= 1 else 0)
    distinct, full, blocks = [np.arange(g)], [np.arange(g)], [slice(0, 1), slice(1, 1 + n)][: order + 1]
    start, packed_start = g, g
    for d in range(2, order + 1):
        reps, spread = symmetric_indices(n, d)
        distinct.append(start + np.ravel_multi_index(reps, (n,) * d))
        full.append(packed_start + spread)
        blocks.append(slice(packed_start, packed_start + len(reps[0])))
        start, packed_start = start + n**d, packed_start + len(reps[0])
    pairs = None
    if order >= 3:
        (P, Q, R), spread2 = symmetric_indices(n, 3)[0], symmetric_indices(n, 2)[1]
        pairs = tuple(spread2[x * n + y] for x, y in ((Q, R), (P, R), (P, Q)))
    out = SimpleNamespace(distinct=np.concatenate(distinct), full=np.concatenate(full), blocks=blocks, pairs=pairs)
    for arr in (out.distinct, out.full, *(pairs or ())):
        arr.setflags(write=False)  # cached: shared by every caller
    return out


class BallJet:
    """Balls of a value and its derivatives (order 0 to 3 in ``n`` variables), vectorised.

    ``mid`` and ``rad`` have shape ``(C, *shape)`` with ``C = 1``, ``1 + n``,
    ``1 + n + n^2`` or ``1 + n + n^2 + n^3``: component 0 is the value,
    ``1 .. n`` the gradient, then the Hessian and the third derivatives
    (row-major).
    """

    __slots__ = ("mid", "rad", "n", "order", "packed")

    def __init__(self, mid, rad, n: int, order: int, packed: bool = False):
        self.mid, self.rad, self.n, self.order = mid, rad, int(n), int(order)
        self.packed = bool(packed) and self.order >= 2  # (below order 2 both layouts are one)

    # ------------------------------------------------------------------ construction
    @staticmethod
    def size(n: int, order: int, packed: bool = False) -> int:
        """Number of components of a jet (``packed``: of its distinct ones, :meth:`pack`)."""
        if packed:
            return len(jet_layout(n, order).distinct)
        return 1 + (n if order >= 1 else 0) + (n * n if order >= 2 else 0) + (n**3 if order >= 3 else 0)

    @classmethod
    def constant(cls, mid, rad, n: int, order: int, packed: bool = False) -> BallJet:
        """A ball ``mid ± rad`` whose derivatives are zero."""
        mid, rad = np.asarray(mid, float), np.broadcast_to(np.asarray(rad, float), np.shape(mid))
        C = cls.size(n, order, packed)
        M, R = np.zeros((C, *mid.shape)), np.zeros((C, *mid.shape))
        M[0], R[0] = mid, rad
        return cls(M, R, n, order, packed)

    @classmethod
    def variables(cls, centre, radius, order: int) -> BallJet:
        """The ``n`` variables themselves on the box ``centre ± radius`` (shape ``(..., n)``)."""
        centre, radius = np.asarray(centre, float), np.asarray(radius, float)
        n = centre.shape[-1]
        out = cls.constant(centre, radius, n, order)
        if order >= 1:
            for p in range(n):
                out.mid[1 + p, ..., p] = 1.0
        return out

    def _like(self, mid, rad) -> BallJet:
        """Arrays in this jet's variables, order and layout."""
        return BallJet(mid, rad, self.n, self.order, self.packed)

    def constant_like(self, mid, rad) -> BallJet:
        """A ball ``mid ± rad`` with zero derivatives, in this jet's variables, order and layout."""
        return BallJet.constant(mid, rad, self.n, self.order, self.packed)

    def pack(self) -> BallJet:
        """The same jet at the sorted multi-indices only (:func:`symmetric_indices`); :meth:`unpack` makes it whole.

        Linear operations and :meth:`form` act on it as on the whole jet
        (the same floats there).  For inputs whose ``D_lp`` and ``D_pl`` are
        the same floats (the recursion's sines, cosines, velocities): of a
        jet where they are two enclosures (``Y``'s second derivatives), only
        ``D_pl`` is kept, proved but possibly wider.
        """
        if self.packed or self.order < 2:
            return self
        keep = jet_layout(self.n, self.order).distinct
        return BallJet(self.mid[keep], self.rad[keep], self.n, self.order, True)

    def unpack(self) -> BallJet:
        """The whole jet of a packed one (each derivative copied to its permuted multi-indices)."""
        if not self.packed:
            return self
        full = jet_layout(self.n, self.order).full
        return BallJet(self.mid[full], self.rad[full], self.n, self.order)

    # ------------------------------------------------------------------ pieces
    def value(self) -> BallJet:
        """The value alone (order 0)."""
        return BallJet(self.mid[:1], self.rad[:1], self.n, 0)

    def _pieces(self, arr):
        if self.packed:
            raise ValueError("a packed jet: unpack() it first")
        n = self.n
        v = arr[:1]
        g = arr[1 : 1 + n] if self.order >= 1 else None
        H = arr[1 + n : 1 + n + n * n].reshape(n, n, *arr.shape[1:]) if self.order >= 2 else None
        if self.order >= 3:
            return v, g, H, arr[1 + n + n * n :].reshape(n, n, n, *arr.shape[1:])
        return v, g, H

    def lowered(self, index: int | None, nvars: int) -> BallJet:
        """A jet one order lower in the first ``nvars`` variables: of this jet's value (``index=None``) or of its derivative ``index``."""
        k = nvars

        def parts(arr):
            pieces = self._pieces(arr)
            tail = arr.shape[1:]
            if index is None:
                out = [pieces[0], pieces[1][:k]]
                if self.order >= 3:
                    out.append(pieces[2][:k, :k].reshape(k * k, *tail))
            else:
                out = [pieces[1][index : index + 1], pieces[2][index, :k]]
                if self.order >= 3:
                    out.append(pieces[3][index, :k, :k].reshape(k * k, *tail))
            return np.concatenate(out)

        return BallJet(parts(self.mid), parts(self.rad), nvars, self.order - 1)

    def padded(self, nvars: int) -> BallJet:
        """The same jet in ``nvars >= n`` variables, the new ones last (derivatives in them zero)."""
        n, k = self.n, nvars
        if k == n or self.order == 0:
            return BallJet(self.mid, self.rad, k, self.order)

        def pad(arr):
            pieces = self._pieces(arr)[: 1 + self.order]
            tail = arr.shape[1:]
            out = [pieces[0]]
            for d, piece in enumerate(pieces[1:], start=1):
                full = np.zeros((k,) * d + tail)
                full[(slice(0, n),) * d] = piece
                out.append(full.reshape(k**d, *tail))
            return np.concatenate(out)

        return BallJet(pad(self.mid), pad(self.rad), k, self.order)

    def truncated(self, order: int) -> BallJet:
        """The same jet up to ``order`` (its lower components do not depend on the higher ones)."""
        C = self.size(self.n, order, self.packed)  # packed too: its components go by order
        return BallJet(self.mid[:C], self.rad[:C], self.n, order, self.packed)

    def derivative_value(self, index: int) -> BallJet:
        """The derivative ``index`` as an order-0 ball."""
        return BallJet(self.mid[1 + index : 2 + index], self.rad[1 + index : 2 + index], self.n, 0)

    @property
    def shape(self):
        return self.mid.shape[1:]

    def __getitem__(self, key) -> BallJet:
        key = key if isinstance(key, tuple) else (key,)
        return self._like(self.mid[(slice(None), *key)], self.rad[(slice(None), *key)])

    def swap(self, a: int, b: int) -> BallJet:
        """Swap two of the array's own axes (negative indices count from its end)."""
        return self._like(np.swapaxes(self.mid, a, b), np.swapaxes(self.rad, a, b))

    def transpose(self, *axes: int) -> BallJet:
        """Permute the array's own axes (``axes`` as for :func:`numpy.transpose` of the array without components)."""
        full = (0, *(1 + a for a in axes))
        return self._like(np.transpose(self.mid, full), np.transpose(self.rad, full))

    def reshape(self, *shape: int) -> BallJet:
        """The array's own axes reshaped."""
        C = self.mid.shape[0]
        return self._like(self.mid.reshape(C, *shape), self.rad.reshape(C, *shape))

    @staticmethod
    def stack(jets, axis: int) -> BallJet:
        """Stack jets of one shape along a new own axis (non-negative ``axis``)."""
        first = jets[0]
        mid = np.stack([j.mid for j in jets], axis=1 + axis)
        rad = np.stack([j.rad for j in jets], axis=1 + axis)
        return BallJet(mid, rad, first.n, first.order, first.packed)

    def expand(self, axis: int) -> BallJet:
        """Insert a unit axis into the array's own axes (negative: from the end)."""
        return self._like(np.expand_dims(self.mid, axis), np.expand_dims(self.rad, axis))

    def sum(self, axis: int) -> BallJet:
        """Sum along one of the array's own axes (negative: from the end)."""
        k = self.mid.shape[axis]
        mid = self.mid.sum(axis)
        return self._like(mid, _inflate(self.rad.sum(axis), k * np.abs(self.mid).sum(axis)))

    # ------------------------------------------------------------------ linear operations
    def __add__(self, other: BallJet) -> BallJet:
        mid = self.mid + other.mid
        return self._like(mid, _inflate(self.rad + other.rad, np.abs(self.mid) + np.abs(other.mid)))

    def __sub__(self, other: BallJet) -> BallJet:
        mid = self.mid - other.mid
        return self._like(mid, _inflate(self.rad + other.rad, np.abs(self.mid) + np.abs(other.mid)))

    def __neg__(self) -> BallJet:
        return self._like(-self.mid, self.rad)

    def scaled(self, c) -> BallJet:
        """Times an exact float array ``c`` (broadcast on the array's axes)."""
        c = np.asarray(c, float)
        return self._like(self.mid * c, _inflate(self.rad * np.abs(c), np.abs(self.mid * c)))

    def const_form(self, form: str, cmid, crad=0.0, *, left: bool = True) -> BallJet:
        """``f(C, self)`` (``left``) or ``f(self, C)`` for a constant ball ``C = cmid ± crad`` and a bilinear form."""
        f, fa = FORMS[form]
        cmid = np.asarray(cmid, float)
        crad = np.broadcast_to(np.asarray(crad, float), cmid.shape)
        am, ar = np.abs(self.mid), self.rad

        def g(fn, c, x):
            return fn(c, x) if left else fn(x, c)

        mid = g(f, cmid, self.mid)
        rad = g(fa, np.abs(cmid), ar) + g(fa, crad, am + ar)
        return self._like(mid, _inflate(rad, g(fa, np.abs(cmid), am)))

    # ------------------------------------------------------------------ products
    def form(self, form: str, other: BallJet) -> BallJet:
        """``f(self, other)`` for a bilinear form of :data:`FORMS`, with the product rule on the derivatives.

        Of two packed jets (:meth:`pack`): the product rule at the distinct
        multi-indices only, a packed jet.
        """
        if self.packed or other.packed:
            return self._packed_form(form, other)
        f, fa = FORMS[form]
        order, n = min(self.order, other.order), self.n

        ball = partial(_ball_form, f, fa)

        av, ag, aH, *aT = self._pieces(self.mid)
        bv, bg, bH, *bT = other._pieces(other.mid)
        avr, agr, aHr, *aTr = self._pieces(self.rad)
        bvr, bgr, bHr, *bTr = other._pieces(other.rad)
        parts = [ball(av, bv, avr, bvr)]
        if order >= 1:
            t1, t2 = ball(av, bg, avr, bgr), ball(ag, bv, agr, bvr)
            parts.append(tuple(x + y for x, y in zip(t1, t2)))
        if order >= 2:
            terms = [
                ball(av[None], bH, avr[None], bHr),
                ball(aH, bv[None], aHr, bvr[None]),
                ball(ag[:, None], bg[None, :], agr[:, None], bgr[None, :]),
                ball(ag[None, :], bg[:, None], agr[None, :], bgr[:, None]),
            ]
            H = [sum_terms(t[k] for t in terms) for k in range(3)]
            parts.append(tuple(x.reshape(n * n, *x.shape[2:]) for x in H))
        if order >= 3:  # d_pqr (ab): a T^b + T^a b + the three g H and the three H g pairings
            g_a, g_ar, H_a, H_ar = ag, agr, aH, aHr
            g_b, g_br, H_b, H_br = bg, bgr, bH, bHr
            P, Q, R = (slice(None), None, None), (None, slice(None), None), (None, None, slice(None))
            QR, PR, PQ = (
                (None, slice(None), slice(None)),
                (slice(None), None, slice(None)),
                (slice(None), slice(None), None),
            )
            terms = [
                ball(av[None, None], bT[0], avr[None, None], bTr[0]),
                ball(aT[0], bv[None, None], aTr[0], bvr[None, None]),
            ]
            for gi, Hi in ((P, QR), (Q, PR), (R, PQ)):
                terms.append(ball(g_a[gi], H_b[Hi], g_ar[gi], H_br[Hi]))
                terms.append(ball(H_a[Hi], g_b[gi], H_ar[Hi], g_br[gi]))
            T = [sum_terms(t[k] for t in terms) for k in range(3)]
            parts.append(tuple(x.reshape(n**3, *x.shape[3:]) for x in T))
        mid = np.concatenate([p[0] for p in parts])
        rad = np.concatenate([p[1] for p in parts])
        mag = np.concatenate([p[2] for p in parts])
        return BallJet(mid, _inflate(rad, mag), n, order)

    def _packed_form(self, form: str, other: BallJet) -> BallJet:
        """:meth:`form` of two packed jets: the whole product rule's floats at the sorted multi-indices."""
        if not (self.packed and other.packed):
            raise ValueError("a product of a packed and a whole jet")
        f, fa = FORMS[form]
        order, n = min(self.order, other.order), self.n

        ball = partial(_ball_form, f, fa)

        a_blocks, b_blocks = jet_layout(n, self.order).blocks, jet_layout(n, other.order).blocks
        av, ag, aH, aT = ([self.mid[k] for k in a_blocks] + [None])[:4]
        bv, bg, bH, bT = ([other.mid[k] for k in b_blocks] + [None])[:4]
        avr, agr, aHr, aTr = ([self.rad[k] for k in a_blocks] + [None])[:4]
        bvr, bgr, bHr, bTr = ([other.rad[k] for k in b_blocks] + [None])[:4]
        t1, t2 = ball(av, bg, avr, bgr), ball(ag, bv, agr, bvr)
        parts = [ball(av, bv, avr, bvr), tuple(x + y for x, y in zip(t1, t2))]
        # d_pl (ab) at p <= l: the terms in the order of form's, on the entries it reads there (the same floats)
        P, L = symmetric_indices(n, 2)[0]
        terms = [
            ball(av, bH, avr, bHr),
            ball(aH, bv, aHr, bvr),
            ball(ag[P], bg[L], agr[P], bgr[L]),
            ball(ag[L], bg[P], agr[L], bgr[P]),
        ]
        parts.append(tuple(sum_terms(t[k] for t in terms) for k in range(3)))
        if order >= 3:  # d_pqr (ab) at p <= q <= r: it reads H at (q, r), (p, r), (p, q), all sorted
            P, Q, R = symmetric_indices(n, 3)[0]
            terms = [ball(av, bT, avr, bTr), ball(aT, bv, aTr, bvr)]
            for gi, hi in zip((P, Q, R), jet_layout(n, 3).pairs):
                terms.append(ball(ag[gi], bH[hi], agr[gi], bHr[hi]))
                terms.append(ball(aH[hi], bg[gi], aHr[hi], bgr[gi]))
            parts.append(tuple(sum_terms(t[k] for t in terms) for k in range(3)))
        mid = np.concatenate([p[0] for p in parts])
        rad = np.concatenate([p[1] for p in parts])
        mag = np.concatenate([p[2] for p in parts])
        return BallJet(mid, _inflate(rad, mag), n, order, True)

    def __mul__(self, other: BallJet) -> BallJet:
        return self.form("mul", other)

    def __matmul__(self, other: BallJet) -> BallJet:
        return self.form("matmul", other)


def ball_sin_cos(centre, radius, order: int):
    """``(sin, cos)`` jets of the variables ``centre ± radius`` (shape ``(..., n)``: variable ``p`` is the last axis' ``p``)."""
    c, r = np.asarray(centre, float), np.asarray(radius, float)
    n = c.shape[-1]
    s0, c0 = np.sin(c), np.cos(c)
    half_r2 = 0.5 * r * r
    sin_b = (s0, np.abs(c0) * r + half_r2 + TRIG_MARGIN)
    cos_b = (c0, np.abs(s0) * r + half_r2 + TRIG_MARGIN)
    out = []
    for value, first, second in ((sin_b, cos_b, sin_b), (cos_b, sin_b, cos_b)):
        sign1 = 1.0 if value is sin_b else -1.0
        jet = BallJet.constant(value[0], _inflate(value[1], np.abs(value[0])), n, order)
        for p in range(n):
            if order >= 1:
                jet.mid[1 + p, ..., p] = sign1 * first[0][..., p]
                jet.rad[1 + p, ..., p] = first[1][..., p]
            if order >= 2:  # d2 sin = -sin, d2 cos = -cos
                jet.mid[1 + n + p * n + p, ..., p] = -second[0][..., p]
                jet.rad[1 + n + p * n + p, ..., p] = second[1][..., p]
            if order >= 3:  # d3 sin = -cos, d3 cos = sin
                jet.mid[1 + n + n * n + p * (n * n + n + 1), ..., p] = -sign1 * first[0][..., p]
                jet.rad[1 + n + n * n + p * (n * n + n + 1), ..., p] = first[1][..., p]
        out.append(jet)
    return tuple(out)


def upper(mid, rad):
    """A float above every point of the ball (radius and rounding margin included)."""
    s = mid + rad
    return s + GAMMA * (np.abs(mid) + rad) + TINY


def lower(mid, rad):
    """A float below every point of the ball."""
    s = mid - rad
    return s - GAMMA * (np.abs(mid) + rad) - TINY


def ball_inverse(mid, rad):
    """An enclosure ``(Ymid, Yrad)`` of the inverses of every matrix in ``mid ± rad`` (batched ``(..., m, m)``).

    With ``C`` a float inverse of the midpoint and ``E = I - C M`` (a ball),
    ``M^-1 = C + E C + E^2 M^-1`` and ``|M^-1| <= ||C||_inf / (1 - ||E||_inf)``
    entrywise.  Where ``||E||_inf >= 1`` (the matrices may be singular) the
    radius is ``inf``.
    """
    m = mid.shape[-1]
    C = np.linalg.inv(mid)
    one = BallJet.constant(np.broadcast_to(np.eye(m), mid.shape), 0.0, 0, 0)
    Mb = BallJet(mid[None], rad[None], 0, 0)
    E = one - Mb.const_form("matmul", C)
    EC = E.const_form("matmul", C, left=False)
    Eabs = np.abs(E.mid[0]) + E.rad[0]
    e_norm = upper(Eabs.sum(-1).max(-1), 0.0)
    c_norm = upper(np.abs(C).sum(-1).max(-1), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        y_max = np.where(e_norm < 1.0, upper(c_norm / (1.0 - e_norm), 0.0) * (1 + 1e-12), np.inf)
    tail = upper((Eabs @ Eabs).sum(-1), 0.0) * y_max[..., None]  # |E^2 Y|_ij <= (|E|^2 1)_i max|Y|
    Ymid = C + EC.mid[0]
    Yrad = _inflate(EC.rad[0] + tail[..., None], np.abs(C) + np.abs(EC.mid[0]))
    return Ymid, np.where(np.isfinite(Yrad), Yrad, np.inf)


def intersect(a: BallJet, b: BallJet) -> BallJet:
    """A ball jet inside both enclosures' union-free common part: each component's ``[lo, hi]`` intersected, rounded out.

    Both ``a`` and ``b`` hold the same function's components (same shape,
    variables, order), so their intersection does.  Two outward-rounded
    enclosures of one value always meet: where they do not, one of them is
    wrong, and that is an error, not a choice between them.  (A component
    that is not a number keeps the narrower ball, then an infinite radius.)
    """
    lo = np.maximum(lower(a.mid, a.rad), lower(b.mid, b.rad))
    hi = np.minimum(upper(a.mid, a.rad), upper(b.mid, b.rad))
    if np.any(lo > hi):
        raise CertificationError(
            f"two enclosures of the same quantity do not meet ({int(np.sum(lo > hi))} components): one of them is wrong"
        )
    narrower_a = a.rad <= b.rad
    mid = np.where(lo <= hi, 0.5 * (lo + hi), np.where(narrower_a, a.mid, b.mid))
    rad = np.where(lo <= hi, np.maximum(hi - mid, mid - lo), np.where(narrower_a, a.rad, b.rad))
    rad = np.where(np.isfinite(mid), rad * (1 + GAMMA) + GAMMA * np.abs(mid) + TINY, np.inf)
    mid = np.where(np.isfinite(mid), mid, 0.0)
    return BallJet(mid, rad, a.n, a.order)


def centre_radius(lo, hi):
    """``(centre, radius)`` of boxes with ``[lo, hi]`` inside ``centre ± radius`` (the radius rounded up).

    >>> import numpy as np
    >>> c, r = centre_radius(np.array([0.1]), np.array([0.3]))
    >>> bool(c[0] - r[0] <= 0.1 and 0.3 <= c[0] + r[0])
    True
    """
    c = 0.5 * (lo + hi)
    r = np.maximum(hi - c, c - lo)
    return c, np.where(r > 0, np.nextafter(r, np.inf) * (1 + 4e-16), 0.0)
