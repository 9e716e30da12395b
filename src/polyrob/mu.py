"""Structured singular value :math:`\\mu` for mixed real/complex uncertainty.

:func:`mussv` bounds :math:`\\mu_\\Delta(M)` of one complex matrix, like MATLAB's
``mussv``; :func:`mu_bounds` sweeps it over frequency for a python-control
model.  Every bound comes with its certificate:

* the **upper bound** :math:`\\beta` with scalings :math:`D \\succ 0` (commuting
  with :math:`\\Delta`) and :math:`G = G^H` (non-zero on real blocks only) such
  that :math:`M^H D^2 M + j(GM - M^H G) - \\beta^2 D^2 \\preceq 0`
  (Fan, Tits & Doyle 1991), on the padded square problem of
  :mod:`polyrob.blocks`;
* the **lower bound** :math:`\\ell` with a perturbation :math:`\\Delta` in the
  structure, :math:`\\bar\\sigma(\\Delta) = 1/\\ell` and
  :math:`\\det(I - M\\Delta) = 0`.

What is written by hand here and why: no Python library computes mixed
:math:`\\mu`.  SLICOT AB13MD (through ``slycot``) gives the upper bound for real
scalars + full complex blocks and is used whenever it applies; repeated
scalar blocks need the D-G LMI (solved with cvxpy); the lower bound (power
iteration + a local search) exists in no library at all.
"""

from __future__ import annotations

import sys as _sys
import warnings
from dataclasses import dataclass
from typing import Any, Callable, Literal, Optional

import numpy as np
import scipy.linalg as sla
from scipy.optimize import minimize

from ._threads import single_blas_thread
from .blocks import BlkLike, BlockStructure, as_block_structure
from .errors import PolyrobError, SolverError

__all__ = [
    "MussvResult",
    "MuBoundsResult",
    "mussv",
    "mu_bounds",
    "TimeLimitedCall",
]

Method = Literal["auto", "ab13md", "lmi"]


# =============================================================== results
@dataclass(frozen=True, eq=False)
class MussvResult:
    """Bounds on :math:`\\mu` of one matrix and their certificates.

    Attributes
    ----------
    upper, lower : float
        :math:`\\ell \\le \\mu_\\Delta(M) \\le` ``upper``.
    delta : ndarray
        Worst perturbation of the lower bound (shape of :math:`\\Delta`):
        :math:`\\det(I - M\\Delta) \\approx 0`, :math:`\\bar\\sigma(\\Delta) = 1/\\ell`.
        The zero matrix when ``lower == 0`` (no destabilising Δ was found;
        for purely real structures μ may truly be 0).
    D, G : ndarray
        Upper-bound scalings on the padded square problem (``D`` in square-root
        form, see module docstring).
    Dl, Dr : ndarray
        ``D`` restricted to M's rows and columns: for complex-only structures
        :math:`\\bar\\sigma(D_l M D_r^{-1}) \\le` ``upper``.
    structure : BlockStructure
    method : str
        Upper-bound method used (``"ab13md"`` or ``"lmi"``).
    """

    upper: float
    lower: float
    delta: np.ndarray
    D: np.ndarray
    G: np.ndarray
    Dl: np.ndarray
    Dr: np.ndarray
    structure: BlockStructure
    method: str

    def lmi_residual(self, M: np.ndarray) -> float:
        """Largest eigenvalue of the D-G LMI at ``upper``, relative to ``upper**2``.

        ``<= ~1e-8`` means the scalings certify the upper bound.
        """
        Ms = self.structure.pad(self.structure.check_m(M))
        P = self.D @ self.D
        L = Ms.conj().T @ P @ Ms + 1j * (self.G @ Ms - Ms.conj().T @ self.G) - self.upper**2 * P
        L = (L + L.conj().T) / 2
        return float(np.linalg.eigvalsh(L)[-1]) / max(self.upper**2 * np.linalg.norm(P, 2), 1e-300)


@dataclass(frozen=True, eq=False)
class MuBoundsResult:
    """:math:`\\mu` bounds over frequency (see :func:`mu_bounds`).

    Attributes
    ----------
    omega, upper, lower : ndarray
        Sorted frequencies (rad/s, grid + refinement points) and bounds.
    D, G : ndarray
        Upper-bound scalings per frequency, shape ``(N, n, n)`` (padded).
    peak_upper, peak_upper_frequency : float
        :math:`\\max_\\omega` upper bound and where it is reached.
    peak_lower, critical_frequency : float
        :math:`\\max_\\omega` lower bound and where it is reached.
    worst_delta : ndarray
        Destabilising perturbation at ``critical_frequency`` on the boundary:
        :math:`\\bar\\sigma = 1/` ``peak_lower``, :math:`\\det(I - M(j\\omega_c)\\Delta) = 0`.
    structure : BlockStructure
    method : str
    warm_start_fallbacks : int
        Number of AB13MD warm starts that timed out or failed (then cold).
    """

    omega: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    D: np.ndarray
    G: np.ndarray
    peak_upper: float
    peak_upper_frequency: float
    peak_lower: float
    critical_frequency: float
    worst_delta: np.ndarray
    structure: BlockStructure
    method: str
    warm_start_fallbacks: int = 0


# ======================================================== upper bounds
def _ab13md_impl(Z, nblock, itype, x=None):
    """Indirection so tests can substitute a misbehaving AB13MD."""
    import slycot

    return slycot.ab13md(Z, nblock, itype) if x is None else slycot.ab13md(Z, nblock, itype, x)


_AB13MD_DEFAULT = _ab13md_impl


