"""Controller order reduction with a μ certificate at every order tried.

:func:`reduce_controller` reduces a (full-order μ-synthesis) controller by
balanced truncation and returns the smallest order whose **certified** peak
μ (recomputed with :func:`polyrob.analysis.mu.bounds.mu_bounds` on the reduced closed loop,
peak-refined) stays below a target, plus the μ-order trade-off table.

Unstable controllers.  Balanced truncation needs a stable system, and H∞
controllers are often unstable (or have near-integrators).  The
stable/unstable decomposition of Hsu & Hou (1991), ``K = K_s + K_u``, is
what SLICOT AB09MD/AB09ND do inside ``control.balred(..., alpha=...)``:
the unstable part, including poles on or within ``1e-9`` (relative) of the
imaginary axis, is kept exactly; the stable part is reduced by square-root
balanced truncation, or by singular perturbation (``method="matchdc"``),
which keeps its DC gain: the low-frequency performance weights of robot
plants ask for a sensitivity of 1% below 0.005 rad/s, and a truncation
error there shows up directly in μ.  :func:`stable_unstable_split` gives
the same split explicitly (its stable part's Hankel singular values,
``control.hsvd``, are reported).

The order search bisects on the order (μ is nearly monotone in it) with a
certificate at each order visited; when the final order's certificate
misses the target the search moves up one order at a time.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg as sla

from polyrob._threads import single_blas_thread
from polyrob.analysis.certificate import certify_loop
from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.controller import as_controller_ss
from polyrob.errors import ArgumentError, SynthesisError
from polyrob.synthesis.dk.frequency import frequency_grid
from polyrob.synthesis.result import MusynResult

log = logging.getLogger("polyrob")

__all__ = ["ReductionResult", "reduce_controller", "stable_unstable_split", "balanced_reduction"]


@dataclass(frozen=True, eq=False)
class ReductionResult:
    """A reduced controller and the μ-order trade-off behind it.

    The reduced controller's own figures are its :attr:`result`'s
    (``controller``, ``order``, ``peak_mu``, ``peak_mu_lower``,
    ``certificate`` read them from there).

    Attributes
    ----------
    result : MusynResult
        The reduced controller as a :class:`MusynResult` (``structure="reduced:N"``).
    target : float
        The μ the order had to reach (default: full-order μ × (1 + tol)).
    meets_target : bool
        ``False`` when no order within ``max_order`` reached ``target``:
        ``controller`` is then the best one found within ``max_order``.
    full_order : int
    full_peak_mu : float
    table : list of dict
        ``{"order", "peak_mu", "stable", "method"}`` for every order tried,
        sorted by order.
    hankel : ndarray
        Hankel singular values of the stable part of the full controller.
    n_unstable : int
        Poles kept exactly (unstable or on the axis).
    method : str
    seconds : float
    """

    result: MusynResult
    target: float
    meets_target: bool
    full_order: int
    full_peak_mu: float
    table: list
    hankel: np.ndarray
    n_unstable: int
    method: str
    seconds: float = 0.0

    @property
    def controller(self) -> control.StateSpace:
        """The reduced controller (``order`` states)."""
        return self.result.controller

    @property
    def order(self) -> int:
        return self.result.order

    @property
    def peak_mu(self) -> float:
        """Certified peak μ of ``Fl(P, K_r)`` (``inf`` if the loop is unstable)."""
        return self.result.peak_mu

    @property
    def peak_mu_lower(self) -> float:
        return self.result.peak_mu_lower

    @property
    def certificate(self):
        """The reduced loop's :class:`~polyrob.analysis.certificate.Certificate`."""
        return self.result.certificate

    def summary(self) -> dict:
        """Plain figures for reports and JSON."""
        return {
            "order": int(self.order),
            "peak_mu_upper": float(self.peak_mu),
            "target": float(self.target),
            "meets_target": bool(self.meets_target),
            "full_order": int(self.full_order),
            "full_peak_mu": float(self.full_peak_mu),
            "table": [
                {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in row.items()}
                for row in self.table
            ],
            "seconds": round(float(self.seconds), 3),
        }


