"""Rigorous interval evaluation of serial-chain rigid-body dynamics.

Used by :mod:`polyrob.bounds.certify`.  Pinocchio cannot compute with interval
scalars, so the dynamics are rebuilt here from the model's joint placements,
axes and inertias.

Why symbolic, and why exact
---------------------------
For a chain of revolute and prismatic joints, ``M(q)``, the Christoffel symbols
``Gamma(q)`` (``h = sum Gamma_rjl qdot_j qdot_l + g``) and the gravity torque
``g(q)`` are polynomials in ``(cos q_i, sin q_i)`` (revolute) and ``q_i``
(prismatic).  We compute them once per robot as polynomials with *exact
rational* coefficients (``flint.fmpq_mpoly``; the model's floats are exact
rationals), reduced modulo ``sin^2 + cos^2 = 1``.  Exactness matters: terms
that cancel mathematically (e.g. the dependence of ``M`` on the first joint)
cancel exactly instead of leaving interval "dust", and the joints the dynamics
do not depend on are known structurally.  Derivatives of any order are then
exact polynomial derivatives (chosen over forward-mode AD on ``arb``: the
Taylor models of :func:`box_coefficients` need derivatives of ``M``, ``Gamma``
and ``g`` up to order 4 on every box, and evaluating all of them is a single
``arb_mat`` product in C, far cheaper than nested dual numbers in Python).
On top of them, ``M^-1`` and the Jacobian coefficients are built as order-2
Taylor models (:class:`_TM`), which keep the dependency between the factors
that plain interval arithmetic loses.

Evaluating the polynomials on a box uses ``flint.arb`` ball arithmetic, which
rounds outward, so every value is a rigorous enclosure.

Model semantics: the float parameters are taken as exact.  Joint rotations
are exactly orthonormal (``cos^2 + sin^2 = 1``); the formulas also use
``R^T R = I`` for the joint placements, whose float rotation matrices are
orthonormal only to ~1e-16 (the resolution of the URDF itself);
:class:`SymbolicDynamics` refuses placements that are off by more than 1e-12.
"""

from __future__ import annotations

from fractions import Fraction
from itertools import combinations_with_replacement

import numpy as np
from flint import arb, arb_mat, fmpq, fmpq_mpoly_ctx

from polyrob.errors import CertificationError

__all__ = ["SymbolicDynamics", "joint_axes", "interval_inverse", "arb_upper", "arb_lower", "box_coefficients",
           "entry_list"]


def arb_upper(x: arb) -> float:
    """Float >= every point of ``x`` (``float()`` rounds to nearest: fix up)."""
    u = x.upper()  # exact (radius-zero) ball
    f = float(u)
    if not arb(f) >= u:  # exact comparison of two exact balls
        f = float(np.nextafter(f, np.inf))
    return f


def arb_lower(x: arb) -> float:
    """Float <= every point of ``x``."""
    lo = x.lower()
    f = float(lo)
    if not arb(f) <= lo:
        f = float(np.nextafter(f, -np.inf))
    return f


def _q(x: float) -> fmpq:
    fr = Fraction(float(x))  # exact binary rational of the float
    return fmpq(fr.numerator, fr.denominator)


def joint_axes(model) -> list[tuple[str, np.ndarray]]:
    """``[(kind, axis)]`` per joint, kind ``"R"`` (revolute/continuous) or ``"P"``.

    Raises :class:`CertificationError` for any other joint type or a model
    that is not a serial chain.
    """
    out = []
    unit = {"X": np.array([1.0, 0, 0]), "Y": np.array([0, 1.0, 0]), "Z": np.array([0, 0, 1.0])}
    for i in range(1, model.njoints):
        if model.parents[i] != i - 1:
            raise CertificationError(f"certified bounds need a serial chain; joint {i} has parent {model.parents[i]}")
        j = model.joints[i]
        name = j.shortname().replace("JointModel", "")
        if j.nv != 1:
            raise CertificationError(f"joint {model.names[i]!r} ({name}) is not a one-DoF joint")
        if name in ("RX", "RY", "RZ", "RUBX", "RUBY", "RUBZ"):
            out.append(("R", unit[name[-1]]))
        elif name in ("PX", "PY", "PZ"):
            out.append(("P", unit[name[-1]]))
        elif name in ("RevoluteUnaligned", "RevoluteUnboundedUnaligned", "PrismaticUnaligned"):
            axis = np.asarray(j.extract().axis, dtype=float)
            out.append(("P" if name.startswith("Prismatic") else "R", axis))
        else:
            raise CertificationError(f"joint {model.names[i]!r} of type {name} is not supported by certified bounds")
    return out


