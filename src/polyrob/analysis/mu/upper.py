"""Upper bounds of the structured singular value and their certificates.

* :func:`upper_ab13md`: SLICOT AB13MD (Fan, Tits & Doyle) through ``slycot``,
  for real scalars and full complex blocks;
* :class:`LmiUpper`: the D-G LMI solved by bisection with cvxpy, which also
  takes repeated scalar blocks;
* :class:`TimedAb13md`: AB13MD with a wall-clock safety net against a hung
  call (reported by the caller; never a choice of method);
* :func:`certified_beta`: the smallest ``beta`` that given scalings
  ``(P = D^2, G)`` certify, a generalized eigenvalue, so the bound is exact
  whatever the accuracy of the SDP solver.

Used by :func:`polyrob.analysis.mu.bounds.mussv` and :func:`polyrob.analysis.mu.bounds.mu_bounds`.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla

from polyrob.analysis.mu.blocks import BlockStructure, perron_upper
from polyrob.errors import SolverError

__all__ = [
    "ab13md_call",
    "upper_ab13md",
    "certified_beta",
    "LmiUpper",
    "TimedAb13md",
    "AB13MD_DEFAULT",
    "worker_function",
]


def ab13md_call(Z, nblock, itype, x=None):
    """``slycot.ab13md``, called through a module attribute so tests can substitute a misbehaving one."""
    import slycot

    return slycot.ab13md(Z, nblock, itype) if x is None else slycot.ab13md(Z, nblock, itype, x)


#: The genuine :func:`ab13md_call` (a substituted one is detected by identity).
AB13MD_DEFAULT = ab13md_call


def upper_ab13md(Ms: np.ndarray, st: BlockStructure, result=None):
    """AB13MD upper bound of ``mu(Ms)`` on the padded square problem.

    Parameters
    ----------
    Ms : (n, n) complex ndarray
        Padded square matrix (:meth:`BlockStructure.pad`).
    st : BlockStructure
        Without repeated scalar blocks.
    result : tuple, optional
        A precomputed ``slycot.ab13md`` result (e.g. from a warm-started call
        in a worker process); otherwise a cold call is made.

    Returns
    -------
    bound : float
    D, G : ndarray
        Diagonal scalings (``D`` in square-root form).
    x : ndarray or None
        AB13MD's internal state, for a warm start at the next frequency.

    Raises
    ------
    SolverError
        AB13MD reports an error.
    """
    n = Ms.shape[0]
    if not np.any(Ms):
        return 0.0, np.eye(n), np.zeros((n, n)), None
    if result is None:
        from slycot.exceptions import SlycotError

        nblock, itype = st.ab13md_args
        try:
            result = ab13md_call(Ms, nblock, itype)
        except SlycotError as exc:
            raise SolverError(f"SLICOT AB13MD failed: {exc}") from exc
    bound, d, g, x = result
    return float(bound), np.diag(np.asarray(d, float)), np.diag(np.asarray(g, float)), x


def certified_beta(Ms: np.ndarray, P: np.ndarray, G: np.ndarray) -> tuple[float, np.ndarray]:
    """Smallest beta certified by given (P = D^2, G): a generalized eigenvalue.

    Returns ``(beta, P)`` with ``P`` made safely definite.

    Re-deriving beta from the scalings makes the LMI bound exact whatever the
    accuracy of the SDP solver.
    """
    P = (P + P.conj().T) / 2
    A = Ms.conj().T @ P @ Ms + 1j * (G @ Ms - Ms.conj().T @ G)
    A = (A + A.conj().T) / 2
    # the pencil's eigenvalues do not change under a congruence (S A S, S P S): with a diagonal S that
    # equilibrates P, scalings of blocks many orders apart (the descent's reach e^30) are no longer taken for a
    # barely definite P, whose shift below changes the scalings (it turned a bound of 2.07 into 9.6 on ur5's
    # moving model with the instrument's exact LFT); S is constant on each scalar block, so the shift, a
    # diagonal in P's coordinates, stays in the commutant of Delta
    diag = np.diag(P).real
    if diag.max() <= 0:
        return np.inf, P
    s = 1.0 / np.sqrt(np.maximum(diag, 1e-9 * diag.max()))  # (any positive s is a congruence)
    Pe, Ae = s[:, None] * P * s[None, :], s[:, None] * A * s[None, :]
    ev = np.linalg.eigvalsh(Pe)
    if ev[-1] <= 0:
        return np.inf, P
    if ev[0] < 1e-9 * ev[-1]:
        # solver noise left P barely definite; the shift keeps it in the commutant and the certificate exact for it
        shift = (1e-9 * ev[-1] - ev[0]) * np.eye(P.shape[0])
        Pe = Pe + shift
        P = Pe / (s[:, None] * s[None, :])  # the same shift in P's own coordinates: still in the commutant
        A = Ms.conj().T @ P @ Ms + 1j * (G @ Ms - Ms.conj().T @ G)
        Ae = s[:, None] * ((A + A.conj().T) / 2) * s[None, :]
    try:
        lam = sla.eigh(Ae, Pe, eigvals_only=True)[-1]
    except np.linalg.LinAlgError:
        return np.inf, P
    return float(np.sqrt(max(lam, 0.0))), P


class LmiUpper:
    """D-G LMI upper bound by bisection on beta (cvxpy).

    One problem is compiled per matrix with ``beta**2`` as a DPP parameter,
    so the bisection steps only re-solve.  (A Schur form with M as a
    parameter too would compile once per sweep, but doubles the LMI size and
    was slower overall.)
    """

    def __init__(self, st: BlockStructure, solver: str | None = None, kappa: float = 1e6):
        self.st, self.solver, self.kappa = st, solver, kappa
        #: what went wrong in the bisection (solver fallbacks, failed steps);
        #: a failed step is treated as infeasible, which only loosens the bound
        self.events: list[str] = []

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
        import cvxpy as cp

        self.b2.value = b2
        with warnings.catch_warnings():
            # "inaccurate" answers are fine: certified_beta re-certifies them exactly
            warnings.simplefilter("ignore")
            try:
                self.prob.solve(solver=self.solver or "CLARABEL")
            except cp.error.SolverError as exc:  # interior point stalls near the boundary
                self.events.append(f"beta^2={b2:.6g}: {self.solver or 'CLARABEL'} failed ({exc}); SCS used")
                try:
                    self.prob.solve(solver="SCS", eps=1e-6, max_iters=5000)
                except cp.error.SolverError as exc2:
                    self.events.append(f"beta^2={b2:.6g}: SCS failed too ({exc2}); step taken as infeasible")
                    return None
        if self.prob.status not in ("optimal", "optimal_inaccurate"):
            if self.prob.status not in ("infeasible", "infeasible_inaccurate", "unbounded", "unbounded_inaccurate"):
                self.events.append(f"beta^2={b2:.6g}: solver status {self.prob.status}; step taken as infeasible")
            return None
        P = np.asarray(self.P.value, dtype=complex)
        n = P.shape[0]
        G = np.zeros((n, n), complex) if isinstance(self.G, int) else np.asarray(self.G.value, dtype=complex)
        return (P + P.conj().T) / 2, (G + G.conj().T) / 2

    def __call__(self, Ms: np.ndarray, lo: float = 0.0, rtol: float = 1e-4):
        n = Ms.shape[0]
        best = (float(np.linalg.norm(Ms, 2)), np.eye(n, dtype=complex), np.zeros((n, n), complex))
        bp, Dp = perron_upper(Ms, self.st)
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
            beta, P = certified_beta(Ms, *sol)
            if beta < best[0]:
                best = (beta, P, sol[1])
            if self.t.value is not None and self.t.value <= 0:
                hi = max(min(mid, beta), lo)
            else:
                lo = mid
        beta, P, G = best
        D = sla.sqrtm(P)
        return beta, (D + D.conj().T) / 2, G


def worker_function():
    """What a worker process calls: slycot's own AB13MD, or the substitute a test put in :func:`ab13md_call`.

    slycot's function pickles by reference to slycot, so the worker never
    imports polyrob (and its heavy dependencies).
    """
    import slycot

    return slycot.ab13md if ab13md_call is AB13MD_DEFAULT else ab13md_call


class TimedAb13md:
    """Cold AB13MD calls with a wall-clock safety net against a hung call.

    The method is chosen by the structure (:func:`polyrob.analysis.mu.bounds.resolve_method`),
    never by the clock: whatever AB13MD takes, its value is the one returned.
    The limit only guards against a call that never returns.  A Fortran loop
    cannot be interrupted from Python, so on structures with real blocks (where
    AB13MD's iteration can take tens of seconds at one frequency) the calls run
    in a :class:`~polyrob.analysis.timelimit.TimeLimitedCall` worker; a call
    that exceeds ``timeout`` is killed and answered by the deterministic
    ``fallback`` instead (a strategy: :class:`LmiUpper` by default, or
    :class:`~polyrob.analysis.mu.gradient.GradientUpper` given by the caller;
    either is a true upper bound, but not AB13MD's figure), counted in :attr:`fallbacks` so the caller can report it.  The
    limit must therefore be far above any call that merely runs slowly on a
    busy machine.  Complex-only structures (a convex problem for AB13MD) are
    called in-process, without a limit.

    Parameters
    ----------
    st : BlockStructure
        Without repeated scalar blocks.
    timeout : float or None
        Wall-clock seconds per cold call; ``None`` or 0: no limit (in-process).
    solver : str, optional
        cvxpy solver of the LMI fallback.
    rtol : float
        Bisection tolerance of the LMI fallback.
    fallback : callable ``Ms -> (bound, D, G, ...)``, optional
        What answers a call that exceeded the limit (default :class:`LmiUpper`).
    fallback_name : str
        The fallback in words, for the notes of a result.
    """

    def __init__(
        self,
        st: BlockStructure,
        timeout: float | None,
        solver: str | None = None,
        rtol: float = 1e-4,
        fallback=None,
        fallback_name: str = "D-G LMI",
    ):
        from polyrob.analysis.timelimit import TimeLimitedCall

        self.st, self.timeout, self.solver, self.rtol = st, timeout, solver, rtol
        self.fallback, self.fallback_name = fallback, fallback_name
        guarded = bool(timeout) and st.has_real
        self._call = TimeLimitedCall(worker_function(), float(timeout)) if guarded else None
        self._lmi = None
        #: how many calls exceeded the limit (answered by the fallback)
        self.fallbacks = 0

    @property
    def events(self) -> list[str]:
        """The fallback LMI's solver events (see :class:`LmiUpper`)."""
        return [] if self._lmi is None else list(self._lmi.events)

    def __call__(self, Ms: np.ndarray, lo: float = 0.0):
        """``(bound, D, G, x)`` as :func:`upper_ab13md` (``x`` is ``None`` after a fallback)."""
        if self._call is None or not np.any(Ms):
            return upper_ab13md(Ms, self.st)
        ok, value = self._call(Ms, *self.st.ab13md_args)
        if ok:
            return upper_ab13md(Ms, self.st, value)
        if not str(value).startswith("timeout"):  # AB13MD's own error, relayed by the worker
            raise SolverError(f"SLICOT AB13MD failed: {value}")
        self.fallbacks += 1
        if self.fallback is not None:
            bound, D, G = self.fallback(Ms)[:3]
            return bound, D, G, None
        if self._lmi is None:
            self._lmi = LmiUpper(self.st, self.solver)
        bound, D, G = self._lmi(Ms, lo=lo, rtol=self.rtol)
        return bound, D, G, None

    def close(self) -> None:
        """Stop the worker process, if any."""
        if self._call is not None:
            self._call.close()
