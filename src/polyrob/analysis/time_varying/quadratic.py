"""Certificates for time-varying Jacobians: quadratic stability and performance.

μ with constant real parameters (:mod:`polyrob.analysis.mu.bounds`) certifies every
*frozen* plant of the uncertainty set.  A moving robot's Jacobians change with
its state; the classic sufficient tests for a polytopic linear differential
inclusion (PLDI, Boyd, El Ghaoui, Feron & Balakrishnan, *LMIs in System and
Control Theory*, 1994, ch. 5-6),

.. math:: \\dot x = A(t) x + B(t) u, \\quad (A(t), B(t)) \\in \\mathrm{Co}\\{(A_i, B_i)\\}

with arbitrarily fast variation, are

* :func:`quadstab`: one ``P > 0`` with ``A_cl,i^T P + P A_cl,i < 0`` at every
  vertex of the closed loop (quadratic stability);
* :func:`quadperf`: one ``P > 0`` satisfying the bounded-real LMI with level
  ``γ`` at every vertex (quadratic H∞ performance: the L2 gain from the
  reference to the weighted errors of the mixed-sensitivity problem is below
  ``γ`` for every admissible variation; the performance is met when ``γ < 1``).

For a fixed controller the closed loop is affine in ``(A, B)`` and both LMIs
are affine in the closed-loop matrices for fixed ``P``, so the vertices suffice
(:mod:`polyrob.analysis.time_varying.vertices`).  The LMIs are solved with cvxpy +
Clarabel on a balanced, time-scaled copy of the problem (a diagonal
power-of-two similarity and a power-of-two time scale, both exact in floating
point), with margins for strictness; the verdict then rests only on an
a-posteriori check of the returned ``P``: the eigenvalues of every vertex
matrix, computed in floating point, must be negative by more than a bound of
the rounding errors.  The solver's status is recorded, never trusted.

For LFT models too large for vertex enumeration see
:func:`polyrob.analysis.time_varying.smallgain.scaled_small_gain`.
"""

from __future__ import annotations

import time

import numpy as np

from polyrob.analysis.time_varying.results import QuadPerfResult, QuadStabResult, covers_text
from polyrob.analysis.time_varying.vertices import (
    MAX_VERTICES,
    closed_loop_vertices,
    performance_vertices,
    vertex_set,
)
from polyrob.errors import NotApplicable

__all__ = ["QuadStabResult", "QuadPerfResult", "quadstab", "quadperf"]

_U = np.finfo(float).eps
#: Largest condition number of ``P`` the LMIs search over (balanced, time-scaled coordinates).
COND_MAX = 1e6
#: Largest L2-gain level quadperf searches over.
GAMMA_MAX = 1e4
#: Largest closed loop (states) the vertex LMIs are built for: cvxpy's
#: canonicalisation of k vertex LMIs grows like k n^3 (measured: 24 GiB and
#: an out-of-memory kill for a 92-state loop at its first 48 vertices).
MAX_STATES = 40


def _check_size(n: int, what: str) -> None:
    if n > MAX_STATES:
        raise NotApplicable(
            f"{what}: the closed loop has {n} states; the vertex LMIs are built for at most {MAX_STATES} "
            "(memory grows like n^3 per vertex): reduce the controller (--reduce) or use a fixed structure"
        )


# --------------------------------------------------------------------------- numerics


def _pow2(x: float) -> float:
    return float(2.0 ** np.round(np.log2(x))) if x > 0 and np.isfinite(x) else 1.0


def _scaling(As: np.ndarray) -> tuple[np.ndarray, float]:
    """Diagonal power-of-two similarity ``s`` (``T = diag(s)``) and time scale ``c``."""
    from scipy.linalg import matrix_balance

    _, (s, _) = matrix_balance(np.abs(As).max(axis=0), permute=False, separate=True)
    Ab = As / s[None, :, None] * s[None, None, :]
    c = _pow2(max(np.linalg.norm(a, 2) for a in Ab))
    return s, c


def _rounding(n: int, *prods: float) -> float:
    """Bound on the rounding error of a computed ``n x n`` sum of products and of its eigenvalues."""
    return 8.0 * (n + 2) * _U * sum(prods)


def _solve(problem, what: str) -> str:
    import warnings

    import cvxpy as cp

    try:
        with warnings.catch_warnings():  # "may be inaccurate": the status says so, the verification decides
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:  # a numerical failure is a "not certified", not a crash
        return f"solver error: {exc}"
    return str(problem.status)