def interval_inverse(A: arb_mat):
    """Enclosure of ``A^-1`` for every matrix in the interval matrix ``A``, or None.

    Preconditioned (Hansen/Krawczyk-style) form: with ``R`` the float inverse of
    ``mid(A)`` and ``E = I - R A``, ``A^-1 = (I + E + Z) R`` where
    ``|Z_ij| <= ||E||^2 / (1 - ||E||)``.  Unlike interval Gaussian elimination
    this stays first-order tight on wide boxes.  None when ``||E|| >= 1``.
    """
    n = A.nrows()
    mid = np.array([[float(A[i, j].mid()) for j in range(n)] for i in range(n)])
    try:
        Rf = np.linalg.inv(mid)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(Rf)):
        return None
    R = arb_mat([[arb(float(Rf[i, j])) for j in range(n)] for i in range(n)])
    I = arb_mat([[arb(1 if i == j else 0) for j in range(n)] for i in range(n)])
    E = I - R * A
    # (Python's max() on overlapping balls may pick the wrong one: compare floats)
    beta = arb(max(arb_upper(sum(abs(E[i, j]) for j in range(n))) for i in range(n)))
    if not beta < 1:
        return None
    z = beta * beta / (1 - beta)
    zr = arb(0, arb_upper(z)) if z.is_finite() else None
    if zr is None:
        return None
    Z = arb_mat([[zr for _ in range(n)] for _ in range(n)])
    return (I + E + Z) * R


