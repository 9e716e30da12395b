"""Rigorous enclosures of the Jacobian coefficients of serial-chain dynamics on a q-box.

Used by :mod:`polyrob.bounds.certified.enclosure`.  Pinocchio cannot compute with
interval scalars, so the dynamics are rebuilt exactly as polynomials
(:class:`~polyrob.bounds.certified.symbolic_rbd.SymbolicDynamics`); on a q-box,
``M^-1`` and every Jacobian entry's coefficients (as a polynomial in
``qdot`` and ``u``) are then enclosed by order-2 Taylor models
(:mod:`polyrob.bounds.certified.taylor_models`) evaluated in ball arithmetic, which
rounds outward: every value is a rigorous enclosure.
"""

from __future__ import annotations

from flint import arb, arb_mat

from polyrob.bounds.certified.balls import arb_lower, arb_upper
from polyrob.bounds.certified.symbolic_rbd import SymbolicDynamics, joint_axes
from polyrob.bounds.certified.taylor_models import TaylorContext, const_tm, interval_inverse, inverse_tm, poly_tm

__all__ = [
    "SymbolicDynamics",
    "joint_axes",
    "interval_inverse",
    "arb_upper",
    "arb_lower",
    "box_coefficients",
    "entry_list",
    "entry_terms",
    "entry_depends",
]


def entry_list(m: int) -> list[tuple[str, int, int]]:
    """All varying entries, in the order :func:`box_coefficients` returns them.

    ``("B", i, j)`` = ``Minv[i, j]`` (i <= j; ``Minv`` is symmetric),
    ``("Av", i, j)`` = ``d qdd_i / d qdot_j``, ``("Aq", i, k)`` = ``d qdd_i / d q_k``.
    """
    return (
        [("B", i, j) for i in range(m) for j in range(i, m)]
        + [("Av", i, j) for i in range(m) for j in range(m)]
        + [("Aq", i, k) for i in range(m) for k in range(m)]
    )


def _coef_rows(sd, d, Minv, W, T, MG, cq):
    """Basis coefficient lists of every entry (linear in its matrix arguments)."""
    m, P = sd.m, len(sd.pairs)
    nb = 1 + 2 * m + P
    zero = arb(0)
    pidx = {pr: n for n, pr in enumerate(sd.pairs)}
    out = []
    for i in range(m):
        for j in range(i, m):
            out.append([Minv[i, j]] + [zero] * (nb - 1))
    for i in range(m):
        for j in range(m):
            row = [zero] * nb
            row[0] = -Minv[i, j] * d[j]
            for l in range(m):
                row[1 + m + l] = -2 * MG[i, pidx[(min(j, l), max(j, l))]]
            out.append(row)
    for i in range(m):
        for k in range(m):
            row = [cq[k][i, 0]]
            row += [-W[k][i, j] for j in range(m)]
            row += [W[k][i, j] * d[j] for j in range(m)]
            row += [(1 if j == l else 2) * T[k][i, n] for n, (j, l) in enumerate(sd.pairs)]
            out.append(row)
    return out


def _coefficient_tms(sd, get_c, get_b, ctx):
    """Taylor models of (Minv, W_k, T_k, MG, cq_k): every coefficient is linear in these.

    ``qdd = Minv (u - D v - Gamma(v, v) - g)`` gives
    ``d qdd/d q_k = -W_k u + W_k D v + T_k(v, v) + cq_k`` with
    ``W_k = Minv dM_k Minv``, ``T_k = W_k Gamma - Minv dGamma_k``,
    ``cq_k = W_k g - Minv dg_k``; and ``d qdd/d v = -Minv (2 Gamma v + D)``.
    """
    m, P = sd.m, len(sd.pairs)

    def mkey(i, j):
        return ("M", min(i, j), max(i, j))

    def gkey(r, n):
        return ("G", r, n)

    def vkey(r, _):
        return ("g", r)

    Minv = inverse_tm(poly_tm(ctx, get_c, get_b, mkey, (m, m)))
    if Minv is None:
        return None
    G = poly_tm(ctx, get_c, get_b, gkey, (m, P))
    g = poly_tm(ctx, get_c, get_b, vkey, (m, 1))
    W, T, cq = [], [], []
    for k in range(m):
        if all(sd.index[("M", i, j, (k,))] is None for i in range(m) for j in range(i, m)):
            Wk = None  # M does not depend on q_k: W_k = 0 exactly
        else:
            Wk = Minv * poly_tm(ctx, get_c, get_b, mkey, (m, m), (k,)) * Minv
        dG = poly_tm(ctx, get_c, get_b, gkey, (m, P), (k,))
        dg = poly_tm(ctx, get_c, get_b, vkey, (m, 1), (k,))
        zero = const_tm(ctx, arb_mat(m, m))
        W.append(Wk if Wk is not None else zero)
        T.append((Wk * G if Wk is not None else const_tm(ctx, arb_mat(m, P))) - Minv * dG)
        cq.append((Wk * g if Wk is not None else const_tm(ctx, arb_mat(m, 1))) - Minv * dg)
    return Minv, W, T, Minv * G, cq