def _upper_ab13md(Ms: np.ndarray, st: BlockStructure, result=None):
    """Cold AB13MD call (or use a precomputed ``result``) -> (bound, D, G, x)."""
    n = Ms.shape[0]
    if not np.any(Ms):
        return 0.0, np.eye(n), np.zeros((n, n)), None
    if result is None:
        from slycot.exceptions import SlycotError

        nblock, itype = st.ab13md_args
        try:
            result = _ab13md_impl(Ms, nblock, itype)
        except SlycotError as exc:
            raise SolverError(f"SLICOT AB13MD failed: {exc}") from exc
    bound, d, g, x = result
    return float(bound), np.diag(np.asarray(d, float)), np.diag(np.asarray(g, float)), x


def _cert_beta(Ms: np.ndarray, P: np.ndarray, G: np.ndarray) -> tuple[float, np.ndarray]:
    """Smallest beta certified by given (P = D^2, G): a generalized eigenvalue.

    Returns ``(beta, P)`` with ``P`` made safely definite.

    Re-deriving beta from the scalings makes the LMI bound exact whatever the
    accuracy of the SDP solver.
    """
    P = (P + P.conj().T) / 2
    ev = np.linalg.eigvalsh(P)
    if ev[-1] <= 0:
        return np.inf, P
    if ev[0] < 1e-9 * ev[-1]:
        # solver noise left P barely definite; a shift by I keeps it in the
        # commutant of Delta and the certificate below stays exact for it
        P = P + (1e-9 * ev[-1] - ev[0]) * np.eye(P.shape[0])
    A = Ms.conj().T @ P @ Ms + 1j * (G @ Ms - Ms.conj().T @ G)
    A = (A + A.conj().T) / 2
    try:
        lam = sla.eigh(A, P, eigvals_only=True)[-1]
    except np.linalg.LinAlgError:
        return np.inf, P
    return float(np.sqrt(max(lam, 0.0))), P


def _perron_upper(Ms: np.ndarray, st: BlockStructure) -> tuple[float, np.ndarray]:
    """Cheap D-scaled upper bound (Perron scaling of the block-norm matrix).

    ``D = diag(d_i I)`` commutes with every structure, so
    ``sigma_max(D M D^-1)`` is a valid upper bound; the Perron vectors of the
    matrix of block norms give a good ``d`` (Safonov's heuristic).
    """
    sls = st.padded_slices
    B = np.array([[np.linalg.norm(Ms[a, b], 2) for b in sls] for a in sls]) + 1e-12
    lv, V = np.linalg.eig(B)
    lw, W = np.linalg.eig(B.T)
    x, y = np.abs(V[:, np.argmax(np.abs(lv))]), np.abs(W[:, np.argmax(np.abs(lw))])
    d = np.sqrt(np.maximum(y, 1e-300) / np.maximum(x, 1e-300))
    d = np.concatenate([np.full(sl.stop - sl.start, di) for sl, di in zip(sls, d / d.max())])
    if not np.all(np.isfinite(d)) or d.min() <= 0:
        d = np.ones(Ms.shape[0])
    return float(np.linalg.norm(d[:, None] * Ms / d[None, :], 2)), np.diag(d)


class _LmiUpper:
    """D-G LMI upper bound by bisection on beta (cvxpy).

    One problem is compiled per matrix with ``beta**2`` as a DPP parameter,
    so the bisection steps only re-solve.  (A Schur form with M as a
    parameter too would compile once per sweep, but doubles the LMI size and
    was slower overall.)
    """

    def __init__(self, st: BlockStructure, solver: Optional[str] = None, kappa: float = 1e6):
        self.st, self.solver, self.kappa = st, solver, kappa

    def _build(self, Ms: np.ndarray):
        import cvxpy as cp

        st, n = self.st, self.st.padded_size
        self.b2 = cp.Parameter(nonneg=True)
        P, G = 0, 0
        for b, sl in zip(st.blocks, st.padded_slices):
            S = np.zeros((n, b.size))
            S[sl, :] = np.eye(b.size)
            if b.repeated:  # full Hermitian scalings commute with delta*I
                Pi = cp.Variable((b.size, b.size), hermitian=True)
                P = P + S @ Pi @ S.T
                if b.kind == "real":
                    Gi = cp.Variable((b.size, b.size), hermitian=True)
                    G = G + S @ Gi @ S.T
            else:
                p = cp.Variable()
                P = P + p * (S @ S.T)
                if b.kind == "real":
                    g = cp.Variable()
                    G = G + g * (S @ S.T)
        self.P, self.G = P, G
        MH = Ms.conj().T
        # Minimising the LMI's largest eigenvalue t (instead of a pure
        # feasibility problem) keeps the SDP strictly feasible, which interior
        # point solvers handle far better next to the boundary.
        self.t = cp.Variable()
        L = MH @ P @ Ms - self.b2 * P - self.t * np.eye(n)
        if not isinstance(G, int):  # G-scalings only exist with real blocks
            L = L + 1j * (G @ Ms - MH @ G)
        cons = [(L + L.H) / 2 << 0, P >> np.eye(n) / self.kappa, cp.real(cp.trace(P)) == n]
        self.prob = cp.Problem(cp.Minimize(self.t), cons)

    def _solve(self, b2: float):
        self.b2.value = b2
        with warnings.catch_warnings():
            # "inaccurate" answers are fine: _cert_beta re-certifies them exactly
            warnings.simplefilter("ignore")
            try:
                self.prob.solve(solver=self.solver or "CLARABEL")
            except Exception:  # noqa: BLE001 - interior point stalls near the boundary
                try:
                    self.prob.solve(solver="SCS", eps=1e-6, max_iters=5000)
                except Exception:  # noqa: BLE001
                    return None
        if self.prob.status not in ("optimal", "optimal_inaccurate"):
            return None
        P = np.asarray(self.P.value, dtype=complex)
        n = P.shape[0]
        G = np.zeros((n, n), complex) if isinstance(self.G, int) else np.asarray(self.G.value, dtype=complex)
        return (P + P.conj().T) / 2, (G + G.conj().T) / 2

    def __call__(self, Ms: np.ndarray, lo: float = 0.0, rtol: float = 1e-4):
        n = Ms.shape[0]
        best = (float(np.linalg.norm(Ms, 2)), np.eye(n, dtype=complex), np.zeros((n, n), complex))
        bp, Dp = _perron_upper(Ms, self.st)
        if bp < best[0]:
            best = (bp, (Dp @ Dp).astype(complex), best[2])
        if best[0] == 0.0:
            return 0.0, np.eye(n), np.zeros((n, n))
        hi, lo = best[0], min(max(lo, 0.0), best[0])
        if hi - lo > rtol * hi:
            self._build(Ms)
        while hi - lo > rtol * hi:
            mid = 0.5 * (lo + hi)
            sol = self._solve(mid**2)
            if sol is None:
                lo = mid
                continue
            # any (P, G) certifies *some* beta: keep the best one seen
            beta, P = _cert_beta(Ms, *sol)
            if beta < best[0]:
                best = (beta, P, sol[1])
            if self.t.value is not None and self.t.value <= 0:
                hi = max(min(mid, beta), lo)
            else:
                lo = mid
        beta, P, G = best
        D = sla.sqrtm(P)
        return beta, (D + D.conj().T) / 2, G