class SymbolicDynamics:
    """Exact polynomial form of ``M``, ``Gamma``, ``g`` and their derivatives.

    Parameters
    ----------
    model : pinocchio.Model
        Serial chain of one-DoF revolute/continuous/prismatic joints.

    Attributes
    ----------
    m : int
        Number of joints.
    kinds : list of str
        ``"R"`` or ``"P"`` per joint.
    depends : numpy.ndarray of bool
        ``depends[k]``: some dynamics polynomial involves joint ``k``
        (exact, structural).
    """

    def __init__(self, model):
        self.kinds_axes = joint_axes(model)
        self.m = len(self.kinds_axes)
        self.kinds = [k for k, _ in self.kinds_axes]
        names, self._var = [], []  # _var[i] = (index of c or p, index of s or None)
        for i, k in enumerate(self.kinds):
            if k == "R":
                self._var.append((len(names), len(names) + 1))
                names += [f"c{i}", f"s{i}"]
            else:
                self._var.append((len(names), None))
                names.append(f"p{i}")
        self.nvars = len(names)
        self.ctx = fmpq_mpoly_ctx.get(tuple(names), "lex")
        self._build(model)

    # ---- polynomial helpers -------------------------------------------------
    def _reduce(self, P):
        """Canonical form: every sin exponent <= 1 (s^2 -> 1 - c^2)."""
        d = P.to_dict()
        sidx = [(ci, si) for ci, si in self._var if si is not None]
        if not any(e[si] >= 2 for e in d for _, si in sidx):
            return P
        ctx, out = self.ctx, self.ctx.from_dict({})
        gens = ctx.gens()
        for e, coef in d.items():
            e = list(e)
            term = ctx.constant(coef)
            for ci, si in sidx:
                k = e[si] // 2
                if k:
                    e[si] -= 2 * k
                    term = term * (1 - gens[ci] ** 2) ** k
            out = out + ctx.from_dict({tuple(e): 1}) * term
        return out

    def _dq(self, P, i):
        """d P / d q_i (chain rule through cos/sin for revolute joints)."""
        ci, si = self._var[i]
        if si is None:
            return P.derivative(ci)
        c, s = self.ctx.gens()[ci], self.ctx.gens()[si]
        return self._reduce(c * P.derivative(si) - s * P.derivative(ci))

    def _matmul(self, A, B):
        return [[self._reduce(sum((A[i][k] * B[k][j] for k in range(3)), self.ctx.from_dict({})))
                 for j in range(len(B[0]))] for i in range(len(A))]

    def _const(self, x):
        return self.ctx.constant(_q(x))

    # ---- build --------------------------------------------------------------
    def _build(self, model):
        m, ctx, gens = self.m, self.ctx, self.ctx.gens()
        zero = ctx.from_dict({})
        C = self._const
        # local transforms (i-1)T_i = placement_i * joint_i(q_i), as polynomials
        Tloc = []
        for i, (kind, a) in enumerate(self.kinds_axes):
            pl = model.jointPlacements[i + 1]
            Rp = np.asarray(pl.rotation)
            if np.abs(Rp.T @ Rp - np.eye(3)).max() > 1e-12:
                raise CertificationError(f"placement of joint {model.names[i + 1]!r} is not a rotation")
            Rpl = [[C(Rp[r, c]) for c in range(3)] for r in range(3)]
            ppl = [C(x) for x in np.asarray(pl.translation)]
            aq = [_q(x) for x in a]
            if kind == "R":
                cv, sv = gens[self._var[i][0]], gens[self._var[i][1]]
                K = [[0, -aq[2], aq[1]], [aq[2], 0, -aq[0]], [-aq[1], aq[0], 0]]
                # Rodrigues as Pinocchio: c I + s K + (1 - c) a a^T
                Rj = [[cv * (1 if r == c else 0) + sv * K[r][c] + (1 - cv) * aq[r] * aq[c] for c in range(3)]
                      for r in range(3)]
                pj = [zero, zero, zero]
            else:
                pv = gens[self._var[i][0]]
                Rj = [[ctx.constant(1 if r == c else 0) for c in range(3)] for r in range(3)]
                pj = [pv * aq[r] for r in range(3)]
            R = self._matmul(Rpl, Rj)
            p = [ppl[r] + sum((Rpl[r][k] * pj[k] for k in range(3)), zero) for r in range(3)]
            Tloc.append((R, p))
        # T[j][b] = jT_b for frames 0 (base) .. m, j <= b
        eye = [[ctx.constant(1 if r == c else 0) for c in range(3)] for r in range(3)]
        T = [[None] * (m + 1) for _ in range(m + 1)]
        for j in range(m + 1):
            T[j][j] = (eye, [zero, zero, zero])
            for b in range(j + 1, m + 1):
                Rjb, pjb = T[j][b - 1]
                Rl, pl_ = Tloc[b - 1]
                R = self._matmul(Rjb, Rl)
                p = [self._reduce(pjb[r] + sum((Rjb[r][k] * pl_[k] for k in range(3)), zero)) for r in range(3)]
                T[j][b] = (R, p)
        inert = [model.inertias[i + 1] for i in range(m)]
        mass = [_q(I.mass) for I in inert]
        lever = [[C(x) for x in np.asarray(I.lever)] for I in inert]
        Ic = [[[C(x) for x in row] for row in np.asarray(I.inertia)] for I in inert]
        axes = [[_q(x) for x in a] for _, a in self.kinds_axes]

        def com(j, b):  # CoM of body b (1-based) in frame j
            R, p = T[j][b]
            return [self._reduce(p[r] + sum((R[r][k] * lever[b - 1][k] for k in range(3)), zero)) for r in range(3)]

        def cross(a, v):
            return [a[1] * v[2] - a[2] * v[1], a[2] * v[0] - a[0] * v[2], a[0] * v[1] - a[1] * v[0]]

        def vel(j, b):  # CoM velocity of body b per unit qdot_j, frame j (1-based j)
            a = axes[j - 1]
            if self.kinds[j - 1] == "P":
                return [ctx.constant(x) for x in a]
            return cross(a, com(j, b))

        # M_jk = sum_b m_b w_jb^T (jR_k) w_kb + a_j^T jR_k (kR_b I_b kR_b^T) a_k ;
        # grouped so that every factor has degree <= 1 per joint (no RR^T products)
        Msym = [[zero] * m for _ in range(m)]
        for j in range(1, m + 1):
            for k in range(j, m + 1):
                Rjk = T[j][k][0]
                tot = zero
                for b in range(k, m + 1):
                    wj, wk = vel(j, b), vel(k, b)
                    Rwk = [sum((Rjk[r][c] * wk[c] for c in range(3)), zero) for r in range(3)]
                    tot += mass[b - 1] * self._reduce(sum((wj[r] * Rwk[r] for r in range(3)), zero))
                    if self.kinds[j - 1] == "R" and self.kinds[k - 1] == "R":
                        Rkb = T[k][b][0]
                        Ib = self._matmul(self._matmul(Rkb, Ic[b - 1]), [[Rkb[c][r] for c in range(3)] for r in range(3)])
                        Ia = [sum((Ib[r][c] * axes[k - 1][c] for c in range(3)), zero) for r in range(3)]
                        RIa = [sum((Rjk[r][c] * Ia[c] for c in range(3)), zero) for r in range(3)]
                        tot += self._reduce(sum((axes[j - 1][r] * RIa[r] for r in range(3)), zero))
                if j == k:
                    tot += C(model.armature[j - 1])
                Msym[j - 1][k - 1] = Msym[k - 1][j - 1] = self._reduce(tot)
        grav = [_q(x) for x in np.asarray(model.gravity.linear)]
        V = zero
        for b in range(1, m + 1):
            cb = com(0, b)
            V -= mass[b - 1] * sum((grav[r] * cb[r] for r in range(3)), zero)
        V = self._reduce(V)
        dM = [[[self._dq(Msym[i][j], k) for k in range(m)] for j in range(m)] for i in range(m)]
        self.pairs = [(j, l) for j in range(m) for l in range(j, m)]
        # Christoffel symbols of the first kind: h_r = sum_{j,l} G_r[j,l] v_j v_l + g_r
        half = fmpq(1, 2)
        Gam = [[(dM[r][j][l] + dM[r][l][j] - dM[j][l][r]) * half for (j, l) in self.pairs] for r in range(m)]
        gvec = [self._dq(V, r) for r in range(m)]
        # register every polynomial and its derivatives up to order 4: the Taylor
        # models of dM_k, dGamma_k, dg_k need their third derivatives
        polys, self.index = [], {}

        def register(key, P):
            ders = {(): P}
            for k in range(m):
                ders[(k,)] = self._dq(P, k)
            for k, p in combinations_with_replacement(range(m), 2):
                ders[(k, p)] = self._dq(ders[(k,)], p)
            for k, p, r in combinations_with_replacement(range(m), 3):
                ders[(k, p, r)] = self._dq(ders[(k, p)], r)
            for k, p, r, t in combinations_with_replacement(range(m), 4):
                ders[(k, p, r, t)] = self._dq(ders[(k, p, r)], t)
            for o, D in ders.items():
                self.index[key + (o,)] = None if D.is_zero() else len(polys)
                if not D.is_zero():
                    polys.append(D)

        for i in range(m):
            for j in range(i, m):
                register(("M", i, j), Msym[i][j])
        for r in range(m):
            for pi in range(len(self.pairs)):
                register(("G", r, pi), Gam[r][pi])
            register(("g", r), gvec[r])
        self.depends = np.zeros(m, dtype=bool)
        monos = sorted({e for P in polys for e in P.to_dict()})
        for e in monos:
            for i, (ci, si) in enumerate(self._var):
                if e[ci] or (si is not None and e[si]):
                    self.depends[i] = True
        self.monos = monos
        self.maxdeg = [max([e[v] for e in monos] + [0]) for v in range(self.nvars)]
        mpos = {e: n for n, e in enumerate(monos)}
        rows = []
        for P in polys:
            row = [arb(0)] * len(monos)
            for e, cf in P.to_dict().items():
                row[mpos[e]] = arb(cf)  # rigorous ball around the exact rational
            rows.append(row)
        self.coef = arb_mat(rows) if rows else None
        self.npolys = len(polys)
        self.Msym, self.V = Msym, V

    # ---- evaluation ---------------------------------------------------------
    def evaluate(self, qballs):
        """Values of all registered polynomials for ``q`` in the balls ``qballs``.

        Returns a function ``get(key, order)`` giving an ``arb`` (exact 0 for
        structurally zero polynomials).
        """
        vals = [None] * self.nvars
        for i, (ci, si) in enumerate(self._var):
            if si is None:
                vals[ci] = qballs[i]
            else:
                vals[ci], vals[si] = qballs[i].cos(), qballs[i].sin()
        pw = []
        for v in range(self.nvars):
            lst = [arb(1)]
            for _ in range(self.maxdeg[v]):
                lst.append(lst[-1] * vals[v])
            pw.append(lst)
        mv = []
        for e in self.monos:
            x = arb(1)
            for v, ev in enumerate(e):
                if ev:
                    x = x * pw[v][ev]
            mv.append([x])
        y = self.coef * arb_mat(mv) if self.coef is not None else None
        zero = arb(0)
        index = self.index

        def get(key, order=()):
            n = index[key + (tuple(sorted(order)),)]
            return zero if n is None else y[n, 0]

        return get


