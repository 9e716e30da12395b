"""Exact symbolic rigid-body dynamics of a serial chain: ``M``, ``Gamma``, ``g`` as polynomials.

Used by :mod:`polyrob.bounds.certified.interval_rbd` and :mod:`polyrob.bounds.certified.enclosure`, and,
evaluated on forward-derivative balls by :class:`SymbolicTwin`, by the moving robot's cells
(:mod:`polyrob.analysis.lpv.cells`) for URDF robots of up to three joints.
Pinocchio cannot compute with interval scalars, so the dynamics are rebuilt
here from the model's joint placements, axes and inertias.

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
Taylor models (:mod:`polyrob.bounds.certified.taylor_models`), which keep the
dependency between the factors that plain interval arithmetic loses.

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

from polyrob.errors import CertificationError, NotApplicable

__all__ = ["SymbolicDynamics", "SymbolicTwin", "joint_axes", "MAX_TWIN_JOINTS"]


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
        names, self.var_index = [], []  # _var[i] = (index of c or p, index of s or None)
        for i, k in enumerate(self.kinds):
            if k == "R":
                self.var_index.append((len(names), len(names) + 1))
                names += [f"c{i}", f"s{i}"]
            else:
                self.var_index.append((len(names), None))
                names.append(f"p{i}")
        self.nvars = len(names)
        self.ctx = fmpq_mpoly_ctx.get(tuple(names), "lex")
        self._build(model)

    # ---- polynomial helpers -------------------------------------------------
    def _reduce(self, P):
        """Canonical form: every sin exponent <= 1 (s^2 -> 1 - c^2)."""
        d = P.to_dict()
        sidx = [(ci, si) for ci, si in self.var_index if si is not None]
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
        ci, si = self.var_index[i]
        if si is None:
            return P.derivative(ci)
        c, s = self.ctx.gens()[ci], self.ctx.gens()[si]
        return self._reduce(c * P.derivative(si) - s * P.derivative(ci))

    def _matmul(self, A, B):
        return [
            [self._reduce(sum((A[i][k] * B[k][j] for k in range(3)), self.ctx.from_dict({}))) for j in range(len(B[0]))]
            for i in range(len(A))
        ]

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
                cv, sv = gens[self.var_index[i][0]], gens[self.var_index[i][1]]
                K = [[0, -aq[2], aq[1]], [aq[2], 0, -aq[0]], [-aq[1], aq[0], 0]]
                # Rodrigues as Pinocchio: c I + s K + (1 - c) a a^T
                Rj = [
                    [cv * (1 if r == c else 0) + sv * K[r][c] + (1 - cv) * aq[r] * aq[c] for c in range(3)]
                    for r in range(3)
                ]
                pj = [zero, zero, zero]
            else:
                pv = gens[self.var_index[i][0]]
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
                        Ib = self._matmul(
                            self._matmul(Rkb, Ic[b - 1]), [[Rkb[c][r] for c in range(3)] for r in range(3)]
                        )
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
            for i, (ci, si) in enumerate(self.var_index):
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
        self.Msym, self.V, self.Gam, self.gvec = Msym, V, Gam, gvec

    # ---- evaluation ---------------------------------------------------------
    def evaluate(self, qballs):
        """Values of all registered polynomials for ``q`` in the balls ``qballs``.

        Returns a function ``get(key, order)`` giving an ``arb`` (exact 0 for
        structurally zero polynomials).
        """
        vals = [None] * self.nvars
        for i, (ci, si) in enumerate(self.var_index):
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


#: Largest chain whose polynomials are built (their number of terms grows quickly with the joints).
MAX_TWIN_JOINTS = 3


class SymbolicTwin:
    """``M``, ``C``, ``g`` of a URDF robot on :class:`~polyrob.bounds.certified.analytic.Jet` arrays (shape ``(1, m)``).

    Picklable: the polynomials are rebuilt in each process that evaluates them
    (flint's objects do not pickle).  Why it exists: the moving robot's cells
    enclose the Jacobians with forward derivatives in ball arithmetic
    (:func:`~polyrob.bounds.certified.analytic.analytic_jacobian_enclosure`,
    :func:`~polyrob.bounds.certified.analytic.task_jacobian_enclosure`),
    which call ``M``, ``C``, ``g`` on Jets; Pinocchio cannot compute with them,
    the polynomials of :class:`SymbolicDynamics` can.

    Parameters
    ----------
    robot : polyrob.model.urdf.Robot
        A Pinocchio robot of at most :data:`MAX_TWIN_JOINTS` joints.

    Raises
    ------
    NotApplicable
        More joints, or no Pinocchio model.

    Examples
    --------
    >>> import numpy as np, polyrob
    >>> from polyrob.bounds.certified.analytic import analytic_jacobian_enclosure
    >>> robot = polyrob.load_robot("planar_2r")
    >>> twin = SymbolicTwin(robot)
    >>> q, qd, u = np.array([0.1, 1.2]), np.array([0.3, -0.4]), np.array([1.0, 2.0])
    >>> enc = analytic_jacobian_enclosure(twin, q, q, qd, qd, u)
    >>> A, B = robot.jacobians(q, qd, u)
    >>> bool(np.allclose(enc.A_lo, A, atol=1e-10) and np.allclose(enc.B_hi, B, atol=1e-12))
    True
    """

    def __init__(self, robot):
        if getattr(robot, "model", None) is None or not hasattr(robot.model, "jointPlacements"):
            raise NotApplicable(f"{robot.name}: no Pinocchio model to rebuild as polynomials")
        if robot.m > MAX_TWIN_JOINTS:
            raise NotApplicable(f"{robot.name} has {robot.m} joints: the exact polynomials are built for at most "
                                f"{MAX_TWIN_JOINTS}")  # fmt: skip
        self.robot, self.name, self.m = robot, robot.name, robot.m
        self.damping = np.asarray(robot.damping, float)
        self._sd = None

    def __getstate__(self):
        return {"robot": self.robot, "name": self.name, "m": self.m, "damping": self.damping, "_sd": None}

    @property
    def dynamics(self):
        """The :class:`~polyrob.bounds.certified.symbolic_rbd.SymbolicDynamics` (built on first use)."""
        if self._sd is None:
            self._sd = SymbolicDynamics(self.robot.model)
        return self._sd

    def _variables(self, q):
        """Per polynomial variable its value: ``cos q_i``, ``sin q_i`` (revolute) or ``q_i`` (prismatic)."""
        sd = self.dynamics
        vals = [None] * sd.nvars
        for i, (ci, si) in enumerate(sd.var_index):
            if si is None:
                vals[ci] = q[i]
            else:
                vals[ci], vals[si] = q[i].cos(), q[i].sin()
        return vals

    @staticmethod
    def _evaluate(P, vals, powers):
        """The polynomial ``P`` at ``vals`` (exact rational coefficients as balls; ``powers`` caches ``v**k``)."""
        total = arb(0)
        for exps, coef in P.to_dict().items():
            term = arb(coef)
            for v, e in enumerate(exps):
                if e:
                    term = _power(vals, powers, v, e) * term
            total = term + total
        return total

    def M(self, q):
        q = q[0]
        vals, powers, sd = self._variables(q), {}, self.dynamics
        return [[[self._evaluate(sd.Msym[i][j], vals, powers) for j in range(self.m)] for i in range(self.m)]]

    def C(self, q, qdot):
        """``C(q, qdot)`` with ``C qdot`` the Coriolis and centrifugal torque: ``C_rl = sum_j c_rjl qdot_j``."""
        q, qd = q[0], qdot[0]
        vals, powers, sd = self._variables(q), {}, self.dynamics
        christoffel = {}
        for p, (j, l) in enumerate(sd.pairs):
            for r in range(self.m):
                christoffel[r, j, l] = christoffel[r, l, j] = self._evaluate(sd.Gam[r][p], vals, powers)
        out = []
        for r in range(self.m):
            row = []
            for l in range(self.m):
                s = arb(0)
                for j in range(self.m):
                    s = christoffel[r, j, l] * qd[j] + s
                row.append(s)
            out.append(row)
        return [out]

    def g(self, q):
        q = q[0]
        vals, powers, sd = self._variables(q), {}, self.dynamics
        return [[self._evaluate(sd.gvec[r], vals, powers) for r in range(self.m)]]


def _power(vals, powers, v: int, e: int):
    """``vals[v] ** e`` by repeated products, each power cached in ``powers``."""
    if (v, e) not in powers:
        powers[(v, e)] = vals[v] if e == 1 else _power(vals, powers, v, e - 1) * vals[v]
    return powers[(v, e)]
