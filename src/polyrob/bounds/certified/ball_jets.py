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

Examples
--------
>>> import numpy as np
>>> x = BallJet.variables(np.array([0.1]), np.array([0.0]), order=1)   # x = 0.1 exactly, dx/dx = 1
>>> y = x * x                                                          # y = x^2, dy/dx = 2x
>>> bool(y.mid[0, 0] - y.rad[0, 0] <= 0.1 * 0.1 <= y.mid[0, 0] + y.rad[0, 0]), float(y.mid[1, 0])
(True, 0.2)
"""

from __future__ import annotations

import numpy as np

from polyrob.errors import CertificationError

__all__ = ["BallJet", "GAMMA", "TINY", "ball_sin_cos", "ball_inverse", "intersect", "upper", "lower", "centre_radius"]

#: Relative margin added to every result for the rounding of float sums (``k u`` for ``k`` terms, ``k <= 90``).
GAMMA = 1e-14
#: Absolute margin added to every radius (underflow of tiny products).
TINY = 1e-300
#: Margin of the library's sin/cos beyond the exact value (4 ulps of a number of modulus <= 1).
TRIG_MARGIN = 4.5e-16


def _cross(x, y):
    return np.stack(
        [x[..., 1] * y[..., 2] - x[..., 2] * y[..., 1],
         x[..., 2] * y[..., 0] - x[..., 0] * y[..., 2],
         x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]], axis=-1)  # fmt: skip


def _cross_abs(x, y):
    """The bilinear form with the absolute coefficients of the cross product (bounds ``|x × y|``)."""
    return np.stack(
        [x[..., 1] * y[..., 2] + x[..., 2] * y[..., 1],
         x[..., 2] * y[..., 0] + x[..., 0] * y[..., 2],
         x[..., 0] * y[..., 1] + x[..., 1] * y[..., 0]], axis=-1)  # fmt: skip


def _mul(x, y):
    return x * y


def _matvec(x, y):
    # a sum over the (short) last axis, not einsum: einsum's broadcasting over the jets' many leading axes is slow
    out = x[..., 0] * y[..., None, 0]
    for j in range(1, x.shape[-1]):
        out = out + x[..., j] * y[..., None, j]
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


class BallJet:
    """Balls of a value and its derivatives (order 0 to 3 in ``n`` variables), vectorised.

    ``mid`` and ``rad`` have shape ``(C, *shape)`` with ``C = 1``, ``1 + n``,
    ``1 + n + n^2`` or ``1 + n + n^2 + n^3``: component 0 is the value,
    ``1 .. n`` the gradient, then the Hessian and the third derivatives
    (row-major).
    """

    __slots__ = ("mid", "rad", "n", "order")

    def __init__(self, mid, rad, n: int, order: int):
        self.mid, self.rad, self.n, self.order = mid, rad, int(n), int(order)

    # ------------------------------------------------------------------ construction
    @staticmethod
    def size(n: int, order: int) -> int:
        """Number of components of a jet."""
        return 1 + (n if order >= 1 else 0) + (n * n if order >= 2 else 0) + (n**3 if order >= 3 else 0)

    @classmethod
    def constant(cls, mid, rad, n: int, order: int) -> BallJet:
        """A ball ``mid ± rad`` whose derivatives are zero."""
        mid, rad = np.asarray(mid, float), np.broadcast_to(np.asarray(rad, float), np.shape(mid))
        C = cls.size(n, order)
        M, R = np.zeros((C, *mid.shape)), np.zeros((C, *mid.shape))
        M[0], R[0] = mid, rad
        return cls(M, R, n, order)

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

    def constant_like(self, mid, rad) -> BallJet:
        """A ball ``mid ± rad`` with zero derivatives, in this jet's variables and order."""
        return BallJet.constant(mid, rad, self.n, self.order)

    # ------------------------------------------------------------------ pieces
    def value(self) -> BallJet:
        """The value alone (order 0)."""
        return BallJet(self.mid[:1], self.rad[:1], self.n, 0)

    def _pieces(self, arr):
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
        C = self.size(self.n, order)
        return BallJet(self.mid[:C], self.rad[:C], self.n, order)

    def derivative_value(self, index: int) -> BallJet:
        """The derivative ``index`` as an order-0 ball."""
        return BallJet(self.mid[1 + index : 2 + index], self.rad[1 + index : 2 + index], self.n, 0)

    @property
    def shape(self):
        return self.mid.shape[1:]

    def __getitem__(self, key) -> BallJet:
        key = key if isinstance(key, tuple) else (key,)
        return BallJet(self.mid[(slice(None), *key)], self.rad[(slice(None), *key)], self.n, self.order)

    def swap(self, a: int, b: int) -> BallJet:
        """Swap two of the array's own axes (negative indices count from its end)."""
        return BallJet(np.swapaxes(self.mid, a, b), np.swapaxes(self.rad, a, b), self.n, self.order)

    def transpose(self, *axes: int) -> BallJet:
        """Permute the array's own axes (``axes`` as for :func:`numpy.transpose` of the array without components)."""
        full = (0, *(1 + a for a in axes))
        return BallJet(np.transpose(self.mid, full), np.transpose(self.rad, full), self.n, self.order)

    def reshape(self, *shape: int) -> BallJet:
        """The array's own axes reshaped."""
        C = self.mid.shape[0]
        return BallJet(self.mid.reshape(C, *shape), self.rad.reshape(C, *shape), self.n, self.order)

    @staticmethod
    def stack(jets, axis: int) -> BallJet:
        """Stack jets of one shape along a new own axis (non-negative ``axis``)."""
        first = jets[0]
        mid = np.stack([j.mid for j in jets], axis=1 + axis)
        rad = np.stack([j.rad for j in jets], axis=1 + axis)
        return BallJet(mid, rad, first.n, first.order)

    def expand(self, axis: int) -> BallJet:
        """Insert a unit axis into the array's own axes (negative: from the end)."""
        return BallJet(np.expand_dims(self.mid, axis), np.expand_dims(self.rad, axis), self.n, self.order)

    def sum(self, axis: int) -> BallJet:
        """Sum along one of the array's own axes (negative: from the end)."""
        k = self.mid.shape[axis]
        mid = self.mid.sum(axis)
        return BallJet(mid, _inflate(self.rad.sum(axis), k * np.abs(self.mid).sum(axis)), self.n, self.order)

    # ------------------------------------------------------------------ linear operations
    def __add__(self, other: BallJet) -> BallJet:
        mid = self.mid + other.mid
        return BallJet(mid, _inflate(self.rad + other.rad, np.abs(self.mid) + np.abs(other.mid)), self.n, self.order)

    def __sub__(self, other: BallJet) -> BallJet:
        mid = self.mid - other.mid
        return BallJet(mid, _inflate(self.rad + other.rad, np.abs(self.mid) + np.abs(other.mid)), self.n, self.order)

    def __neg__(self) -> BallJet:
        return BallJet(-self.mid, self.rad, self.n, self.order)

    def scaled(self, c) -> BallJet:
        """Times an exact float array ``c`` (broadcast on the array's axes)."""
        c = np.asarray(c, float)
        return BallJet(self.mid * c, _inflate(self.rad * np.abs(c), np.abs(self.mid * c)), self.n, self.order)

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
        return BallJet(mid, _inflate(rad, g(fa, np.abs(cmid), am)), self.n, self.order)

    # ------------------------------------------------------------------ products
    def form(self, form: str, other: BallJet) -> BallJet:
        """``f(self, other)`` for a bilinear form of :data:`FORMS`, with the product rule on the derivatives."""
        f, fa = FORMS[form]
        order, n = min(self.order, other.order), self.n

        def ball(x, y, xr, yr):
            xm, ym = np.abs(x), np.abs(y)
            return f(x, y), fa(xm, yr) + fa(xr, ym + yr), fa(xm, ym)

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
            H = [sum(t[k] for t in terms) for k in range(3)]
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
            T = [sum(t[k] for t in terms) for k in range(3)]
            parts.append(tuple(x.reshape(n**3, *x.shape[3:]) for x in T))
        mid = np.concatenate([p[0] for p in parts])
        rad = np.concatenate([p[1] for p in parts])
        mag = np.concatenate([p[2] for p in parts])
        return BallJet(mid, _inflate(rad, mag), n, order)

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