def entry_list(m: int) -> list[tuple[str, int, int]]:
    """All varying entries, in the order :func:`box_coefficients` returns them.

    ``("B", i, j)`` = ``Minv[i, j]`` (i <= j; ``Minv`` is symmetric),
    ``("Av", i, j)`` = ``d qdd_i / d qdot_j``, ``("Aq", i, k)`` = ``d qdd_i / d q_k``.
    """
    return ([("B", i, j) for i in range(m) for j in range(i, m)]
            + [("Av", i, j) for i in range(m) for j in range(m)]
            + [("Aq", i, k) for i in range(m) for k in range(m)])


class _TM:
    """Matrix Taylor model of order 2 in ``delta = q - qc`` over a q-box.

    ``X(qc + delta) in c0 + sum_p c1[p] delta_p + sum_{p<=q} c2[p, q] delta_p delta_q + R``
    for every ``delta`` in the box, entrywise; ``c0``, ``c1``, ``c2`` are thin
    ``arb_mat`` (balls around exact values), ``R`` an interval ``arb_mat``.
    Products keep the polynomial part exactly (up to rounding) and push only
    third- and higher-order terms into ``R``: this is what defeats the
    dependency problem of plain interval evaluation (with ``M^-1`` of an
    ill-conditioned ``M`` plain intervals over-estimate derivative ranges 10-100x).
    """

    __slots__ = ("c0", "c1", "c2", "R", "ctx")

    def __init__(self, c0, c1, c2, R, ctx):
        self.c0, self.c1, self.c2, self.R, self.ctx = c0, c1, c2, R, ctx

    def _enc1(self):
        D = self.ctx.delta
        return sum((x * D[p] for p, x in self.c1.items()), arb_mat(self.c0.nrows(), self.c0.ncols()))

    def _enc2(self):
        D2 = self.ctx.delta2
        return sum((x * D2[k] for k, x in self.c2.items()), arb_mat(self.c0.nrows(), self.c0.ncols()))

    def enclosure(self):
        return self.c0 + self._enc1() + self._enc2() + self.R

    def __add__(self, o):
        return _TM(self.c0 + o.c0, {p: x + o.c1[p] for p, x in self.c1.items()},
                   {k: x + o.c2[k] for k, x in self.c2.items()}, self.R + o.R, self.ctx)

    def __sub__(self, o):
        return _TM(self.c0 - o.c0, {p: x - o.c1[p] for p, x in self.c1.items()},
                   {k: x - o.c2[k] for k, x in self.c2.items()}, self.R - o.R, self.ctx)

    def __neg__(self):
        return _TM(-self.c0, {p: -x for p, x in self.c1.items()}, {k: -x for k, x in self.c2.items()},
                   -self.R, self.ctx)

    def __mul__(self, o):
        A, B = self, o
        c1 = {p: A.c0 * B.c1[p] + A.c1[p] * B.c0 for p in A.c1}
        c2 = {}
        for (p, q), x in A.c2.items():
            cross = A.c1[p] * B.c1[p] if p == q else A.c1[p] * B.c1[q] + A.c1[q] * B.c1[p]
            c2[p, q] = A.c0 * B.c2[p, q] + x * B.c0 + cross
        a1, a2, b1, b2 = A._enc1(), A._enc2(), B._enc1(), B._enc2()
        aP = A.c0 + a1 + a2
        R = a1 * b2 + a2 * b1 + a2 * b2 + aP * B.R + A.R * (B.c0 + b1 + b2 + B.R)
        return _TM(A.c0 * B.c0, c1, c2, R, A.ctx)


