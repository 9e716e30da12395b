"""The LMIs of :func:`polyrob.lpvnorm` assembled directly as conic data, solved by Clarabel or SCS without cvxpy.

cvxpy's canonicalisation of the bounded-real LMIs on a grid is slow (44 s
for 360 LMIs of size 26 in 1051 variables) and Clarabel's dense cone blocks
make the interior-point step cost grow like (number of LMIs) x (number of
variables)^2.  Here the data ``(c, A, b, cones)`` of

.. math:: \\min c^T x \\quad \\text{s.t.} \\quad b - A x \\in \\mathcal{S}_+^{s_1} \\times \\dots

are written at once from the unit responses ``E A + A^T E`` of the symmetric
basis matrices ``E`` (numpy, per grid point), and the parameter-dependent
part of ``X`` may be restricted: ``X(rho) = Z_0 f_0(rho) + sum_{j >= 1}
f_j(rho) L^T Y_j L`` with ``L`` (``r x n``) given, e.g. the rows of the
states whose equations depend on ``rho`` (option ``x_factor`` of
:func:`polyrob.lpvnorm`).  A restriction shrinks the variables; any
solution of the restricted LMIs is a solution of the full ones, and the
float64 re-check of :mod:`polyrob.analysis.lpv.check` proves the level as
before.

Examples
--------
>>> import numpy as np
>>> from polyrob.analysis.lpv.check import grid_data
>>> data = grid_data([np.array([[-1.0]])], [np.array([[1.0]])], [np.array([[1.0]])], [np.array([[0.0]])])
>>> Xs, g, status = solve_direct(data)
>>> status, round(g, 4)                        # 1/(s + 1): gamma = 1
('solved', 1.0)
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from polyrob.errors import ArgumentError, SolverError

__all__ = ["svec_index", "conic_data", "solve_direct", "backed_off", "gap_progress", "SOLVERS"]

#: The structured solver's stopping tolerance when a ``level`` fixes gamma (:func:`_solve_structured`).
STRUCTURED_LEVEL_TOL = 1e-4

#: Solvers :func:`solve_direct` drives through their own Python interfaces.
SOLVERS = ("clarabel", "scs", "structured")


def svec_index(s: int, solver: str):
    """Row and column indices of a symmetric ``s x s`` matrix in the solver's triangle order, and the scales.

    Clarabel: upper triangle, column by column; SCS: lower triangle, column
    by column; off-diagonal entries times ``sqrt(2)`` for both.

    Examples
    --------
    >>> r, c, w = svec_index(2, "clarabel")
    >>> r.tolist(), c.tolist()
    ([0, 0, 1], [0, 1, 1])
    """
    if solver == "clarabel":
        pairs = [(i, j) for j in range(s) for i in range(j + 1)]
    else:
        pairs = [(i, j) for j in range(s) for i in range(j, s)]
    r, c = (np.array(x, dtype=int) for x in zip(*pairs))
    return r, c, np.where(r == c, 1.0, np.sqrt(2.0))


def _sym_units(r: int) -> np.ndarray:
    """The symmetric basis matrices ``E_e`` (``r(r+1)/2, r, r``): ``e_i e_j^T + e_j e_i^T`` or ``e_i e_i^T``."""
    iu, ju = np.triu_indices(r)
    E = np.zeros((iu.size, r, r))
    E[np.arange(iu.size), iu, ju] = 1.0
    E[np.arange(iu.size), ju, iu] = 1.0
    return E


def conic_data(data, *, x_bounds=(1e-6, 1e6), eps=1e-7, curvature=None, x_factor=None, solver="clarabel", level=None):
    """``(c, A, b, sizes, unpack)`` of the bounded-real LMIs at every grid point and rate vertex.

    The first variable is ``gamma`` (minimised); with ``level`` given, ``gamma``
    is fixed there and the first variable is a margin ``t`` (maximised:
    ``M + t I <= -eps I``), which gives a point well inside the feasible set
    where minimising ``gamma`` stalls on its boundary.

    Parameters
    ----------
    data : GridData
    x_bounds : (float, float)
        ``lo I <= X(rho_a) <= hi I``.
    eps : float
        LMIs imposed as ``M <= -eps I``.
    curvature : AffineTerms, optional
        Multi-convexity constraints ``D_i >= 0`` (:mod:`polyrob.analysis.lpv.between`).
    x_factor : ndarray, optional
        ``L`` (``r x n``): the matrices of the basis functions after the first are ``L^T Y_j L``.
    solver : str
        The triangle order (:func:`svec_index`).
    level : float, optional
        Fix ``gamma`` and maximise the margin ``t`` instead.

    Returns
    -------
    c : ndarray
    A : scipy.sparse.csc_matrix
    b : ndarray
    sizes : list of int
        The PSD cones' sides, in order.
    unpack : callable
        ``x -> (Zs (k, n, n), gamma)``.
    """
    A_, B_, C_, D_, F, G = data.A, data.B, data.C, data.D, data.F, data.G
    N, n, m = B_.shape
    q = C_.shape[1]
    k = F.shape[1]
    s = n + m + q
    constant = k == 1 and not np.any(G)
    E_full = _sym_units(n)
    if x_factor is None or k == 1:
        L = np.eye(n)
    else:
        L = np.atleast_2d(np.asarray(x_factor, float))
        if L.shape[1] != n:
            raise ArgumentError(f"x_factor must have {n} columns (got shape {L.shape})")
    E_dep = np.einsum("ri,erc,cj->eij", L, _sym_units(L.shape[0]), L)  # L^T E L
    units = [E_full] + [E_dep] * (k - 1)
    offsets = np.cumsum([1] + [u.shape[0] for u in units])
    nv = int(offsets[-1])
    unpack_units = units

    def unpack(x):
        x = np.asarray(x, float)
        Zs = np.array([np.einsum("e,eij->ij", x[offsets[j] : offsets[j + 1]], units[j]) for j in range(k)])
        return Zs, float(x[0])

    rows_s, cols_s, w_s = svec_index(s, solver)
    rows_n, cols_n, w_n = svec_index(n, solver)
    blocks, rhs, sizes = [], [], []

    def add(block, b, side):
        blocks.append(sp.csr_matrix(block))
        rhs.append(b)
        sizes.append(side)

    def embed(TL, TR):
        """``(e, s, s)`` with ``[[TL, TR], [TR^T, 0]]`` in the top-left ``n + m`` corner, as svec rows."""
        U = np.zeros((TL.shape[0], s, s))
        U[:, :n, :n] = TL
        U[:, :n, n : n + m] = TR
        U[:, n : n + m, :n] = np.transpose(TR, (0, 2, 1))
        return (U[:, rows_s, cols_s] * w_s).T  # (ns, e)

    eye_s = (rows_s == cols_s).astype(float)
    gamma_col = np.zeros((rows_s.size, 1))
    gamma_col[(rows_s == cols_s) & (rows_s >= n), 0] = -1.0
    if level is not None:  # the first variable is the margin t: M(gamma = level) + t I
        gamma_const = -float(level) * gamma_col[:, 0]
        gamma_col = eye_s[:, None].copy()
    M0 = np.zeros((s, s))
    eye_n = (rows_n == cols_n).astype(float)
    for a in range(N):
        resp, rate = [], []
        for E in units[: min(k, 2)]:  # the first matrix, and the one shape every later basis function shares
            EA = E @ A_[a]
            resp.append(embed(EA + np.transpose(EA, (0, 2, 1)), E @ B_[a]))
            rate.append(embed(E, np.zeros((E.shape[0], n, m))))
        resp += [resp[-1]] * (k - len(resp))
        rate += [rate[-1]] * (k - len(rate))
        M0[:] = 0.0
        M0[n + m :, :n], M0[n + m :, n : n + m] = C_[a], D_[a]
        M0[:n, n + m :], M0[n : n + m, n + m :] = C_[a].T, D_[a].T
        b0 = -(M0[rows_s, cols_s] * w_s) - eps * eye_s
        if level is not None:
            b0 = b0 + gamma_const  # -(M0 - level I) - eps I
        for nu in data.rates()[a]:
            w = G[a] @ nu
            cols = [gamma_col] + [F[a, j] * resp[j] + (w[j] * rate[j] if w[j] != 0 else 0.0) for j in range(k)]
            add(np.hstack(cols), b0, s)
        if a == 0 or not constant:
            xcols = [np.zeros((rows_n.size, 1))]
            xcols += [F[a, j] * (unpack_units[j][:, rows_n, cols_n] * w_n).T for j in range(k)]
            X = np.hstack(xcols)
            add(-X, -x_bounds[0] * eye_n, n)  # X - lo I >= 0
            add(X, x_bounds[1] * eye_n, n)  # hi I - X >= 0
    if curvature is not None:
        rows_c, cols_c, w_c = svec_index(n + m, solver)
        for i in range(curvature.A.shape[0]):
            if not np.any(curvature.F[i]):
                continue
            cols = [np.zeros((rows_c.size, 1))]
            for j in range(k):
                EA = units[j] @ curvature.A[i]
                K = np.zeros((units[j].shape[0], n + m, n + m))
                K[:, :n, :n] = EA + np.transpose(EA, (0, 2, 1))
                K[:, :n, n:] = units[j] @ curvature.B[i]
                K[:, n:, :n] = np.transpose(K[:, :n, n:], (0, 2, 1))
                cols.append(curvature.F[i, j] * (K[:, rows_c, cols_c] * w_c).T)
            add(-np.hstack(cols), np.zeros(rows_c.size), n + m)  # D_i >= 0
    c = np.zeros(nv)
    c[0] = 1.0 if level is None else -1.0
    return c, sp.vstack(blocks, format="csc"), np.concatenate(rhs), sizes, unpack


def solve_direct(data, *, x_bounds=(1e-6, 1e6), eps=1e-7, curvature=None, x_factor=None, solver="clarabel",
                 settings=None, level=None):  # fmt: skip
    """Minimise ``gamma`` subject to the LMIs of :func:`conic_data` with Clarabel or SCS.

    Parameters
    ----------
    data : GridData
    x_bounds, eps, curvature, x_factor
        As in :func:`conic_data`.
    solver : {"clarabel", "scs", "structured"}
        ``"structured"``: the interior-point method of :mod:`polyrob.analysis.lpv.sdp`, which
        forms the Schur complement from the grid's matrices (no ``x_factor``, no ``curvature``).
    settings : dict, optional
        Solver settings (Clarabel's ``DefaultSettings`` attributes, SCS keywords, or
        :func:`polyrob.analysis.lpv.sdp.interior.solve`'s keywords).
    level : float, optional
        Fix ``gamma`` there and maximise the LMIs' margin (:func:`conic_data`).

    Returns
    -------
    Xs : ndarray or None
        ``(k, n, n)``, ``None`` when the solver returned no point.
    gamma : float
        The solver's optimum (``inf`` when none; ``level`` when given): not a certificate.
    status : str

    Raises
    ------
    SolverError
        The solver failed to run (not: the LMIs are infeasible, which is a status).
    """
    if solver not in SOLVERS:
        raise ArgumentError(f"lpvnorm: unknown solver {solver!r}; known: {', '.join(SOLVERS)}")
    if solver == "structured":
        return _solve_structured(data, x_bounds=x_bounds, eps=eps, curvature=curvature, x_factor=x_factor,
                                 settings=settings, level=level)  # fmt: skip
    c, A, b, sizes, unpack = conic_data(
        data, x_bounds=x_bounds, eps=eps, curvature=curvature, x_factor=x_factor, solver=solver, level=level
    )
    settings = dict(settings or {})
    try:
        if solver == "clarabel":
            import clarabel

            opts = clarabel.DefaultSettings()
            opts.verbose = False
            for key, value in settings.items():
                setattr(opts, key, value)
            cones = [clarabel.PSDTriangleConeT(int(t)) for t in sizes]
            P = sp.csc_matrix((c.size, c.size))
            sol = clarabel.DefaultSolver(P, c, A, b, cones, opts).solve()
            status, x = str(sol.status), np.asarray(sol.x, float)
            # an interior-point iterate is strictly inside the cones: the last one may prove a level even
            # when the solver stalls near the optimum (NumericalError, InsufficientProgress); the re-check decides
            ok = "Infeasible" not in status
            status = {"Solved": "solved", "AlmostSolved": "solved_inaccurate"}.get(status, status)
        else:
            import scs

            opts = {"verbose": False, "eps_abs": 1e-7, "eps_rel": 1e-7, "max_iters": 20000, **settings}
            sol = scs.SCS({"A": A, "b": b, "c": c}, {"s": [int(t) for t in sizes]}, **opts).solve()
            status, x = str(sol["info"]["status"]), np.asarray(sol["x"], float)
            ok = "infeasible" not in status and "unbounded" not in status
    except (ValueError, ArithmeticError, RuntimeError, TypeError) as exc:
        raise SolverError(f"lpvnorm: the LMI solver failed: {exc}") from exc
    if not ok or not np.all(np.isfinite(x)):
        return None, float("inf"), status.lower()
    Zs, gamma = unpack(x)
    if level is not None:
        gamma = float(level)
    return 0.5 * (Zs + np.transpose(Zs, (0, 2, 1))), gamma, status.lower()


def gap_progress(tol: float):
    """``progress(iteration, objective, gap)`` for the interior point: the whole job's line moves with the gap.

    Each iteration reports how far the relative gap has come from its first
    value towards ``tol`` on a log scale (:func:`polyrob.progress.report`):
    an interior point's gap falls by a roughly constant factor per
    iteration, so this is the fraction of the iterations done.

    Examples
    --------
    >>> import io
    >>> from polyrob.progress import JobProgress
    >>> job = JobProgress(["moving-robot"], stream=io.StringIO(), clock=lambda: 0.0)
    >>> job.start() is job and job._stop.set() is None
    True
    >>> job.begin(1, "moving-robot")
    >>> on_iteration = gap_progress(1e-8)
    >>> on_iteration(1, 0.0, 1.0); on_iteration(2, 0.0, 1e-4)
    >>> round(job.share, 3)
    0.5
    >>> job.stop()
    """
    from polyrob.progress import report

    first = []

    def on_iteration(iteration, objective, gap):
        if not (np.isfinite(gap) and gap > 0):
            return
        if not first:
            first.append(max(float(gap), 10.0 * tol))
        report(np.log(first[0] / max(float(gap), tol)), np.log(first[0] / tol))

    return on_iteration


def _solve_structured(data, *, x_bounds, eps, curvature, x_factor, settings, level):
    """:func:`solve_direct` by :mod:`polyrob.analysis.lpv.sdp` (full ``X_j``, no curvature constraints)."""
    from polyrob.analysis.lpv.sdp.family import BoundedRealFamily
    from polyrob.analysis.lpv.sdp.interior import solve

    if x_factor is not None or curvature is not None:
        raise ArgumentError("lpvnorm: solver 'structured' takes neither x_factor nor affine=True; use 'clarabel'")
    family = BoundedRealFamily(data, x_bounds=x_bounds, eps=eps, level=level)
    # with a level the point sought is one well inside every LMI, not the last digits of the margin: stopped at
    # 1e-4 the iterate stays central; driven further, X goes to the edge of the feasible set and holds less well
    # between the grid points (measured on the x4 moving robot, docs/lpvnorm.md)
    tol = STRUCTURED_LEVEL_TOL if level is not None else 1e-8
    try:
        res = solve(family, **{"tol": tol, "progress": gap_progress(tol), **dict(settings or {})})
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise SolverError(f"lpvnorm: the structured LMI solver failed: {exc}") from exc
    if res.status == "infeasible" or not np.all(np.isfinite(res.y)):
        return None, float("inf"), res.status
    gamma = float(level) if level is not None else float(res.y[0])
    return family.matrices(res.y), gamma, res.status


def backed_off(cond, data, T, Zs, g_solver, opts, L, aff, notes):
    """The solver's ``X`` if the re-check proves a level with it, else one from a fixed level above ``g_solver``.

    Minimising ``gamma`` ends on the boundary of the feasible set, where a
    stalled interior-point solver may return a point the float64 re-check
    rejects; with ``gamma`` fixed at ``1.1`` (then ``1.5``) times its
    optimum and the LMIs' margin maximised the point lies well inside.

    Parameters
    ----------
    cond : GridData
        The conditioned data the LMIs are written on (orthonormal basis ``F T``).
    data : GridData
        The same in the user's basis (for the re-check).
    T : ndarray
        The basis transform (``X_j = sum_l T_jl Z_l``).
    Zs : ndarray or None
        The solver's matrices in the conditioned basis.
    g_solver : float
    opts : dict
        :func:`polyrob.lpvnorm`'s options.
    L : ndarray or None
        The ``x_factor`` in the conditioned coordinates.
    aff : AffineTerms or None
    notes : list of str
        Appended to when the back-off gave the matrices.

    Returns
    -------
    ndarray or None
    """
    from polyrob.analysis.lpv.check import GridData, proved_gamma

    check_data = GridData(cond.A, cond.B, cond.C, cond.D, data.F, data.G, data.nus, data.points)
    if Zs is not None and np.isfinite(proved_gamma(check_data, np.einsum("jl,lab->jab", T, Zs), g_solver)[0]):
        return Zs
    for factor in (1.1, 1.5):
        Z2, _, st = solve_direct(
            cond, x_bounds=opts["x_bounds"], eps=opts["eps"], curvature=aff, x_factor=L,
            solver=opts["solver"], settings=opts["settings"], level=factor * g_solver,
        )  # fmt: skip
        if Z2 is not None and np.isfinite(proved_gamma(check_data, np.einsum("jl,lab->jab", T, Z2), g_solver)[0]):
            notes.append(f"X from the LMIs at gamma = {factor} x the solver's optimum, margin maximised ({st})")
            return Z2
    return Zs