# ======================================================== lower bound
def _q_from(a: np.ndarray, w: np.ndarray, meta) -> np.ndarray:
    """Structured Q (norm <= 1) aligning ``a`` with ``w`` block by block.

    This is the Packard-Doyle power-iteration update: it maximises
    ``Re(w^H Q a)`` over the unit ball of each complex block.  For real blocks
    (Young-Doyle) the projection of the complex alignment on the reals is used
    as a heuristic; the local search below makes it exact.
    """
    n = a.size
    Q = np.zeros((n, n), dtype=complex)
    for kind, rep, sl in meta:
        ai, wi = a[sl], w[sl]
        na, nw = np.linalg.norm(ai), np.linalg.norm(wi)
        if na < 1e-300 or nw < 1e-300:
            continue
        if kind == "full" and not rep:
            Q[sl, sl] = np.outer(wi, ai.conj()) / (na * nw)
        else:
            c = np.vdot(ai, wi) / (na * nw)
            q = c.real if kind == "real" else (c / abs(c) if abs(c) > 1e-300 else 1.0)
            Q[sl, sl] = q * np.eye(sl.stop - sl.start)
    return Q


def _power_iteration(Ms, meta, b, w, maxiter=60, tol=1e-9):
    """Packard-Doyle / Young-Doyle power iteration; returns the last Q, b, w."""
    beta_old = 0.0
    Q = np.zeros_like(Ms)
    for _ in range(maxiter):
        a = Ms @ b
        na = np.linalg.norm(a)
        if na < 1e-300:
            break
        a /= na
        z = _q_from(a, w, meta).conj().T @ w
        w = Ms.conj().T @ z
        nw = np.linalg.norm(w)
        if nw < 1e-300:
            break
        w /= nw
        Q = _q_from(a, w, meta)
        b = Q @ a
        nb = np.linalg.norm(b)
        if nb < 1e-300:
            break
        b /= nb
        beta = na * nb
        if abs(beta - beta_old) <= tol * max(beta, 1e-300):
            break
        beta_old = beta
    return Q, b, w


def _blocks_norm(delta_sq: np.ndarray, st: BlockStructure) -> float:
    return max((np.linalg.norm(delta_sq[sl, sl], 2) for sl in st.padded_slices), default=0.0)


def _candidate(Ms, st, Q):
    """Turn a structured Q into a verified (lower, padded delta) or None."""
    lam, X = np.linalg.eig(Ms @ Q)
    nq = _blocks_norm(Q, st)
    if nq == 0.0 or not np.any(np.abs(lam) > 0):
        return None
    if st.has_real:
        # only real eigenvalues are admissible: a complex phase cannot be
        # absorbed by real blocks.
        ok = np.abs(lam.imag) <= 1e-9 * np.abs(lam) + 1e-300
        if not np.any(ok & (np.abs(lam) > 0)):
            return None
        k = int(np.argmax(np.where(ok, np.abs(lam), -1.0)))
        lk = lam[k].real
    else:
        k = int(np.argmax(np.abs(lam)))
        lk = lam[k]
    return abs(lk) / nq, Q / lk, X[:, k]


def _vertex_candidates(Ms, st, max_real=10):
    """Exhaustive sign patterns of the real scalars (exact for real M, real blocks)."""
    idx = [sl for b, sl in zip(st.blocks, st.padded_slices) if b.kind == "real"]
    if len(idx) > max_real or len(idx) != len(st.blocks):
        return []
    n = Ms.shape[0]
    signs = np.array(np.meshgrid(*[[-1.0, 1.0]] * len(idx), indexing="ij")).reshape(len(idx), -1).T
    qdiag = np.zeros((signs.shape[0], n))
    for j, sl in enumerate(idx):
        qdiag[:, sl] = signs[:, [j]]
    lam = np.linalg.eigvals(Ms[None, :, :] * qdiag[:, None, :])
    score = np.where(np.abs(lam.imag) <= 1e-9 * np.abs(lam), np.abs(lam), -1.0).max(axis=1)
    best = int(np.argmax(score))
    if score[best] <= 0:
        return []
    c = _candidate(Ms, st, np.diag(qdiag[best]).astype(complex))
    return [c] if c is not None else []