class _TMContext:
    def __init__(self, dims, delta):
        self.dims, self.delta = dims, delta
        self.pairs = [(p, q) for p in dims for q in dims if p <= q]
        self.delta2 = {(p, q): _sq(delta[p]) if p == q else delta[p] * delta[q] for p, q in self.pairs}


def _sq(x: arb) -> arb:
    """Tight enclosure of ``x^2`` (ball multiplication would allow negatives)."""
    a = x.abs_upper()
    if x > 0 or x < 0:
        b = x.abs_lower()
        return (b * b).union(a * a)
    return arb(0).union(a * a)


def _poly_tm(ctx, get_c, get_b, key_of, shape, shift=()):
    """Taylor model of the matrix of polynomials ``key_of(i, j)`` (derivative ``shift``).

    Coefficients from exact derivatives at the centre (``get_c``); remainder
    ``1/6 sum d3 p(Q) delta^3`` from third derivatives over the box (``get_b``).
    """
    n, k = shape

    def mat(get, o):
        return arb_mat([[get(key_of(i, j), shift + o) for j in range(k)] for i in range(n)])

    dims = ctx.dims
    c1 = {p: mat(get_c, (p,)) for p in dims}
    c2 = {(p, q): mat(get_c, (p, q)) * (arb(0.5) if p == q else arb(1)) for p, q in ctx.pairs}
    R = arb_mat(n, k)
    D = ctx.delta
    for p, q, r in combinations_with_replacement(dims, 3):
        distinct = len({p, q, r})
        weight = arb(1) if distinct == 3 else (arb(1) / 2 if distinct == 2 else arb(1) / 6)
        R += mat(get_b, (p, q, r)) * (weight * D[p] * D[q] * D[r])
    return _TM(mat(get_c, ()), c1, c2, R, ctx)