def _active_set(n_v: int, solve_subset, violation, first: np.ndarray, *, probe=None, add: int = 24, rounds: int = 15):
    """Cutting planes over the vertices: solve on a subset, add the most violated vertices, repeat.

    Most vertex inequalities are inactive at the optimum; solving on the
    active ones and checking all of them afterwards gives the same answer at
    a fraction of the cost.  Infeasible on a subset means infeasible on all:
    a smaller ``probe`` subset, when given, is solved first and ends the
    search when it has no solution (a 48-vertex LMI cost 30 s where 8
    vertices took 2 s to refute); otherwise its solution is dropped and the
    search starts from ``first`` as without it.
    Returns ``(solution or None, status, vertices used)``.
    """
    active = np.unique(np.asarray(first, int))
    if probe is not None:
        probe = np.unique(np.asarray(probe, int))
        if probe.size < active.size:
            sol, status = solve_subset(probe)
            if sol is None:
                return None, status, probe.size
            active = np.union1d(active, probe)
    sol, status = None, "not run"
    for _ in range(rounds):
        sol, status = solve_subset(active)
        if sol is None:
            return None, status, active.size
        viol = violation(sol)
        bad = np.setdiff1d(np.flatnonzero(viol > 0), active)
        if bad.size == 0:
            return sol, status, active.size
        active = np.union1d(active, bad[np.argsort(-viol[bad])[:add]])
    return sol, f"{status}; {rounds} cutting-plane rounds left violated vertices", active.size


