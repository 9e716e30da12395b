"""Structured singular value :math:`\\mu` for mixed real/complex uncertainty.

:func:`mussv` bounds :math:`\\mu_\\Delta(M)` of one complex matrix, like MATLAB's
``mussv``; :func:`mu_bounds` sweeps it over frequency for a python-control
model.  Every bound comes with its certificate:

* the **upper bound** :math:`\\beta` with scalings :math:`D \\succ 0` (commuting
  with :math:`\\Delta`) and :math:`G = G^H` (non-zero on real blocks only) such
  that :math:`M^H D^2 M + j(GM - M^H G) - \\beta^2 D^2 \\preceq 0`
  (Fan, Tits & Doyle 1991), on the padded square problem of
  :mod:`polyrob.analysis.blocks`;
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

import warnings
from dataclasses import dataclass
from typing import Literal, Optional

import numpy as np
import scipy.linalg as sla

from polyrob._threads import single_blas_thread
from polyrob.analysis.blocks import BlkLike, BlockStructure, _perron_upper, as_block_structure
from polyrob.errors import PolyrobError, SolverError
from polyrob.analysis._timelimit import TimeLimitedCall
from polyrob.analysis.mu_lower import _lower_bound

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
        MATLAB ``blk`` encoding, see :mod:`polyrob.analysis.blocks`.
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
    >>> from polyrob.analysis.mu import mussv
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
    >>> from polyrob.analysis.mu import mu_bounds
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
            H = np.concatenate([H, Hn])
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
            lo_i, d_i = lower_at(H[i], refine=True, target=up[i], D=Ds[i])
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


# Public name for the D-scale fit of the synthesis stage.
upper_bound_ab13md = _upper_ab13md