def _const_tm(ctx, A):
    n, k = A.nrows(), A.ncols()
    return _TM(A, {p: arb_mat(n, k) for p in ctx.dims}, {pq: arb_mat(n, k) for pq in ctx.pairs}, arb_mat(n, k), ctx)


def _inverse_tm(Mt):
    """Taylor model of ``M^-1`` from one of ``M``.

    ``M = M0 + N`` with ``N`` of order >= 1, so ``M^-1 = (I + X)^-1 M0^-1`` with
    ``X = M0^-1 N`` and ``(I + X)^-1 = I - X + X^2 - X^3 (I + X)^-1``, whose last
    term is bounded entrywise by ``b^3 / (1 - b)``, ``b = ||X||_inf < 1``.
    """
    ctx, n = Mt.ctx, Mt.c0.nrows()
    M0inv = interval_inverse(Mt.c0)
    if M0inv is None:
        return None
    Nt = _TM(arb_mat(n, n), Mt.c1, Mt.c2, Mt.R, ctx)
    X = _const_tm(ctx, M0inv) * Nt
    Xe = X.enclosure()
    b = arb(max(arb_upper(sum(abs(Xe[i, j]) for j in range(n))) for i in range(n)))
    if not b < 1:
        return None
    tail = arb_upper(b ** 3 / (1 - b))
    I = arb_mat([[arb(1 if i == j else 0) for j in range(n)] for i in range(n)])
    Y = _const_tm(ctx, I) - X + X * X
    Y.R += arb_mat([[arb(0, tail) for _ in range(n)] for _ in range(n)])
    return Y * _const_tm(ctx, M0inv)


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

    Minv = _inverse_tm(_poly_tm(ctx, get_c, get_b, mkey, (m, m)))
    if Minv is None:
        return None
    G = _poly_tm(ctx, get_c, get_b, gkey, (m, P))
    g = _poly_tm(ctx, get_c, get_b, vkey, (m, 1))
    W, T, cq = [], [], []
    for k in range(m):
        if all(sd.index[("M", i, j, (k,))] is None for i in range(m) for j in range(i, m)):
            Wk = None  # M does not depend on q_k: W_k = 0 exactly
        else:
            Wk = Minv * _poly_tm(ctx, get_c, get_b, mkey, (m, m), (k,)) * Minv
        dG = _poly_tm(ctx, get_c, get_b, gkey, (m, P), (k,))
        dg = _poly_tm(ctx, get_c, get_b, vkey, (m, 1), (k,))
        zero = _const_tm(ctx, arb_mat(m, m))
        W.append(Wk if Wk is not None else zero)
        T.append((Wk * G if Wk is not None else _const_tm(ctx, arb_mat(m, P))) - Minv * dG)
        cq.append((Wk * g if Wk is not None else _const_tm(ctx, arb_mat(m, 1))) - Minv * dg)
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
    ctx = _TMContext(dims, delta)
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
    ctx0 = _TMContext(ctx.dims, {p: arb(0) for p in ctx.dims})
    Minv, W, T, MG, cq = _coefficient_tms(sd, get_c, get_c, ctx0)

    def rows(f):
        return _coef_rows(sd, d, f(Minv), [f(x) for x in W], [f(x) for x in T], f(MG), [f(x) for x in cq])

    return (rows(lambda t: t.c0), {p: rows(lambda t: t.c1[p]) for p in ctx.dims},
            {k: rows(lambda t: t.c2[k]) for k in ctx.pairs})


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
    for i in range(m):
        for j in range(m):
            out.append(({0} if damping[j] != 0 else set()) | ({1 + m + l for l in range(m)} if Gnz else set()))
    for i in range(m):
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
                    js |= {i for i, (ci, si) in enumerate(sd._var) if mono[ci] or (si is not None and mono[si])}
        rows[name, o] = js

    def dep(name, o=()):
        return rows.get((name, o), set())

    base = dep("M") | {p for k in range(m) for p in dep("M", (k,))}  # Minv and its derivative
    out = [dep("M") for i in range(m) for j in range(i, m)]
    out += [dep("M") | dep("G") for i in range(m) for j in range(m)]
    for i in range(m):
        for k in range(m):
            out.append(base | dep("G") | dep("G", (k,)) | dep("g") | dep("g", (k,)))
    return out