def _refine(Ms, st, delta0, x0):
    """Local search for a smaller destabilising Delta (SLSQP).

    With ``y = Delta x`` and ``x = M y`` the condition ``det(I - M Delta) = 0``
    becomes per-block constraints on ``y``: ``|y_i| <= s |x_i|`` for full and
    complex scalar blocks, plus ``Im(conj(x_i) y_i) = 0`` for real scalars and
    ``y_i = delta_i x_i`` for repeated ones.  Minimising ``s`` maximises the
    lower bound ``1/s``; the result is re-verified by the caller.
    """
    n = Ms.shape[0]
    T = np.block([[Ms.real, -Ms.imag], [Ms.imag, Ms.real]])
    y0 = delta0 @ x0
    ny = np.linalg.norm(y0)
    if ny == 0:
        return None
    y0 = y0 / ny
    rep = [(b, sl) for b, sl in zip(st.blocks, st.padded_slices) if b.repeated]
    nd = sum(1 if b.kind == "real" else 2 for b, _ in rep)
    nv = 2 * n + nd + 1
    dvals = []
    for b, sl in rep:
        d = delta0[sl.start, sl.start]
        dvals += [d.real] if b.kind == "real" else [d.real, d.imag]
    p0 = np.concatenate([y0.real, y0.imag, dvals, [_blocks_norm(delta0, st)]])
    cr, ci = y0.real, y0.imag
    Tr, Ti = T[:n], T[n:]
    I2n = np.eye(2 * n)
    blocks = list(zip(st.blocks, st.padded_slices))
    real1 = np.array([sl.start for b, sl in blocks if b.kind == "real" and not b.repeated], dtype=int)
    nonrep = [sl for b, sl in blocks if not b.repeated]
    reps, k = [], 2 * n
    for b, sl in blocks:
        if b.repeated:
            reps.append((sl, b.kind == "real", k))
            k += 1 if b.kind == "real" else 2

    def split(p):
        xx = T @ p[: 2 * n]
        return p[:n], p[n : 2 * n], xx[:n], xx[n:]

    # Analytic Jacobians: SLSQP with finite differences was ~10x slower.
    def eq(p):
        yr, yi, xr, xi = split(p)
        out = [[cr @ yr + ci @ yi - 1.0, cr @ yi - ci @ yr], xr[real1] * yi[real1] - xi[real1] * yr[real1]]
        for sl, is_real, k in reps:
            dr, di = p[k], (0.0 if is_real else p[k + 1])
            out += [yr[sl] - (dr * xr[sl] - di * xi[sl]), yi[sl] - (dr * xi[sl] + di * xr[sl])]
        return np.concatenate(out)

    def eq_jac(p):
        yr, yi, xr, xi = split(p)
        rows = [np.r_[cr, ci, np.zeros(nv - 2 * n)], np.r_[-ci, cr, np.zeros(nv - 2 * n)]]
        J = np.zeros((len(real1), nv))
        J[:, : 2 * n] = yi[real1, None] * Tr[real1] - yr[real1, None] * Ti[real1]
        J[np.arange(len(real1)), n + real1] += xr[real1]
        J[np.arange(len(real1)), real1] -= xi[real1]
        out = [np.array(rows), J]
        for sl, is_real, k in reps:
            dr, di = p[k], (0.0 if is_real else p[k + 1])
            m = sl.stop - sl.start
            J1, J2 = np.zeros((m, nv)), np.zeros((m, nv))
            J1[:, : 2 * n] = I2n[sl] - dr * Tr[sl] + di * Ti[sl]
            J2[:, : 2 * n] = I2n[n + sl.start : n + sl.stop] - dr * Ti[sl] - di * Tr[sl]
            J1[:, k], J2[:, k] = -xr[sl], -xi[sl]
            if not is_real:
                J1[:, k + 1], J2[:, k + 1] = xi[sl], -xr[sl]
            out += [J1, J2]
        return np.vstack(out)

    def ineq(p):
        yr, yi, xr, xi = split(p)
        s2 = p[-1] ** 2
        out = [s2 * (xr[sl] @ xr[sl] + xi[sl] @ xi[sl]) - (yr[sl] @ yr[sl] + yi[sl] @ yi[sl]) for sl in nonrep]
        out += [s2 - p[k] ** 2 - (0.0 if is_real else p[k + 1] ** 2) for _, is_real, k in reps]
        return np.array(out)

    def ineq_jac(p):
        yr, yi, xr, xi = split(p)
        s = p[-1]
        J = np.zeros((len(nonrep) + len(reps), nv))
        for r, sl in enumerate(nonrep):
            J[r, : 2 * n] = 2 * s**2 * (xr[sl] @ Tr[sl] + xi[sl] @ Ti[sl])
            J[r, sl] -= 2 * yr[sl]
            J[r, n + sl.start : n + sl.stop] -= 2 * yi[sl]
            J[r, -1] = 2 * s * (xr[sl] @ xr[sl] + xi[sl] @ xi[sl])
        for r, (_, is_real, k) in enumerate(reps, start=len(nonrep)):
            J[r, k] = -2 * p[k]
            if not is_real:
                J[r, k + 1] = -2 * p[k + 1]
            J[r, -1] = 2 * s
        return J

    e_s = np.eye(nv)[-1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = minimize(
            lambda p: p[-1], p0, jac=lambda p: e_s, method="SLSQP",
            constraints=[{"type": "eq", "fun": eq, "jac": eq_jac},
                         {"type": "ineq", "fun": ineq, "jac": ineq_jac}],
            bounds=[(None, None)] * (nv - 1) + [(0.0, None)],
            options={"maxiter": 200, "ftol": 1e-12},
        )
    p = res.x
    yr, yi, xr, xi = split(p)
    y, x = yr + 1j * yi, xr + 1j * xi
    delta = np.zeros((n, n), dtype=complex)
    k = 2 * n
    for b, sl in zip(st.blocks, st.padded_slices):
        xi_, yi_ = x[sl], y[sl]
        if b.repeated:
            d = p[k] + (0.0 if b.kind == "real" else 1j * p[k + 1])
            k += 1 if b.kind == "real" else 2
            delta[sl, sl] = d * np.eye(b.size)
        elif np.linalg.norm(xi_) > 1e-300:
            if b.kind == "real":
                delta[sl, sl] = (yi_[0] / xi_[0]).real
            else:
                delta[sl, sl] = np.outer(yi_, xi_.conj()) / np.vdot(xi_, xi_).real
    # Q := delta normalised; _candidate re-verifies and rescales exactly.
    nd_ = _blocks_norm(delta, st)
    return _candidate(Ms, st, delta / nd_) if nd_ > 0 else None


def _lower_bound(Ms, st, *, starts=4, refine=True, seed=0, init=None, real_starts=8,
                 target=np.inf, D=None):
    """Best verified (lower, padded delta, power-iteration state).

    ``D`` (upper-bound scaling, commuting with Delta) balances the matrix for
    the power iteration: ``rho(D M D^-1 Q) = rho(M Q)`` so its Q's are valid
    for M, and the scaled matrix's singular vectors are far better starts
    (unscaled, they can sit on disjoint blocks and stall the iteration at a
    spurious fixed point).  ``target`` (a known upper bound) stops the local
    search once reached.
    """
    n = Ms.shape[0]
    meta = [("real" if b.kind == "real" else "full" if (b.kind == "full" or b.size == 1) else "complex",
             b.repeated, sl) for b, sl in zip(st.blocks, st.padded_slices)]
    if not np.any(Ms):
        return 0.0, np.zeros((n, n), complex), None
    rng = np.random.default_rng(seed)
    if D is None:
        D = _perron_upper(Ms, st)[1]
    try:
        Mp = D @ Ms @ np.linalg.inv(D)
    except np.linalg.LinAlgError:
        Mp = Ms
    if not np.all(np.isfinite(Mp)):
        Mp = Ms
    U, _, Vh = np.linalg.svd(Mp)
    inits = [init] if init is not None else []
    inits.append((Vh[0].conj(), U[:, 0]))
    for _ in range(starts - 1):
        inits.append(tuple(rng.standard_normal(n) + 1j * rng.standard_normal(n) for _ in range(2)))
    cands, state = [], None
    for b0, w0 in inits:
        Q, b, w = _power_iteration(Mp, meta, b0, w0)
        state = state or (b, w)
        c = _candidate(Ms, st, Q)
        if c is not None:
            cands.append(c)
        elif refine and np.any(Q):
            # no admissible eigenvalue yet (real blocks): seed the local
            # search with the dominant, possibly complex, eigenpair.
            lam, X = np.linalg.eig(Ms @ Q)
            k = int(np.argmax(np.abs(lam)))
            if abs(lam[k]) > 0:
                cands.append((0.0, Q / lam[k], X[:, k]))
    if st.has_real:
        cands += _vertex_candidates(Ms, st)
    good = [c for c in cands if c[0] > 0 and _singular(Ms, c[1])]
    best = max(good, key=lambda c: c[0]) if good else (0.0, np.zeros((n, n), complex))
    if refine and best[0] < target * (1 - 1e-7):
        seeds = sorted(cands, key=lambda c: -c[0])[:2]
        if st.has_real:
            # Real blocks make the lower bound a non-convex search with many
            # local optima (the power iteration often stalls); random
            # perturbations as extra seeds of the local search pay off.
            for _ in range(real_starts):
                Q = st.pad_delta(st.random_delta(rng, uniform=True))
                lam, X = np.linalg.eig(Ms @ Q)
                k = int(np.argmax(np.abs(lam)))
                if abs(lam[k]) > 0:
                    seeds.append((0.0, Q / lam[k], X[:, k]))
        for c in seeds:
            r = _refine(Ms, st, c[1], c[2])
            if r is not None and r[0] > best[0] and _singular(Ms, r[1]):
                best = r
                if best[0] >= target * (1 - 1e-7):  # matches the upper bound
                    break
    return best[0], best[1], state


def _singular(Ms, delta_sq, tol=1e-7):
    """Verify det(I - M Delta) = 0 via the smallest singular value."""
    A = np.eye(Ms.shape[0]) - Ms @ delta_sq
    return np.linalg.svd(A, compute_uv=False)[-1] <= tol * max(1.0, np.linalg.norm(A, 2))


# ================================================================ mussv
def _choose_method(st: BlockStructure, method: str) -> str:
    if method == "auto":
        return "lmi" if st.has_repeated else "ab13md"
    if method not in ("ab13md", "lmi"):
        raise PolyrobError(f"method must be 'auto', 'ab13md' or 'lmi', got {method!r}")
    if method == "ab13md" and st.has_repeated:
        raise PolyrobError("AB13MD cannot handle repeated scalar blocks; use method='lmi'")
    return method


def mussv(
    M: np.ndarray,
    blk: BlkLike,
    *,
    method: Method = "auto",
    lower: bool = True,
    refine: bool = True,
    starts: int = 4,
    seed: int = 0,
    rtol: float = 1e-4,
    solver: Optional[str] = None,
) -> MussvResult:
    """Bounds on the structured singular value of a complex matrix.

    Parameters
    ----------
    M : (nc, nr) array_like
        Matrix closing the loop with :math:`\\Delta` (``nr x nc``).
    blk : BlockStructure or array_like
        MATLAB ``blk`` encoding, see :mod:`polyrob.blocks`.
    method : {"auto", "ab13md", "lmi"}
        Upper bound: SLICOT AB13MD (real scalars, full complex blocks) or
        the D-G LMI solved by bisection with cvxpy (also repeated scalars).
        ``"auto"`` picks AB13MD whenever it applies.
    lower : bool
        Compute the lower bound and its worst perturbation.
    refine : bool
        Polish the power-iteration lower bound with a local search.
    starts : int
        Number of power-iteration starts (singular vectors + random).
    seed : int
        Seed of the random starts (results are deterministic).
    rtol : float
        Relative bisection tolerance of the LMI method.
    solver : str, optional
        cvxpy solver for the LMI method (default CLARABEL, SCS as fallback).

    Returns
    -------
    MussvResult

    Raises
    ------
    PolyrobError
        Bad shapes or structure; :class:`~polyrob.errors.SolverError` if the
        upper-bound solver fails.

    Examples
    --------
    Skogestad & Postlethwaite, Example 8.5:

    >>> import numpy as np
    >>> from polyrob.mu import mussv
    >>> M = np.array([[2.0, 2.0], [-1.0, -1.0]])
    >>> r = mussv(M, [[1, 0], [1, 0]])
    >>> print(f"{r.lower:.4f} <= mu <= {r.upper:.4f}")
    3.0000 <= mu <= 3.0000
    >>> bool(abs(np.linalg.det(np.eye(2) - M @ r.delta)) < 1e-9)
    True
    """
    st = as_block_structure(blk)
    M = st.check_m(M)
    meth = _choose_method(st, method)
    with single_blas_thread():
        return _mussv(M, st, meth, lower, refine, starts, seed, rtol, solver)


def _mussv(M, st, meth, lower, refine, starts, seed, rtol, solver) -> MussvResult:
    Ms = st.pad(M)
    n = Ms.shape[0]
    lo, dsq = 0.0, np.zeros((n, n), complex)
    if meth == "ab13md":
        up, D, G, _ = _upper_ab13md(Ms, st)
    else:
        # a verified lower bound narrows the bisection bracket for free
        lo, dsq, _ = _lower_bound(Ms, st, starts=1, refine=False, seed=seed)
        up, D, G = _LmiUpper(st, solver)(Ms, lo=lo * (1 - 1e-9), rtol=rtol)
    if lower:
        lo2, dsq2, _ = _lower_bound(Ms, st, starts=starts, refine=refine, seed=seed, target=up, D=D)
        if lo2 >= lo:
            lo, dsq = lo2, dsq2
    else:
        lo, dsq = 0.0, np.zeros((n, n), complex)
    # Rounding can leave the certified upper bound a hair below a verified
    # lower bound when both are tight; they bound the same number.
    up = max(up, lo)
    Dl, Dr = st.restrict_scaling(D)
    return MussvResult(float(up), float(lo), st.unpad_delta(dsq), D, G, Dl, Dr, st, meth)


# ============================================================ warm start
# The worker is plain stdlib code run by ``python -c``: it imports nothing of
# polyrob (whose package import is heavy) unless unpickling ``fn`` needs it.
# Pickles come in on stdin and go out on a private duplicate of fd 1, while
# fd 1 itself is pointed at stderr so stray prints cannot corrupt the channel.
_BOOT = """
import os, pickle, sys
out = os.fdopen(os.dup(1), "wb"); os.dup2(2, 1)
inp = sys.stdin.buffer
sys.path[:] = pickle.load(inp)
fn = pickle.load(inp)
pickle.dump(("ready", None), out); out.flush()
while True:
    try:
        args = pickle.load(inp)
    except EOFError:
        break
    try:
        msg = ("ok", fn(*args))
    except Exception as exc:
        msg = ("err", repr(exc))
    pickle.dump(msg, out); out.flush()
"""


class TimeLimitedCall:
    """Call ``fn`` in a persistent worker process with a time limit.

    AB13MD warm starts (``x`` from the previous frequency) are known to hang
    forever on some inputs, and a Fortran loop cannot be interrupted from
    Python, so the call runs in a child process that is killed on timeout.
    The child is a fresh interpreter (``python -c``), not a fork (forking a
    process whose BLAS threads hold locks can deadlock) nor a
    ``multiprocessing`` spawn (which re-imports the user's ``__main__``
    script); ``fn`` must therefore be picklable, e.g. a module-level function.

    Parameters
    ----------
    fn : callable
        Function to call.
    timeout : float
        Seconds to wait for each call (the worker's start-up is not counted).
    startup_timeout : float
        Seconds to wait for a new worker to import its modules.

    Examples
    --------
    >>> from polyrob.mu import TimeLimitedCall
    >>> with TimeLimitedCall(abs, timeout=5.0) as call:
    ...     call(-3)
    (True, 3)
    """

    def __init__(self, fn: Callable[..., Any], timeout: float = 2.0, startup_timeout: float = 120.0):
        self.fn, self.timeout, self.startup_timeout = fn, float(timeout), float(startup_timeout)
        self._proc = self._queue = None

    def _start(self) -> bool:
        import pickle
        import queue
        import subprocess
        import threading

        self._proc = subprocess.Popen(
            [_sys.executable, "-c", _BOOT], stdin=subprocess.PIPE, stdout=subprocess.PIPE
        )
        self._queue = q = queue.Queue()
        stdout = self._proc.stdout

        def reader():  # a thread makes the wait portable (no select on pipes)
            while True:
                try:
                    q.put(pickle.load(stdout))
                except Exception:  # noqa: BLE001 - EOF or garbage: worker is gone
                    q.put(("dead", None))
                    return

        threading.Thread(target=reader, daemon=True).start()
        try:
            pickle.dump(list(_sys.path), self._proc.stdin)
            pickle.dump(self.fn, self._proc.stdin)
            self._proc.stdin.flush()
            if q.get(timeout=self.startup_timeout)[0] == "ready":
                return True
        except Exception:  # noqa: BLE001 - unpicklable fn, broken pipe, timeout
            pass
        self.close()
        return False

    def __call__(self, *args) -> tuple[bool, Any]:
        """Return ``(True, value)``, or ``(False, reason)`` on timeout/error."""
        import pickle
        import queue

        if (self._proc is None or self._proc.poll() is not None) and not self._start():
            return False, "worker did not start"
        try:
            pickle.dump(args, self._proc.stdin)
            self._proc.stdin.flush()
            status, value = self._queue.get(timeout=self.timeout)
        except queue.Empty:
            self.close()  # hung: kill the worker, a fresh one starts next call
            return False, "timeout"
        except Exception as exc:  # noqa: BLE001 - broken pipe: worker died
            self.close()
            return False, f"worker failed: {exc!r}"
        if status == "ok":
            return True, value
        if status == "dead":
            self.close()
            return False, "worker died"
        return False, value

    def close(self):
        """Kill the worker (a new one starts on the next call)."""
        if self._proc is not None:
            if self._proc.poll() is None:
                self._proc.kill()
            try:
                self._proc.wait(timeout=5)
            except Exception:  # noqa: BLE001
                pass
            for f in (self._proc.stdin, self._proc.stdout):
                try:
                    f.close()
                except Exception:  # noqa: BLE001
                    pass
        self._proc = self._queue = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass


# ============================================================ frequency
def _is_discrete(sys) -> bool:
    dt = getattr(sys, "dt", 0)
    return dt not in (0, None, False)


def _default_grid(sys, per_decade: int = 40) -> np.ndarray:
    """Log grid spanning the poles/zeros +- one decade (python-control style).

    Natural frequencies of the poles are inserted too: a lightly damped
    resonance is then bracketed by grid points, which the peak refinement
    relies on.
    """
    feats = []
    for attr in ("poles", "zeros"):
        try:
            feats.append(np.atleast_1d(getattr(sys, attr)()))
        except Exception:  # noqa: BLE001 - zeros of non-square/odd systems
            pass
    f = np.concatenate(feats).astype(complex) if feats else np.array([], dtype=complex)
    if _is_discrete(sys):  # map z-plane features to continuous frequencies
        f = np.log(f[np.abs(f) > 0]) / float(sys.dt)
    f = np.abs(f)
    f = f[np.isfinite(f) & (f > 1e-12)]
    lo, hi = (-1.0, 1.0) if f.size == 0 else (np.floor(np.log10(f.min())) - 1, np.ceil(np.log10(f.max())) + 1)
    w = np.logspace(lo, hi, int(per_decade * (hi - lo)) + 1)
    w = np.union1d(w, f)
    if _is_discrete(sys):
        w = w[w < np.pi / sys.dt]
    return w


def _freqresp(sys, omega: np.ndarray) -> np.ndarray:
    """Frequency response as an ``(N, p, m)`` array, vectorised over omega."""
    import control

    with np.errstate(divide="ignore", invalid="ignore"):  # poles on the grid -> inf
        if isinstance(sys, control.FrequencyResponseData):
            H = sys.eval(omega, squeeze=False)
        else:
            pts = np.exp(1j * omega * float(sys.dt)) if _is_discrete(sys) else 1j * omega
            H = sys(pts, squeeze=False, warn_infinite=False)
    return np.moveaxis(np.asarray(H, dtype=complex).reshape(sys.noutputs, sys.ninputs, -1), -1, 0)


def mu_bounds(
    sys,
    blk: BlkLike,
    omega: Optional[np.ndarray] = None,
    *,
    method: Method = "auto",
    refine_peak: bool = True,
    warm_start: bool = False,
    warm_timeout: float = 2.0,
    progress: Optional[bool] = None,
    rtol: float = 1e-4,
    solver: Optional[str] = None,
) -> MuBoundsResult:
    """:math:`\\mu` upper and lower bounds of an LTI system over frequency.

    Parameters
    ----------
    sys : control.StateSpace, TransferFunction or FrequencyResponseData
        The :math:`M` of the :math:`M`-:math:`\\Delta` loop.
    blk : BlockStructure or array_like
        Uncertainty structure (MATLAB ``blk`` encoding).
    omega : array_like, optional
        Frequencies in rad/s.  Default: a log grid over the system's poles and
        zeros (FRD: its own frequencies).
    method : {"auto", "ab13md", "lmi"}
        Upper-bound method, see :func:`mussv`.
    refine_peak : bool
        Golden-section search of the upper-bound peak between the grid points
        around the best local maxima, so a sharp resonance is not missed.
    warm_start : bool
        Warm-start AB13MD from the previous frequency.  Such calls run in a
        worker process killed after ``warm_timeout`` s (AB13MD warm starts can
        hang); then the sweep falls back to cold calls.
    progress : bool, optional
        tqdm progress bar; default: shown on a terminal for long sweeps.
    rtol, solver
        LMI method options, see :func:`mussv`.

    Returns
    -------
    MuBoundsResult

    Examples
    --------
    >>> import control
    >>> from polyrob.mu import mu_bounds
    >>> G = control.tf([1], [1, 0.2, 1])          # |G| peaks at 1/(2 zeta sqrt(1-zeta^2))
    >>> r = mu_bounds(G, [[1, 1]])
    >>> print(f"{r.peak_upper:.4f} {r.peak_lower:.4f} {r.peak_upper_frequency:.4f}")
    5.0252 5.0252 0.9899
    """
    import control

    st = as_block_structure(blk)
    if not isinstance(sys, control.LTI):
        raise PolyrobError(f"mu_bounds needs a python-control LTI system, got {type(sys).__name__}")
    if (sys.noutputs, sys.ninputs) != st.m_shape:
        raise PolyrobError(
            f"system is {sys.noutputs}x{sys.ninputs} but block structure {st} needs {st.m_shape}"
        )
    is_frd = isinstance(sys, control.FrequencyResponseData)
    if omega is None:
        omega = np.asarray(sys.omega if is_frd else _default_grid(sys), dtype=float)
    omega = np.unique(np.asarray(omega, dtype=float).ravel())
    # near-duplicates (a pole frequency next to a grid point) would make a
    # degenerate bracket for the peak refinement
    omega = omega[np.r_[True, np.diff(omega) > 1e-9 * np.abs(omega[1:])]] if omega.size else omega
    if omega.size == 0 or np.any(omega < 0) or not np.all(np.isfinite(omega)):
        raise PolyrobError("omega must be a non-empty array of finite non-negative frequencies")
    meth = _choose_method(st, method)
    with single_blas_thread():
        return _sweep(sys, st, omega, is_frd, meth, refine_peak, warm_start, warm_timeout, progress, rtol, solver)


def _sweep(sys, st, omega, is_frd, meth, refine_peak, warm_start, warm_timeout, progress, rtol, solver):
    from tqdm import tqdm

    lmi = _LmiUpper(st, solver) if meth == "lmi" else None
    guard = None
    if warm_start and meth == "ab13md":
        import slycot

        # slycot's own function when not substituted: the worker then never
        # imports polyrob (and its heavy dependencies)
        fn = slycot.ab13md if _ab13md_impl is _AB13MD_DEFAULT else _ab13md_impl
        guard = TimeLimitedCall(fn, warm_timeout)
    fallbacks = 0
    state = {"x": None, "pi": None}
    n = st.padded_size

    def upper_at(Ms, lo=0.0):
        nonlocal fallbacks, guard
        if not np.all(np.isfinite(Ms)):  # on a pole of M: mu is infinite
            return np.inf, np.eye(n), np.zeros((n, n))
        if lmi is not None:
            return lmi(Ms, lo=lo, rtol=rtol)
        res = None
        if guard is not None and state["x"] is not None and np.any(Ms):
            ok, val = guard(Ms, *st.ab13md_args, state["x"])
            if ok:
                res = val
            else:  # hung or failed once: stop warm-starting for this sweep
                fallbacks += 1
                guard.close()
                guard = None
        up, D, G, x = _upper_ab13md(Ms, st, res)
        state["x"] = x if x is not None else state["x"]
        return up, D, G

    def lower_at(Ms, refine=False, target=np.inf, D=None):
        if not np.all(np.isfinite(Ms)):
            return np.inf, np.zeros((n, n), complex)
        lo, dsq, pi = _lower_bound(Ms, st, starts=1 if not refine else 4, refine=refine,
                                   init=state["pi"], target=target, D=D)
        state["pi"] = pi if pi is not None else state["pi"]
        return lo, dsq

    H = st.pad(_freqresp(sys, omega))
    show = (omega.size >= 50) if progress is None else progress
    up, lo = np.zeros(omega.size), np.zeros(omega.size)
    Ds, Gs = np.zeros((omega.size, n, n), complex), np.zeros((omega.size, n, n), complex)
    deltas = {}
    try:
        for i in tqdm(range(omega.size), disable=None if show else True, desc="mu", leave=False):
            if lmi is not None:  # the bisection wants the lower bound as bracket
                lo[i], deltas[i] = lower_at(H[i])
            up[i], Ds[i], Gs[i] = upper_at(H[i], lo[i])
            l2, d2 = lower_at(H[i], D=Ds[i])
            if l2 >= lo[i]:
                lo[i], deltas[i] = l2, d2
        extra = []
        can_eval = not is_frd or getattr(sys, "ifunc", None) is not None
        if refine_peak and can_eval and omega.size >= 3:
            extra = _refine_peaks(omega, up, lambda w: upper_at(st.pad(_freqresp(sys, np.array([w])))[0])[0])
        # refined points (and the best lower-bound points) get the full treatment
        w_new = np.array([w for w in extra if w not in omega])
        if w_new.size:
            Hn = st.pad(_freqresp(sys, w_new))
            res = []
            for k in range(w_new.size):
                u = upper_at(Hn[k])
                res.append((u, lower_at(Hn[k], refine=True, target=u[0], D=u[1])))
            omega = np.concatenate([omega, w_new])
            up = np.concatenate([up, [r[0][0] for r in res]])
            lo = np.concatenate([lo, [r[1][0] for r in res]])
            Ds = np.concatenate([Ds, np.array([r[0][1] for r in res])])
            Gs = np.concatenate([Gs, np.array([r[0][2] for r in res])])
            for k, r in enumerate(res):
                deltas[omega.size - w_new.size + k] = r[1][1]
        # refine the lower bound where it matters: at its own and at the upper peak
        for i in {int(np.argmax(lo)), int(np.argmax(up))}:
            if lo[i] >= up[i] * (1 - 1e-7):
                continue
            lo_i, d_i = lower_at(st.pad(_freqresp(sys, omega[[i]]))[0], refine=True, target=up[i], D=Ds[i])
            if lo_i > lo[i]:
                lo[i], deltas[i] = lo_i, d_i
    finally:
        if guard is not None:
            guard.close()
    up = np.maximum(up, lo)
    order = np.argsort(omega)
    iu, il = int(np.argmax(up)), int(np.argmax(lo))
    return MuBoundsResult(
        omega=omega[order], upper=up[order], lower=lo[order], D=Ds[order], G=Gs[order],
        peak_upper=float(up[iu]), peak_upper_frequency=float(omega[iu]),
        peak_lower=float(lo[il]), critical_frequency=float(omega[il]),
        worst_delta=st.unpad_delta(deltas[il]), structure=st, method=meth,
        warm_start_fallbacks=fallbacks,
    )


def _refine_peaks(omega, up, f, n_peaks=3, xtol=1e-7):
    """Bounded scalar maximisation (in log omega) around the best local maxima."""
    from scipy.optimize import minimize_scalar

    inner = [i for i in range(omega.size) if (i == 0 or up[i] >= up[i - 1]) and (i == omega.size - 1 or up[i] >= up[i + 1])]
    inner = sorted(inner, key=lambda i: -up[i])[:n_peaks]
    out = []
    for i in inner:
        lo_i, hi_i = max(i - 1, 0), min(i + 1, omega.size - 1)
        if omega[lo_i] <= 0 or hi_i == lo_i:
            continue
        r = minimize_scalar(lambda x: -f(np.exp(x)), bounds=(np.log(omega[lo_i]), np.log(omega[hi_i])),
                            method="bounded", options={"xatol": xtol})
        out.append(float(np.exp(r.x)))
    return out