# ============================================================ decomposition
def stable_unstable_split(K: control.StateSpace, margin: float = 1e-9):
    """``K = K_s + K_u`` with ``K_s`` strictly stable (poles ``Re < -margin |λ|``).

    Returns ``(Ks, Ku)``; ``Ku`` is strictly proper and carries every pole
    on or right of the margin, ``Ks`` the feedthrough.

    Examples
    --------
    >>> import control, numpy as np
    >>> from polyrob.synthesis.reduction import stable_unstable_split
    >>> K = control.ss(control.tf([1, 3], [1, 1, -2]))       # poles 1 and -2
    >>> Ks, Ku = stable_unstable_split(K)
    >>> Ks.nstates, Ku.nstates, float(np.real(Ku.poles()[0]))
    (1, 1, 1.0)
    """
    A, B, C, D = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
    n = A.shape[0]
    if n == 0:
        return K, control.ss(np.zeros((0, 0)), np.zeros((0, B.shape[1])), np.zeros((C.shape[0], 0)), np.zeros_like(D))

    def is_stable(re, im):
        return re < -margin * max(1.0, abs(complex(re, im)))

    T, Z, k = sla.schur(A, output="real", sort=is_stable)
    Bt, Ct = Z.T @ B, C @ Z
    if k < n:
        T11, T12, T22 = T[:k, :k], T[:k, k:], T[k:, k:]
        X = sla.solve_sylvester(T11, -T22, -T12) if k > 0 else np.zeros((0, n - k))
        # x = [I X; 0 I] x' block-diagonalises T
        Bs = Bt[:k] - X @ Bt[k:]
        Bu = Bt[k:]
        Cs = Ct[:, :k]
        Cu = Ct[:, :k] @ X + Ct[:, k:]
    else:
        T11, T22 = T, np.zeros((0, 0))
        Bs, Bu, Cs, Cu = Bt, Bt[:0], Ct, Ct[:, :0]
    Ks = (
        control.ss(T11, Bs, Cs, D)
        if k
        else control.ss(np.zeros((0, 0)), np.zeros((0, B.shape[1])), np.zeros((C.shape[0], 0)), D)
    )
    Ku = (
        control.ss(T22, Bu, Cu, np.zeros_like(D))
        if k < n
        else control.ss(np.zeros((0, 0)), np.zeros((0, B.shape[1])), np.zeros((C.shape[0], 0)), np.zeros_like(D))
    )
    return Ks, Ku


def balanced_reduction(
    K: control.StateSpace, order: int, method: str = "truncate", margin: float = 1e-9
) -> control.StateSpace:
    """Reduce ``K`` to ``order`` states: unstable part kept, stable part balanced-truncated.

    ``control.balred`` with ``alpha = -margin max(1, ρ(A))``: SLICOT AB09MD
    (truncation) or AB09ND (singular perturbation, ``"matchdc"``) keep the
    modes right of ``alpha`` (unstable, on or within the margin of the axis)
    exactly and reduce the rest.

    Examples
    --------
    >>> import control
    >>> from polyrob.synthesis.reduction import balanced_reduction
    >>> K = control.ss(control.tf([1, 10], [1, 11, 10]) * control.tf([1], [1, 1000]))
    >>> balanced_reduction(K, 2).nstates
    2
    """
    if method not in ("truncate", "matchdc"):
        raise ArgumentError(f"method must be 'truncate' or 'matchdc', got {method!r}")
    A = np.asarray(K.A, float)
    if K.nstates == 0 or order >= K.nstates:
        return K
    lam = np.linalg.eigvals(A)
    alpha = -margin * max(1.0, float(np.max(np.abs(lam))))
    nu = int(np.sum(lam.real >= alpha))
    if order < nu:
        raise ArgumentError(f"cannot reduce below the {nu} unstable/marginal poles of the controller")
    Kc = control.ss(A, np.asarray(K.B, float), np.asarray(K.C, float), np.asarray(K.D, float))
    if nu == 0 and method == "truncate" and order > 0:
        return control.balred(Kc, order, method="truncate")  # AB09AD (alpha is for AB09MD only)
    return control.balred(Kc, order, method=method, alpha=alpha)