def _spread_subset(abscissa: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` frozen vertices closest to instability, and ``k`` spread over the others."""
    n_v = len(abscissa)
    return np.union1d(np.argsort(-abscissa)[:k], np.linspace(0, n_v - 1, min(k, n_v)).astype(int))


def _first_vertices(As: np.ndarray, k: int = 24) -> np.ndarray:
    """Start with the frozen vertices closest to instability, and a spread of the others."""
    ab = np.array([np.linalg.eigvals(a).real.max() for a in As])
    return _spread_subset(ab, k), ab


# --------------------------------------------------------------------------- quadstab


def _lyapunov_congruence(Ab: np.ndarray):
    """``(T, T^-1)`` with ``T^T P0 T = I``, ``P0`` the Lyapunov matrix of the vertices' mean (``None``: not Hurwitz).

    A loop whose time constants span many decades (the main job's: 0.03 to
    5000 rad/s) needs a ``P`` whose condition exceeds :data:`COND_MAX` in
    the diagonally balanced coordinates, and the interior-point solver then
    stalls at a level of the order of the slowest decay rate.  In the
    coordinates where the centre's own Lyapunov matrix is the identity the
    search starts from a well-scaled point; the candidate is mapped back and
    verified in the balanced coordinates like any other (a similarity is no
    part of the proof).
    """
    from scipy.linalg import solve_continuous_lyapunov

    A0 = Ab.mean(axis=0)
    if np.linalg.eigvals(A0).real.max() >= 0:
        return None
    P0 = solve_continuous_lyapunov(A0.T, -np.eye(A0.shape[0]))
    w, V = np.linalg.eigh(0.5 * (P0 + P0.T))
    if not np.all(np.isfinite(w)) or w[0] <= 0:
        return None
    return V @ np.diag(w**-0.5) @ V.T, V @ np.diag(w**0.5) @ V.T



def _verify_stab(As: np.ndarray, P: np.ndarray) -> float:
    """Verified ``min_i λ_min(-(A_i^T P + P A_i)) / λ_max(P)`` (``<= 0``: not verified)."""
    n = P.shape[0]
    lamP = np.linalg.eigvalsh(P)
    nP = np.linalg.norm(P, 2)
    if lamP[0] - _rounding(n, nP) <= 0:
        return -np.inf
    M = np.transpose(As, (0, 2, 1)) @ P + P @ As
    lam = np.linalg.eigvalsh(M)[:, -1]
    err = np.array(
        [
            _rounding(n, 2 * np.linalg.norm(np.abs(a), 2) * np.linalg.norm(np.abs(P), 2), np.linalg.norm(m, 2))
            for a, m in zip(As, M)
        ]
    )
    return float(np.min(-(lam + err)) / lamP[-1])


def quadstab(vertices, K, *, which: str = "auto", max_vertices: int = MAX_VERTICES) -> QuadStabResult:
    """Quadratic stability of ``u = K (r - y)`` around every plant of a PLDI.

    Parameters
    ----------
    vertices : PLDI, VertexSet or sequence of (A_i, B_i)
        See :func:`~polyrob.analysis.time_varying.vertices.vertex_set`.
    K : LTI system, ``m x m`` gain or ``(A_K, B_K, C_K, D_K)``
    which, max_vertices
        Vertex set of a PLDI (``"auto"``, ``"polytope"``, ``"box"``).

    Returns
    -------
    QuadStabResult

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.analysis.time_varying.quadratic import quadstab
    >>> B = np.array([[0.0], [1.0]])
    >>> verts = [(np.array([[0.0, 1.0], [a, -1.0]]), B) for a in (-1.0, 1.0)]
    >>> r = quadstab(verts, np.array([[4.0]]))    # u = -4 q: stiffness 3..5, damping 1
    >>> r.holds, r.n_vertices, r.margin > 0
    (True, 2, True)
    """
    import cvxpy as cp

    t0 = time.perf_counter()
    vs = vertex_set(vertices, which=which, max_vertices=max_vertices)
    As = closed_loop_vertices(vs, K)
    n = As.shape[1]
    _check_size(n, "quadstab")
    s, c = _scaling(As)
    Ab = As / s[None, :, None] * s[None, None, :] / c  # exact: powers of two
    first, abscissa = _first_vertices(Ab)
    eye = np.eye(n)
    if abscissa.max() >= 0:  # a frozen vertex is unstable: no common Lyapunov function exists
        Pv, status, used = None, f"vertex {int(np.argmax(abscissa))} unstable (frozen)", 0
    else:

        def solve_subset(idx):
            # always feasible (bounded P, free level s): interior-point methods are slow to prove
            # infeasibility; s < 0 is a candidate certificate, s >= 0 means none with cond(P) <= COND_MAX
            P, t = cp.Variable((n, n), symmetric=True), cp.Variable()
            cons = [P >> eye, P << COND_MAX * eye] + [Ab[i].T @ P + P @ Ab[i] << t * eye for i in idx]
            st = _solve(cp.Problem(cp.Minimize(t), cons), "quadstab")
            if P.value is None or t.value is None:
                return None, st
            if t.value >= 0:
                return None, f"no common P with cond(P) <= {COND_MAX:g} (best level {t.value:.3g} >= 0)"
            return 0.5 * (P.value + P.value.T), st

        def violation(P):  # flag vertices not clearly negative (the rounding allowance is far below this)
            return np.linalg.eigvalsh(np.transpose(Ab, (0, 2, 1)) @ P + P @ Ab)[:, -1] + 1e-9 * np.linalg.norm(P, 2)

        probe = _spread_subset(abscissa, 4)  # when these 8 have no common P, neither have all
        Pv, status, used = _active_set(len(Ab), solve_subset, violation, first, probe=probe)
        congruence = _lyapunov_congruence(Ab) if Pv is None else None
        if congruence is not None:  # a stiff loop: the same LMIs in the coordinates of the centre's Lyapunov matrix
            T, Ti = congruence
            At = Ti @ Ab @ T
            level = T.T @ T  # the identity of the balanced coordinates, seen from the new ones

            def solve_congruent(idx):
                Pt, t = cp.Variable((n, n), symmetric=True), cp.Variable()
                cons = [Pt >> 1e-3 * eye, Pt << 1e3 * eye] + [At[i].T @ Pt + Pt @ At[i] << t * level for i in idx]
                st = _solve(cp.Problem(cp.Minimize(t), cons), "quadstab")
                if Pt.value is None or t.value is None or t.value >= 0:
                    return None, st if t.value is None else f"{st}; level {t.value:.3g} >= 0"
                P = Ti.T @ (0.5 * (Pt.value + Pt.value.T)) @ Ti
                return 0.5 * (P + P.T), st

            P2, st2, used2 = _active_set(len(Ab), solve_congruent, violation, first, probe=probe)
            if P2 is not None:
                Pv, used = P2, used2
                status = f"{st2} (in the coordinates of the centre's Lyapunov matrix; {status} in the balanced ones)"
    rate = _verify_stab(Ab, Pv) * c if Pv is not None else np.nan
    holds = bool(np.isfinite(rate) and rate > 0)
    P_orig = None if Pv is None else Pv / s[:, None] / s[None, :]  # V = x'^T P x', x' = T^-1 x
    lam = np.linalg.eigvalsh(Pv) if Pv is not None else np.array([np.nan])
    return QuadStabResult(
        holds=holds,
        margin=float(rate),
        n_vertices=vs.n_vertices,
        vertex_source=vs.source,
        enclosure=vs.enclosure,
        P=P_orig,
        cond_P=float(lam[-1] / lam[0]) if lam[0] > 0 else np.inf,
        solver_status=status,
        seconds=time.perf_counter() - t0,
        covers=covers_text(vs, "exponential stability (common Lyapunov function V = x^T P x)"),
        info={
            "time_scale": c,
            "vertex_note": vs.note,
            "closed_loop_order": n,
            "lmi_vertices": used,
            "frozen_abscissa": float(abscissa.max() * c),
        },
    )


# --------------------------------------------------------------------------- quadperf


def _brl(As, Bs, Cs, Ds, P, gamma):
    """The bounded-real matrices of every vertex at level ``gamma`` (v, n+p+q, n+p+q)."""
    v, n, p = Bs.shape
    q = Cs.shape[1]
    L = np.zeros((v, n + p + q, n + p + q))
    L[:, :n, :n] = np.transpose(As, (0, 2, 1)) @ P + P @ As
    PB = P @ Bs
    L[:, :n, n : n + p], L[:, n : n + p, :n] = PB, np.transpose(PB, (0, 2, 1))
    L[:, n + p :, :n], L[:, :n, n + p :] = Cs, np.transpose(Cs, (0, 2, 1))
    L[:, n + p :, n : n + p], L[:, n : n + p, n + p :] = Ds, np.transpose(Ds, (0, 2, 1))
    d = np.arange(n, n + p + q)
    L[:, d, d] -= gamma
    return L


def _brl_ok(As, Bs, Cs, Ds, P, gamma) -> bool:
    L = _brl(As, Bs, Cs, Ds, P, gamma)
    N = L.shape[1]
    nA = max(np.linalg.norm(np.abs(a), 2) + np.linalg.norm(np.abs(b), 2) for a, b in zip(As, Bs))
    err = _rounding(N, 2 * nA * np.linalg.norm(np.abs(P), 2), max(np.linalg.norm(x, 2) for x in L))
    return bool(np.all(np.linalg.eigvalsh(L)[:, -1] + err < 0))


def _verified_gamma(As, Bs, Cs, Ds, P, g0: float) -> float:
    """Smallest level (within 1e-6 relative) at which every vertex BRL is verified with ``P``."""
    n = P.shape[0]
    lamP = np.linalg.eigvalsh(P)
    if lamP[0] - _rounding(n, np.linalg.norm(P, 2)) <= 0:
        return np.inf
    hi = max(g0, 1e-12) * (1 + 1e-9)
    k = 0
    while not _brl_ok(As, Bs, Cs, Ds, P, hi):
        hi *= 2.0 if k > 3 else 1.0 + 10.0 ** (k - 6)
        k += 1
        if k > 40:
            return np.inf
    lo = hi / (2.0 if k > 4 else 1.0 + 10.0 ** (k - 7)) if k else max(g0, 1e-12) * (1 - 1e-6)
    while hi - lo > 1e-7 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _brl_ok(As, Bs, Cs, Ds, P, mid) else (mid, hi)
    return float(hi)


def quadperf(
    vertices,
    K,
    W_S=None,
    W_T=None,
    W_KS=None,
    *,
    which: str = "auto",
    max_vertices: int = MAX_VERTICES,
    vertex_norms: bool = True,
) -> QuadPerfResult:
    """Quadratic H∞ performance of the mixed-sensitivity loop over a PLDI (common-``P`` bounded-real lemma).

    Parameters
    ----------
    vertices : PLDI, VertexSet or sequence of (A_i, B_i)
    K : LTI system, ``m x m`` gain or ``(A_K, B_K, C_K, D_K)``
    W_S, W_T, W_KS : weights as in :func:`polyrob.plant.generalized.generalized_plant`
    which, max_vertices
        Vertex set of a PLDI.
    vertex_norms : bool
        Also compute every vertex's own H∞ norm (:attr:`QuadPerfResult.worst_vertex_hinf`).

    Returns
    -------
    QuadPerfResult

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.analysis.time_varying.quadratic import quadperf
    >>> A, B = np.array([[0.0, 1.0], [0.0, -1.0]]), np.array([[0.0], [1.0]])
    >>> r = quadperf([(A, B)], np.array([[1.0]]), W_S=0.5)   # |S| of 1/(s(s+1)) peaks at 1.468
    >>> r.holds, round(r.gamma, 3), round(r.worst_vertex_hinf, 3)
    (True, 0.734, 0.734)
    """
    import cvxpy as cp

    t0 = time.perf_counter()
    vs = vertex_set(vertices, which=which, max_vertices=max_vertices)
    As, Bs, Cs, Ds = performance_vertices(vs, K, W_S, W_T, W_KS)
    v, n, p = Bs.shape
    _check_size(n, "quadperf")
    q = Cs.shape[1]
    s, c = _scaling(As)
    # similarity T = diag(s) and time scale c: (A, B, C) -> (T^-1 A T / c, T^-1 B / c, C T): same H∞ norm
    Ab = As / s[None, :, None] * s[None, None, :] / c
    Bb = Bs / s[None, :, None] / c
    Cb = Cs * s[None, None, :]
    eps = 1e-8
    first, abscissa = _first_vertices(Ab)

    def solve_subset(idx):
        # a free level t on the LMI (t >= -eps): always feasible (interior-point methods are slow
        # to prove infeasibility); the level g is kept only when the solver reaches t < 0
        P, g, t = cp.Variable((n, n), symmetric=True), cp.Variable(), cp.Variable()
        cons = [P >> eps * np.eye(n), g <= GAMMA_MAX, t >= -eps]  # bounded by t >= -eps and g >= 0
        for i in idx:
            a, b, cc, d = Ab[i], Bb[i], Cb[i], Ds[i]
            cons.append(
                cp.bmat([[a.T @ P + P @ a, P @ b, cc.T], [b.T @ P, -g * np.eye(p), d.T], [cc, d, -g * np.eye(q)]])
                << t * np.eye(n + p + q)
            )
        st = _solve(cp.Problem(cp.Minimize(g + GAMMA_MAX * t), cons), "quadperf")
        if P.value is None or g.value is None or t.value is None:
            return None, st
        if t.value >= 0:
            return None, f"no common P with gamma <= {GAMMA_MAX:g} (best LMI level {t.value:.3g} >= 0)"
        return (0.5 * (P.value + P.value.T), float(g.value)), st

    def violation(sol):
        P, g = sol
        return np.linalg.eigvalsh(_brl(Ab, Bb, Cb, Ds, P, g * (1 + 1e-6)))[:, -1]

    if abscissa.max() >= 0:
        sol, status, used = None, f"vertex {int(np.argmax(abscissa))} unstable (frozen)", 0
    else:
        sol, status, used = _active_set(len(Ab), solve_subset, violation, first)
    Pv, g_solver = (None, np.inf) if sol is None else sol
    gamma = _verified_gamma(Ab, Bb, Cb, Ds, Pv, g_solver) if Pv is not None and np.isfinite(g_solver) else np.inf
    worst = np.nan
    if vertex_norms:
        worst = _worst_vertex_hinf(As, Bs, Cs, Ds)
    return QuadPerfResult(
        holds=bool(gamma < 1.0),
        gamma=gamma,
        margin=1.0 - gamma,
        worst_vertex_hinf=worst,
        n_vertices=vs.n_vertices,
        vertex_source=vs.source,
        enclosure=vs.enclosure,
        P=None if Pv is None else Pv / s[:, None] / s[None, :] / c,
        solver_gamma=g_solver,
        solver_status=status,
        seconds=time.perf_counter() - t0,
        covers=covers_text(
            vs,
            f"an L2 gain below gamma = {gamma:.4g} from r to z = [W_S e; W_T y] "
            "(zero initial state) and exponential stability",
        ),
        info={"time_scale": c, "vertex_note": vs.note, "closed_loop_order": n, "lmi_vertices": used},
    )


def _worst_vertex_hinf(As, Bs, Cs, Ds) -> float:
    """Largest H∞ norm of the frozen vertices (``inf`` if one is unstable)."""
    from polyrob.analysis.norms import hinf_norm

    worst = 0.0
    for a, b, cc, d in zip(As, Bs, Cs, Ds):
        worst = max(worst, hinf_norm((a, b, cc, d)))  # inf for an unstable vertex
    return worst
