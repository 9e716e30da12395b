"""Stability verdicts that state their margin and survive badly conditioned realisations.

A controller made by another tool can arrive in a realisation whose closed
loop has ``||A|| ~ 1e10`` and eigenvalue condition numbers ``~ 1e9`` (dkpy's
D-K controller for the distillation column): double-precision eigenvalues
then show a spurious pole at ``+0.018`` while the loop is stable (largest real
part ``-1e-6``).  :func:`stability_verdict` therefore never reads the sign of
a double-precision eigenvalue alone:

1. the state matrix is **balanced** (LAPACK ``gebal`` through
   :func:`scipy.linalg.matrix_balance`: a diagonal similarity by powers of 2,
   so no rounding); the transform's condition is recorded;
2. **eigenvalues in double precision with an error bound**: each
   eigenvalue moves by at most ``kappa_i * n * eps * ||A||_F`` (first order,
   ``kappa_i = 1/|y_i^H x_i|`` for unit left/right eigenvectors: the
   backward error of the QR algorithm times the eigenvalue condition);
3. **a second test, the Lyapunov inertia theorem**: ``A^T X + X A = -I`` is
   solved, the residual is bounded including the rounding of its own
   evaluation, and when ``A^T X + X A`` is proved negative definite the
   inertia of ``X`` decides (``X > 0``: stable; an eigenvalue ``< 0``: an
   eigenvalue of ``A`` in the open right half-plane);
4. unless the Lyapunov test decides (and the eigenvalues do not contradict
   it): the eigenvalues of the same
   (exactly represented) matrix in **extended precision** (python-flint,
   212 bits by default) with the bound ``kappa_i * eta_i`` (``eta_i`` the
   eigenpair's residual, a backward error) plus the effect of relative
   perturbations of ``4 eps`` in every entry (the rounding with which the
   realisation itself was formed), through the componentwise condition
   ``|y_i|^T |A| |x_i| / |y_i^H x_i|``.

The verdict is ``"stable"``, ``"unstable"`` or ``"undecided at double
precision"`` (the margin is inside the error bound at every stage); the
bounds of stages 2 and 4 are first-order estimates, stage 3 is a proof up
to the accounted rounding.

A *minimal* realisation is deliberately not taken: ``control.minreal`` on
dkpy's controller removes 10 of 22 states and changes its frequency response
by a factor 45, i.e. the truncation is itself ill-conditioned there.  States
are never dropped; hidden modes count for internal stability anyway.  The
balancing is used for the eigenvalues only: for frequency responses it made
that controller's double-precision response wrong by a factor 500 (see
:func:`polyrob.analysis.mu.frequency.response_error`, which :mod:`robust
<polyrob.analysis.robust>` uses to switch to extended precision instead).

:func:`stability_screen` is *not* a verdict: the sign of double-precision
eigenvalues, for the inner loops of the synthesis (a γ bisection, a D-K
step, a norm estimate) where a candidate is screened thousands of times and
whatever is kept is later decided by :func:`stability_verdict`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

__all__ = ["StabilityVerdict", "stability_verdict", "stability_screen", "STABLE", "UNSTABLE", "UNDECIDED"]

STABLE, UNSTABLE, UNDECIDED = "stable", "unstable", "undecided at double precision"
_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class StabilityVerdict:
    """Continuous-time stability of a state matrix, with its margin.

    Attributes
    ----------
    verdict : {"stable", "unstable", "undecided at double precision"}
    abscissa : float
        Largest real part of an eigenvalue (of the stage that decided).
    error_bound : float
        Bound on the error of ``abscissa`` (first order; ``inf`` if unknown).
    n_states : int
    transform_condition : float
        Condition of the balancing similarity (ratio of its largest to its
        smallest diagonal scale, powers of 2).
    precision_bits : int
        53 when double precision decided, else the extended precision used.
    tests : tuple of str
        Each test run and its outcome, in order.
    """

    verdict: str
    abscissa: float
    error_bound: float
    n_states: int
    transform_condition: float
    precision_bits: int
    tests: tuple

    @property
    def stable(self) -> bool:
        """Proved stable (``verdict == "stable"``)."""
        return self.verdict == STABLE

    @property
    def unstable(self) -> bool:
        """Proved unstable."""
        return self.verdict == UNSTABLE

    def __str__(self) -> str:
        return (
            f"{self.verdict}: largest real part {self.abscissa:.6g} +- {self.error_bound:.3g} "
            f"({self.n_states} states, {self.precision_bits}-bit, balancing condition "
            f"{self.transform_condition:.3g})"
        )

    def summary(self) -> dict:
        """Plain-JSON form."""
        return {
            "verdict": self.verdict,
            "abscissa": float(self.abscissa),
            "error_bound": float(self.error_bound),
            "n_states": int(self.n_states),
            "transform_condition": float(self.transform_condition),
            "precision_bits": int(self.precision_bits),
            "tests": list(self.tests),
        }


def stability_screen(A, margin: float = 1e-9) -> bool:
    """A screen, not a verdict: every double-precision eigenvalue has ``Re λ < -margin max(1, |λ|)``.

    The one cheap test of the synthesis' inner loops (an empty ``A`` passes, a
    non-finite one fails).  It can be wrong for a badly conditioned matrix;
    what is reported or certified is decided by :func:`stability_verdict`.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.analysis.stability import stability_screen
    >>> stability_screen(np.diag([-1.0, -2.0])), stability_screen(np.diag([-1.0, 1e-3]))
    (True, False)
    """
    A = np.asarray(A, float)
    if A.size == 0:
        return True
    if not np.all(np.isfinite(A)):
        return False
    ev = np.linalg.eigvals(A)
    return bool(np.all(ev.real < -margin * np.maximum(1.0, np.abs(ev))))


#: Precision of the first extended-precision attempt (double-double).
DOUBLE_DOUBLE_BITS = 106


def _decide(re, err):
    up, lo = float(np.max(re + err)), float(np.max(re - err))
    return (STABLE if up < 0 else UNSTABLE if lo > 0 else UNDECIDED), float(
        np.max(err[np.argmax(re)]) if re.size else 0.0
    )


def _eig_double(A):
    n = A.shape[0]
    lam, VL, VR = sla.eig(A, left=True, right=True)
    yx = np.abs(np.sum(VL.conj() * VR, axis=0))
    with np.errstate(divide="ignore"):
        kappa = np.where(yx > 0, 1.0 / yx, np.inf)
    err = kappa * n * _EPS * np.linalg.norm(A, "fro")
    verdict, _ = _decide(lam.real, err)
    i = int(np.argmax(lam.real))
    return verdict, float(lam.real[i]), float(err[i]), float(np.max(err))


def _lyapunov(A):
    """Inertia test with ``A^T X + X A = -I``; returns (verdict, description)."""
    n = A.shape[0]
    import warnings

    try:
        with warnings.catch_warnings():
            # near-singular Sylvester operator: scipy perturbs and warns; the
            # residual check below decides whether the solution is any good
            warnings.simplefilter("ignore", RuntimeWarning)
            X = sla.solve_continuous_lyapunov(A.T, -np.eye(n))
    except (np.linalg.LinAlgError, ValueError) as exc:  # eigenvalues symmetric about the axis
        return UNDECIDED, f"Lyapunov: no solution ({exc})"
    if not np.all(np.isfinite(X)):
        return UNDECIDED, "Lyapunov: non-finite solution"
    X = (X + X.T) / 2
    R = A.T @ X + X @ A + np.eye(n)
    R = (R + R.T) / 2
    # rounding of the residual's own evaluation (Higham, gamma_n bounds)
    gam = 2 * n * _EPS * (2 * np.linalg.norm(A, "fro") * np.linalg.norm(X, "fro") + 1)
    res = float(np.linalg.norm(R, 2)) + gam
    if res >= 0.5:
        return UNDECIDED, f"Lyapunov: residual {res:.3g} too large to prove A^T X + X A < 0"
    ev = np.linalg.eigvalsh(X)
    tol = 2 * n * _EPS * float(np.max(np.abs(ev)))
    if ev[0] > tol:
        return STABLE, f"Lyapunov: X > 0 (min eig {ev[0]:.3g}, residual {res:.2g})"
    if ev[0] < -tol:
        return UNSTABLE, f"Lyapunov: X has a negative eigenvalue {ev[0]:.3g} (residual {res:.2g})"
    return UNDECIDED, f"Lyapunov: smallest eigenvalue of X {ev[0]:.3g} within rounding"


def _eig_extended(A, bits):
    """Eigenvalues at ``bits`` precision with residual and data-perturbation bounds."""
    import flint

    n = A.shape[0]
    old = flint.ctx.prec
    flint.ctx.prec = bits
    try:
        M = flint.acb_mat([[flint.acb(float(x)) for x in row] for row in A])
        E, L, R = M.eig(left=True, right=True, algorithm="approx")
        Res = M * R - R * flint.acb_mat([[E[i] if i == j else 0 for j in range(n)] for i in range(n)])
        lam = np.array([complex(e) for e in E])
        Lc = np.array([[complex(L[i, j]) for j in range(n)] for i in range(n)])
        Rc = np.array([[complex(R[i, j]) for j in range(n)] for i in range(n)])
        res = np.array([max(float(abs(Res[i, j]).upper()) for i in range(n)) for j in range(n)]) * np.sqrt(n)
    finally:
        flint.ctx.prec = old
    yx = np.abs(np.einsum("ij,ji->i", Lc, Rc))
    nl, nr = np.linalg.norm(Lc, axis=1), np.linalg.norm(Rc, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa_n = np.where(yx > 0, nl * nr / yx, np.inf)
        kappa_c = np.where(yx > 0, (np.abs(Lc) @ np.abs(A) * np.abs(Rc).T).sum(axis=1) / yx, np.inf)
        eta = res / np.maximum(nr, 1e-300)  # backward error of each eigenpair
        # slack for the conversion of the high-precision eigenvectors to double
        err = kappa_n * (eta + 8 * n * _EPS * _EPS * np.linalg.norm(A, "fro")) + kappa_c * 4 * _EPS
    err = np.where(np.isfinite(err), err, np.inf)
    verdict, _ = _decide(lam.real, err)
    i = int(np.argmax(lam.real))
    return verdict, float(lam.real[i]), float(err[i])


def stability_verdict(system, *, extended_bits: int = 212) -> StabilityVerdict:
    """Decide continuous-time stability of a state matrix or a state-space system.

    Parameters
    ----------
    system : control.StateSpace or (n, n) array_like
        A system (its ``A`` is used) or a state matrix.
    extended_bits : int
        Precision of the extended-precision stage (0 disables it).

    Returns
    -------
    StabilityVerdict

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.analysis.stability import stability_verdict
    >>> stability_verdict(np.array([[1e-3, 0.0], [0.0, -1.0]])).verdict
    'unstable'
    >>> stability_verdict(np.array([[-1.0, 1e8], [0.0, -2.0]])).verdict
    'stable'
    """
    A = np.array(getattr(system, "A", system), dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        from polyrob.errors import ArgumentError

        raise ArgumentError(f"stability needs a square state matrix, got shape {A.shape}")
    n = A.shape[0]
    if n == 0:
        return StabilityVerdict(STABLE, -np.inf, 0.0, 0, 1.0, 53, ("no states",))
    if not np.all(np.isfinite(A)):
        return StabilityVerdict(UNDECIDED, np.nan, np.inf, n, 1.0, 53, ("non-finite state matrix",))
    Ab, (scale, _) = sla.matrix_balance(A, permute=True, separate=True)
    cond = float(np.max(scale) / np.min(scale))
    v_eig, absc, err, _ = _eig_double(Ab)
    v_lyap, lyap_note = _lyapunov(Ab)
    tests = [f"double eigenvalues: {v_eig}, largest real part {absc:.6g} +- {err:.3g}", lyap_note]
    if v_lyap != UNDECIDED and v_eig in (v_lyap, UNDECIDED):
        # the Lyapunov test is a proof up to the rounding it accounts for
        return StabilityVerdict(v_lyap, absc, err, n, cond, 53, tuple(tests))
    if v_eig != UNDECIDED and v_lyap != UNDECIDED:
        tests.append("double-precision tests disagree")
    # an eigenvalue bound alone is first order: it needs a second opinion
    if extended_bits:
        # double-double precision first (about 4x cheaper); the full precision
        # only when it cannot decide
        for bits in sorted({min(DOUBLE_DOUBLE_BITS, int(extended_bits)), int(extended_bits)}):
            v_ext, absc_x, err_x = _eig_extended(Ab, bits)
            tests.append(f"{bits}-bit eigenvalues: {v_ext}, largest real part {absc_x:.6g} +- {err_x:.3g}")
            if v_ext != UNDECIDED:
                return StabilityVerdict(v_ext, absc_x, err_x, n, cond, bits, tuple(tests))
        return StabilityVerdict(UNDECIDED, absc_x, err_x, n, cond, int(extended_bits), tuple(tests))
    if v_eig != UNDECIDED and v_lyap == UNDECIDED:
        tests.append("no second test available: the double-precision eigenvalue bound decides alone")
        return StabilityVerdict(v_eig, absc, err, n, cond, 53, tuple(tests))
    return StabilityVerdict(UNDECIDED, absc, err, n, cond, 53, tuple(tests))