def box_coefficients(sd: SymbolicDynamics, damping, q_lo, q_hi):
    """Order-2 Taylor models of every entry's coefficients on a q-box.

    Every varying entry of ``A``, ``B`` is, for fixed ``q``, a polynomial in
    ``(qdot, u)`` with basis ``[1, u_1..u_m, v_1..v_m, v_j v_l (j <= l)]``
    and coefficients ``c(q)``.  With ``qc`` the box centre and
    ``delta = q - qc`` in the box::

        c(q) in c0 + sum_p c1[p] delta_p + sum_{p<=q} c2[p,q] delta_p delta_q + R

    Returns ``(c0, c1, c2, R, delta)``: ``c0[e]`` the coefficient list of entry
    ``e`` (order of :func:`entry_list`), ``c1[p][e]``, ``c2[(p, q)][e]`` and
    ``R[e]`` likewise (``R`` is None when ``M`` is not provably invertible on
    the box), ``delta[p]`` the ball ``Q_p - qc_p``.  Only coordinates ``p`` on
    which the dynamics depend and whose range is not a point appear.  ``c0``
    is None if ``M`` is not provably invertible at ``qc``.
    """
    m = sd.m
    d = [arb(float(x)) for x in damping]
    qc = [min(max(0.5 * (float(a) + float(b)), float(a)), float(b)) for a, b in zip(q_lo, q_hi)]
    box = [arb(float(a)).union(arb(float(b))) if a != b else arb(float(a)) for a, b in zip(q_lo, q_hi)]
    dims = [p for p in range(m) if sd.depends[p] and q_lo[p] != q_hi[p]]
    delta = {p: box[p] - arb(qc[p]) for p in dims}
    ctx = TaylorContext(dims, delta)
    get_c = sd.evaluate([arb(x) for x in qc])
    get_b = sd.evaluate(box) if dims else get_c
    tms = _coefficient_tms(sd, get_c, get_b, ctx)
    if tms is None:
        Mc = arb_mat([[get_c(("M", min(i, j), max(i, j))) for j in range(m)] for i in range(m)])
        if interval_inverse(Mc) is None:
            return None, None, None, None, delta
        return _centre_only(sd, d, get_c, ctx) + (None, delta)
    Minv, W, T, MG, cq = tms

    def rows(f):
        return _coef_rows(sd, d, f(Minv), [f(x) for x in W], [f(x) for x in T], f(MG), [f(x) for x in cq])

    c0 = rows(lambda t: t.c0)
    c1 = {p: rows(lambda t: t.c1[p]) for p in dims}
    c2 = {k: rows(lambda t: t.c2[k]) for k in ctx.pairs}
    return c0, c1, c2, rows(lambda t: t.R), delta


def _centre_only(sd, d, get_c, ctx):
    """``(c0, c1, c2)`` at the centre when the box is too wide for a Taylor model."""
    ctx0 = TaylorContext(ctx.dims, {p: arb(0) for p in ctx.dims})
    Minv, W, T, MG, cq = _coefficient_tms(sd, get_c, get_c, ctx0)

    def rows(f):
        return _coef_rows(sd, d, f(Minv), [f(x) for x in W], [f(x) for x in T], f(MG), [f(x) for x in cq])

    return (
        rows(lambda t: t.c0),
        {p: rows(lambda t: t.c1[p]) for p in ctx.dims},
        {k: rows(lambda t: t.c2[k]) for k in ctx.pairs},
    )


def entry_terms(sd: SymbolicDynamics, damping) -> list[set]:
    """Basis indices each entry can depend on (structural; see :func:`box_coefficients`).

    Used to enumerate only the u-vertices / qdot-vertices an entry needs.
    """
    m, P = sd.m, len(sd.pairs)

    def nz(name, rng, o=()):
        return any(sd.index[(name,) + key + (o,)] is not None for key in rng)

    mkeys = [(i, j) for i in range(m) for j in range(i, m)]
    gkeys = [(r, n) for r in range(m) for n in range(P)]
    vkeys = [(r,) for r in range(m)]
    Gnz, gnz = nz("G", gkeys), nz("g", vkeys)
    out = [{0} for i in range(m) for j in range(i, m)]
    for _ in range(m):
        for j in range(m):
            out.append(({0} if damping[j] != 0 else set()) | ({1 + m + l for l in range(m)} if Gnz else set()))
    for _ in range(m):
        for k in range(m):
            Mk = nz("M", mkeys, (k,))
            t = {0} if (Mk and gnz) or nz("g", vkeys, (k,)) else set()
            if Mk:
                t |= {1 + j for j in range(m)} | {1 + m + j for j in range(m) if damping[j] != 0}
            if (Mk and Gnz) or nz("G", gkeys, (k,)):
                t |= {1 + 2 * m + n for n in range(P)}
            out.append(t)
    return out


def entry_depends(sd: SymbolicDynamics) -> list[set]:
    """Joints each entry depends on (exact, from the polynomials' monomials).

    An entry that does not depend on ``q_p`` has the same range on both halves
    of a box split along ``p``, so the branch and bound follows it in one half only.
    """
    m = sd.m
    pos = {}
    for key, n in sd.index.items():
        if n is not None and len(key[-1]) <= 1:
            pos.setdefault((key[0],) + (key[-1],), []).append(n)
    rows = {}
    for (name, o), ns in pos.items():
        js = set()
        for n in ns:
            for mono, c in zip(sd.monos, [sd.coef[n, t] for t in range(len(sd.monos))]):
                if not c.is_zero():
                    js |= {i for i, (ci, si) in enumerate(sd.var_index) if mono[ci] or (si is not None and mono[si])}
        rows[name, o] = js

    def dep(name, o=()):
        return rows.get((name, o), set())

    base = dep("M") | {p for k in range(m) for p in dep("M", (k,))}  # Minv and its derivative
    out = [dep("M") for i in range(m) for j in range(i, m)]
    out += [dep("M") | dep("G") for i in range(m) for j in range(m)]
    for _ in range(m):
        for k in range(m):
            out.append(base | dep("G") | dep("G", (k,)) | dep("g") | dep("g", (k,)))
    return out
