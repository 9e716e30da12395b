"""``lpvnorm``: a proved bound on the induced L2 gain of a gridded LPV system with bounded parameter rates.

What MATLAB LPVTools' ``lpvnorm`` computes for a ``pss``: for

.. math:: \\dot x = A(\\rho) x + B(\\rho) d, \\quad e = C(\\rho) x + D(\\rho) d,

with ``rho(t)`` in the box of the grid and ``d rho_i/dt`` in ``[lo_i, hi_i]``,
an upper bound ``gamma`` of ``sup ||e||_2 / ||d||_2`` (zero initial state)
from the bounded-real LMIs of Wu, Yang, Packard & Becker (IJRNC 6, 1996)
with ``X(rho) = sum_j f_j(rho) X_j``, imposed at every grid point and every
vertex ``nu`` of the rate box (:mod:`polyrob.analysis.lpv.check`).  A
constant ``X`` (no basis) covers arbitrarily fast variation.

The LMIs are solved with cvxpy + Clarabel (minimise ``gamma``) on a
conditioned copy: a power-of-two diagonal similarity of the states (exact in
floating point) and the basis orthonormalised over the grid (Gram-Schmidt of
its values, the gradients transformed by the same matrix).  The number
reported, :attr:`LpvNormResult.gamma`, is not the solver's: it is the
smallest level at which the returned ``X_j`` (mapped back to the user's
basis) pass the float64 re-check with a rounding margin
(:func:`~polyrob.analysis.lpv.check.proved_gamma`), ``inf`` when none does.

Examples
--------
>>> import numpy as np
>>> import polyrob
>>> def system(rho):                       # 1/(s + 1 + rho), rho in [0, 1]
...     return np.array([[-1.0 - rho[0]]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1))
>>> r = polyrob.lpvnorm(system, [np.linspace(0.0, 1.0, 3)])
>>> r.proved, round(r.gamma, 4), round(r.frozen_gamma, 4)
(True, 1.0, 1.0)
>>> r.coverage
'on the grid of 3 points'
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from polyrob.analysis.lpv.assemble import backed_off, solve_direct
from polyrob.analysis.lpv.between import affine_terms, curvature_slack
from polyrob.analysis.lpv.check import GridData, proved_gamma
from polyrob.analysis.lpv.data import evaluate
from polyrob.analysis.lpv.result import ARBITRARILY_FAST, LpvNormResult, rate_text
from polyrob.errors import ArgumentError, SolverError

__all__ = ["lpvnorm", "solve_lmis", "frozen_peak", "state_scaling", "orthonormal_basis"]

#: Options of :func:`lpvnorm` and their defaults.
OPTIONS = {
    "balance": True,
    "orthonormalize": True,
    "affine": False,
    "x_bounds": (1e-6, 1e6),
    "eps": 1e-7,
    "solver": "clarabel",
    "x_factor": None,
    "settings": None,
    "rates_at": None,
    "level": None,
    "points": None,
}


def state_scaling(A: np.ndarray) -> np.ndarray:
    """Power-of-two diagonal scaling ``s`` balancing the elementwise peak ``|A|`` over the grid.

    The similarity ``x = diag(s) x~`` maps ``(A, B, C)`` to
    ``(diag(s)^-1 A diag(s), diag(s)^-1 B, C diag(s))``, exactly in floating
    point (powers of two).

    Parameters
    ----------
    A : ndarray
        ``(N, n, n)``.

    Returns
    -------
    ndarray
        ``(n,)``.

    Examples
    --------
    >>> s = state_scaling(np.array([[[-1.0, 1e4], [1e-4, -1.0]]]))
    >>> bool(np.all(np.log2(s) == np.round(np.log2(s)))), float(s[0] / s[1]) > 1.0
    (True, True)
    """
    from scipy.linalg import matrix_balance

    peak = np.abs(A).max(axis=0)
    _, (s, _) = matrix_balance(peak, permute=False, separate=True)
    return np.asarray(s, dtype=float)


def orthonormal_basis(F: np.ndarray) -> np.ndarray:
    """``T`` with ``F T`` orthonormal over the grid (times ``sqrt(N)``): Gram-Schmidt by QR.

    The new basis is ``f~ = T^T f`` (gradients likewise) and ``X_j = sum_l T_jl Z_l``.

    Parameters
    ----------
    F : ndarray
        ``(N, k)``: the basis values at the grid points.

    Returns
    -------
    ndarray
        ``(k, k)``.

    Raises
    ------
    ArgumentError
        The basis functions are linearly dependent on the grid.

    Examples
    --------
    >>> F = np.array([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]])
    >>> Ft = F @ orthonormal_basis(F)
    >>> np.allclose(Ft.T @ Ft, 3 * np.eye(2))
    True
    """
    N, k = F.shape
    R = np.linalg.qr(F, mode="r")
    d = np.abs(np.diag(R))
    if k > N or d.min() <= 1e-10 * d.max():
        raise ArgumentError(f"the {k} basis functions are linearly dependent on the grid of {N} points")
    return np.linalg.solve(R, np.eye(k)) * np.sqrt(N)


def solve_lmis(data: GridData, *, x_bounds=(1e-6, 1e6), eps: float = 1e-7, curvature=None, solver="clarabel",
               x_factor=None, settings=None, level=None):  # fmt: skip
    """Minimise ``gamma`` subject to the bounded-real LMIs at every grid point and rate vertex.

    ``solver="cvxpy"`` builds them with cvxpy (solved by Clarabel); otherwise
    :func:`polyrob.analysis.lpv.assemble.solve_direct` (``x_factor`` and
    ``settings`` are passed to it and ignored by the cvxpy route, which keeps
    ``X_j`` full); ``level``: ``gamma`` fixed there, the LMIs' margin maximised
    (direct route only).

    Parameters
    ----------
    data : GridData
    x_bounds : (float, float)
        ``lo I <= X(rho_a) <= hi I`` at every grid point (LPVTools uses ``1e-6, 1e6``).
    eps : float
        The LMIs are imposed as ``M <= -eps I``.
    curvature : AffineTerms, optional
        Add the multi-convexity constraints ``D_i >= 0``
        (:mod:`polyrob.analysis.lpv.between`).

    Returns
    -------
    Xs : ndarray or None
        ``(k, n, n)``, ``None`` when the solver returned no point.
    gamma : float
        The solver's optimum (``inf`` when none).
    status : str

    Raises
    ------
    SolverError
        cvxpy or Clarabel failed (not: the LMIs are infeasible, which is a status).
    """
    if solver != "cvxpy":
        return solve_direct(data, x_bounds=x_bounds, eps=eps, curvature=curvature, x_factor=x_factor,
                            solver=solver, settings=settings, level=level)  # fmt: skip
    import cvxpy as cp

    A, B, C, D, F, G = data.A, data.B, data.C, data.D, data.F, data.G
    N, n, m = B.shape
    q = C.shape[1]
    k = F.shape[1]
    Z = [cp.Variable((n, n), symmetric=True) for _ in range(k)]
    g = cp.Variable()
    eye_n, eye_s = np.eye(n), np.eye(n + m + q)
    cons = []
    constant = k == 1 and not np.any(G)
    for a in range(N):
        X = sum(float(F[a, j]) * Z[j] for j in range(k))
        if a == 0 or not constant:
            cons += [X >> x_bounds[0] * eye_n, X << x_bounds[1] * eye_n]
        for nu in data.rates()[a]:
            w = G[a] @ nu
            dX = sum(float(w[j]) * Z[j] for j in range(k) if w[j] != 0)
            XA = X @ A[a]
            top = XA + XA.T + (dX if not isinstance(dX, int) else 0)
            XB = X @ B[a]
            M = cp.bmat([[top, XB, C[a].T], [XB.T, -g * np.eye(m), D[a].T], [C[a], D[a], -g * np.eye(q)]])
            cons.append(0.5 * (M + M.T) << -eps * eye_s)
    if curvature is not None:
        for i in range(curvature.A.shape[0]):
            if not np.any(curvature.F[i]):
                continue
            Y = sum(float(curvature.F[i, j]) * Z[j] for j in range(k))
            YA, YB = Y @ curvature.A[i], Y @ curvature.B[i]
            K = cp.bmat([[YA + YA.T, YB], [YB.T, np.zeros((m, m))]])
            cons.append(0.5 * (K + K.T) >> 0)
    problem = cp.Problem(cp.Minimize(g), cons)
    try:
        with warnings.catch_warnings():  # "inaccurate" is a status; the re-check decides
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL)
    except (cp.error.SolverError, ValueError, ArithmeticError) as exc:
        raise SolverError(f"lpvnorm: the LMI solver failed: {exc}") from exc
    status = str(problem.status)
    if g.value is None or any(z.value is None for z in Z):
        return None, float("inf"), status
    Xs = np.array([0.5 * (z.value + z.value.T) for z in Z])
    return Xs, float(g.value), status


def frozen_peak(data: GridData) -> float:
    """Largest LTI H-infinity norm over the grid points of ``data`` (``inf`` when one frozen system is unstable)."""
    from polyrob.analysis.norms import hinf_norm  # the project's one H∞ norm (inf when unstable)

    peak = 0.0
    for A, B, C, D in zip(data.A, data.B, data.C, data.D):
        peak = max(peak, hinf_norm((A, B, C, D)))
        if not np.isfinite(peak):
            break
    return peak


def _options(options: dict) -> dict:
    unknown = set(options) - set(OPTIONS)
    if unknown:
        raise ArgumentError(f"lpvnorm: unknown option(s) {sorted(unknown)}; known: {sorted(OPTIONS)}")
    opts = {**OPTIONS, **options}
    lo, hi = opts["x_bounds"]
    if not (0 < lo < hi):
        raise ArgumentError(f"lpvnorm: x_bounds must satisfy 0 < lo < hi (got {opts['x_bounds']})")
    if opts["level"] is not None and (opts["solver"] == "cvxpy" or not opts["level"] > 0):
        raise ArgumentError(
            f"lpvnorm: level must be positive, with solver 'clarabel', 'scs' or 'structured' (got {opts['level']})"
        )
    return opts


def lpvnorm(system, grid, rate_bounds=None, basis=None, **options) -> LpvNormResult:
    """Proved upper bound of the induced L2 gain of a gridded LPV system (LPVTools' ``lpvnorm``).

    Parameters
    ----------
    system : callable
        ``rho -> (A, B, C, D)`` (numpy arrays), ``rho`` a 1-D float array of
        the ``p`` scheduling parameters.
    grid : sequence of array_like
        ``p`` 1-D arrays: the tensor grid of ``rho`` (its box ``[min, max]``
        per axis is the parameter range).
    rate_bounds : sequence of (lo, hi) or None
        Bounds of ``d rho_i/dt`` (``±inf`` allowed for a parameter the basis
        does not depend on).  ``None``: arbitrarily fast variation.
    basis : sequence of (f, grad) or None
        ``X(rho) = sum_j f_j(rho) X_j`` with ``f(rho) -> float``,
        ``grad(rho) -> (p,)``; include the constant function yourself.
        ``None``: one constant ``X`` (covers arbitrarily fast variation).
    **options
        ``balance`` (True): power-of-two state balancing;
        ``orthonormalize`` (True): orthonormalise the basis over the grid;
        ``affine`` (False): declare ``A, B, C, D`` affine in ``rho`` (checked
        at the grid points) for a guarantee between the grid points (constant
        or affine ``X``, multi-convexity constraints added);
        ``x_bounds`` ((1e-6, 1e6)): bounds of ``X(rho)``'s eigenvalues in the
        conditioned coordinates; ``eps`` (1e-7): strictness margin of the LMIs;
        ``solver`` ("clarabel"): "clarabel" or "scs" on the conic data
        assembled directly (:mod:`polyrob.analysis.lpv.assemble`),
        "structured" (the interior point of :mod:`polyrob.analysis.lpv.sdp`,
        no coefficient matrix formed; neither ``x_factor`` nor ``affine``), or
        "cvxpy" (cvxpy + Clarabel, slower to build); ``settings`` (None):
        the solver's settings; ``x_factor`` (None): an ``r x n`` matrix
        ``L``, the basis functions after the first then carry ``L^T Y_j L``
        (a smaller search, e.g. the states whose equations depend on ``rho``);
        ``rates_at`` (None): ``rho -> p pairs (lo, hi)``, the rate box at
        each grid point, inside ``rate_bounds`` (e.g. ``dq/dt = qdot``
        exactly when both are parameters); ``level`` (None): fix the solver's
        ``gamma`` there and maximise the LMIs' margin (an ``X`` well inside
        the feasible set, for a check between the grid points); ``points``
        (None): ``(N, p)`` more parameter points inside the grid's box whose
        LMIs join the grid's (where a finer re-check found ``X`` failing).

    Returns
    -------
    LpvNormResult
        ``gamma`` is proved (``inf`` and ``proved=False`` when it is not).

    Raises
    ------
    ArgumentError
        Malformed input (NaN in the grid, wrong shapes, ``lo > hi``, a basis
        without rate bounds, unknown option, ``affine`` declared for a system
        that is not affine on the grid).
    SolverError
        cvxpy/Clarabel failed.

    Examples
    --------
    >>> import numpy as np
    >>> def system(rho):
    ...     A = np.array([[0.0, 1.0], [-2.0 - rho[0], -0.5]])
    ...     return A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]), np.zeros((1, 1))
    >>> grid = [np.linspace(0.0, 1.0, 4)]
    >>> fast = lpvnorm(system, grid)
    >>> slow = lpvnorm(system, grid, [(-0.1, 0.1)],
    ...                [(lambda r: 1.0, lambda r: [0.0]), (lambda r: r[0], lambda r: [1.0])])
    >>> slow.proved and slow.frozen_gamma <= slow.gamma <= fast.gamma * (1 + 1e-6)
    True
    """
    t0 = time.perf_counter()
    opts = _options(options)
    ev = evaluate(system, grid, rate_bounds, basis, opts["rates_at"], opts["points"])
    data = ev.data
    N, n = data.A.shape[:2]
    k = data.F.shape[1]
    notes = []
    # conditioning: exact power-of-two state scaling, orthonormal basis
    s = state_scaling(data.A) if opts["balance"] else np.ones(n)
    T = orthonormal_basis(data.F) if opts["orthonormalize"] and not ev.constant_x else np.eye(k)
    cond = GridData(
        data.A / s[None, :, None] * s[None, None, :],
        data.B / s[None, :, None],
        data.C * s[None, None, :],
        data.D,
        data.F @ T,
        np.einsum("akp,kl->alp", data.G, T),
        data.nus,
        data.points,
    )
    aff = None
    if opts["affine"]:
        aff = affine_terms(cond)
        if not aff.system_affine:
            raise ArgumentError("lpvnorm(affine=True): the system is not affine in rho at the grid points")
        if not aff.basis_affine:
            notes.append("the basis is not affine in rho: no guarantee between the grid points")
            aff = None
    L = None if opts["x_factor"] is None else np.atleast_2d(np.asarray(opts["x_factor"], float)) * s[None, :]
    Zs, g_solver, status = solve_lmis(
        cond, x_bounds=opts["x_bounds"], eps=opts["eps"], curvature=aff, x_factor=L,
        solver=opts["solver"], settings=opts["settings"], level=opts["level"],
    )  # fmt: skip
    gamma, chk, Xs_user, slack = float("inf"), None, (), 0.0
    if opts["level"] is not None:
        notes.append(f"X from the LMIs at gamma = {opts['level']:.6g} fixed, margin maximised")
    elif opts["solver"] != "cvxpy" and np.isfinite(g_solver) and g_solver > 0:
        Zs = backed_off(cond, data, T, Zs, g_solver, opts, L, aff, notes)
    if Zs is not None:
        Xs = np.einsum("jl,lab->jab", T, Zs)  # back to the user's basis (balanced coordinates)
        check_data = GridData(cond.A, cond.B, cond.C, cond.D, data.F, data.G, data.nus, data.points)
        if aff is not None:
            slack = curvature_slack(affine_terms(check_data), check_data, Xs)
        gamma, chk = proved_gamma(check_data, Xs, g_solver, slack=slack)
        Xs_user = tuple(x / s[:, None] / s[None, :] for x in Xs)  # x = diag(s) x~: X = S^-1 X~ S^-1
    proved = bool(np.isfinite(gamma))
    if not proved:
        Xs_user = ()
    reason = ""
    if not proved:
        reason = chk.reason if chk is not None else f"the LMI solver found no solution ({status})"
        if "infeasible" in status:
            reason = f"the LMIs are infeasible ({status}): no X proves any gain"
    frozen = frozen_peak(data)
    if rate_bounds is not None and not ev.constant_x:
        rb = [(float(lo), float(hi)) for lo, hi in rate_bounds]
        variation = rate_text(rb)
        if opts["rates_at"] is not None:
            variation += ", and at each grid point the rates rates_at(rho) gives"
        if not all(lo <= 0.0 <= hi for lo, hi in rb):
            notes.append(
                "0 is outside the rate box: frozen_gamma is not a lower bound (constant rho is not admissible)"
            )
    else:
        variation = ARBITRARILY_FAST
        if rate_bounds is not None:
            notes.append("no basis: a constant X, so the bound holds for arbitrarily fast variation")
    box = " x ".join(f"[{lo:.4g}, {hi:.4g}]" for lo, hi in zip(ev.lo, ev.hi))
    whole_box = aff is not None and proved
    if whole_box:
        coverage = (
            f"the whole parameter box {box} (between grid points: multi-convexity, Gahinet-Apkarian-Chilali 1996; "
            "the system declared affine in rho, checked at the grid points)"
        )
    else:
        coverage = f"on the grid of {N} points"
    return LpvNormResult(
        gamma=float(gamma),
        proved=proved,
        gamma_solver=float(g_solver),
        frozen_gamma=float(frozen),
        variation=variation,
        coverage=coverage,
        whole_box=whole_box,
        n_points=N,
        n_rate_vertices=int(data.rates().shape[1]) if not ev.constant_x else 1,
        n_basis=k,
        n_states=n,
        solver_status=status,
        reason=reason,
        lmi_margin=float(chk.lmi_margin) if chk is not None and proved else float("nan"),
        X=Xs_user,
        notes=tuple(notes),
        seconds=time.perf_counter() - t0,
    )