# ================================================================ search
def reduce_controller(
    P,
    result_or_K,
    blk=None,
    *,
    target: float | None = None,
    max_order: int | None = None,
    tol: float = 0.05,
    method: str = "matchdc",
    omega=None,
    n_u: int | None = None,
    n_y: int | None = None,
) -> ReductionResult:
    """Smallest balanced-truncation order whose certified μ stays below ``target``.

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
    result_or_K : MusynResult or LTI
        The full-order controller (its certified μ is reused from a
        :class:`MusynResult`, else computed).
    blk : array_like, optional
        Default: the result's certificate structure or ``P.block_structure_rp``.
    target : float, optional
        Default: full-order μ × ``(1 + tol)``.
    max_order : int, optional
        Largest order accepted (e.g. 20); default the full order.
    tol : float
        Relative μ degradation allowed when ``target`` is not given.
    method : {"matchdc", "truncate"}
        Singular perturbation (DC gain kept) or plain truncation of the
        balanced stable part.
    omega : array_like, optional
        Certificate grid (default: the full-order result's D-step range
        widened by a decade each side, 8 points per decade; every
        certificate adds the closed loop's resonances and refines its peak).
    n_u, n_y : int, optional
        Controls and measurements of a bare ``StateSpace`` plant (its last inputs and outputs).

    Returns
    -------
    ReductionResult

    Raises
    ------
    SynthesisError
        If the full-order controller does not stabilise the plant.

    Examples
    --------
    >>> import control, numpy as np
    >>> from polyrob.synthesis import musyn, reduce_controller
    >>> G = control.ss(control.tf([1], [1, 1]))
    >>> A, B, C = G.A, G.B, G.C
    >>> P = control.ss(A, np.hstack([B, 0 * B, B]), np.vstack([0 * C, -0.5 * C, -C]),
    ...                [[0, 0, 0.5], [0, 0.5, 0], [0, 1, 0]])
    >>> res = musyn(P, [[1, 1], [1, 1]], n_u=1, n_y=1, max_iter=3, progress=False)
    >>> red = reduce_controller(P, res, [[1, 1], [1, 1]], n_u=1, n_y=1)
    >>> red.order <= res.order, red.meets_target
    (True, True)
    """

    t0 = time.perf_counter()
    if isinstance(result_or_K, MusynResult):
        K = result_or_K.controller_value  # built once on the result; as_controller_ss below takes it as it is
        full_mu = float(result_or_K.peak_mu)
        if blk is None and result_or_K.certificate is not None:
            blk = result_or_K.certificate.mu.structure
        if omega is None and "omega" in result_or_K.info:
            w = np.asarray(result_or_K.info["omega"], float)
            omega = np.logspace(np.log10(w.min()) - 1, np.log10(w.max()) + 1, int(8 * np.log10(w.max() / w.min())) + 17)
    else:
        K = result_or_K
        full_mu = None
    if blk is None:
        blk = getattr(P, "block_structure_rp", None)
        if blk is None:
            raise ArgumentError("reduce_controller needs blk for a bare StateSpace plant")
    st = as_block_structure(blk)
    kw = {} if not isinstance(P, control.StateSpace) else {"n_u": n_u, "n_y": n_y}
    if isinstance(P, control.StateSpace) and (n_u is None or n_y is None):
        raise ArgumentError("reduce_controller of a bare StateSpace plant needs n_u and n_y")
    K = as_controller_ss(K, P.n_u if n_u is None else n_u, P.n_y if n_y is None else n_y)
    if omega is None:
        base = frequency_grid(P.system if hasattr(P, "system") else P)
        omega = np.logspace(
            np.log10(base.min()) - 1, np.log10(base.max()) + 1, int(8 * np.log10(base.max() / base.min())) + 17
        )
    cache = {}

    def evaluate(order, Kr=None):
        if order in cache:
            return cache[order]
        if Kr is None:
            Kr = balanced_reduction(K, order, method)
        t = time.perf_counter()
        cert = certify_loop(P, Kr, st, omega, sweep_unstable=False, **kw)
        cache[order] = (cert.mu_upper_grid, cert.mu_lower, cert, Kr)
        log.info(
            f"reduction: order {order}: peak mu {cert.mu_upper_grid:.4g} ({cert.status.value}), "
            f"{time.perf_counter() - t:.1f} s"
        )
        return cache[order]

    with single_blas_thread():
        n = K.nstates
        if full_mu is None:
            full_mu = evaluate(n, K)[0]
        if not np.isfinite(full_mu):
            raise SynthesisError("the full-order controller does not stabilise the plant: nothing to reduce")
        tgt = float(target) if target is not None else full_mu * (1 + tol)
        Ks, Ku = stable_unstable_split(K)
        hsv = np.real(np.asarray(control.hsvd(Ks))) if Ks.nstates else np.zeros(0)
        nu = Ku.nstates
        cap = n if max_order is None else int(min(max_order, n))
        if cap < nu:
            raise SynthesisError(
                f"max_order={cap} is below the {nu} unstable/marginal poles of the controller, which "
                "balanced truncation must keep"
            )
        # bisection on the order for the smallest one meeting the target
        lo, hi = nu, cap
        ok_hi = evaluate(hi, K if hi == n else None)[0] <= tgt
        if ok_hi:
            while hi - lo > 0:
                mid = (lo + hi) // 2
                if evaluate(mid)[0] <= tgt:
                    hi = mid
                else:
                    lo = mid + 1
            chosen = hi
        else:
            finite = {o: v for o, v in cache.items() if o <= cap}
            chosen = min(finite, key=lambda o: finite[o][0])
        mu, mlo, cert, Kr = cache[chosen]
    table = [
        {"order": int(o), "peak_mu": float(v[0]), "stable": bool(np.isfinite(v[0])), "method": method}
        for o, v in sorted(cache.items())
    ]
    meets = bool(mu <= tgt)
    mres = MusynResult.certified(
        Kr,
        f"reduced:{chosen}",
        cert,
        mu_history=[mu],
        seconds=time.perf_counter() - t0,
        info={"reduction": method, "full_order": n, "full_peak_mu": full_mu, "table": table},
    )
    return ReductionResult(
        mres, tgt, meets, int(n), float(full_mu), table, hsv, int(nu), method, seconds=time.perf_counter() - t0
    )
