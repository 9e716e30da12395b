"""Structured singular value :math:`\\mu` for mixed real/complex uncertainty.

:func:`mussv` bounds :math:`\\mu_\\Delta(M)` of one complex matrix, like MATLAB's
``mussv``; :func:`mu_bounds` sweeps it over frequency for a python-control
model.  Every bound comes with its certificate:

* the **upper bound** :math:`\\beta` with scalings :math:`D \\succ 0` (commuting
  with :math:`\\Delta`) and :math:`G = G^H` (non-zero on real blocks only) such
  that :math:`M^H D^2 M + j(GM - M^H G) - \\beta^2 D^2 \\preceq 0`
  (Fan, Tits & Doyle 1991), on the padded square problem of
  :mod:`polyrob.analysis.mu.blocks`;
* the **lower bound** :math:`\\ell` with a perturbation :math:`\\Delta` in the
  structure, :math:`\\bar\\sigma(\\Delta) = 1/\\ell` and
  :math:`\\det(I - M\\Delta) = 0`.

What is written by hand here and why: no Python library computes mixed
:math:`\\mu`.  SLICOT AB13MD (through ``slycot``) gives the upper bound for real
scalars + full complex blocks and is used whenever it applies; repeated
scalar blocks need the D-G LMI (solved with cvxpy) or, on large structures,
descent on the same scalings (:mod:`polyrob.analysis.mu.gradient`); the lower
bound (power iteration + a local search) exists in no library at all.

What the sweep's figures are: :func:`mu_bounds` evaluates the bounds at the
points of a frequency grid (plus a local refinement around the largest
maxima).  Its ``peak_upper`` is therefore the **peak μ upper bound on the
grid**: an upper bound of μ at each grid point, and an estimate from below of
:math:`\\sup_\\omega \\mu` (a narrow peak between two points can be missed).
:attr:`MuBoundsResult.covers` states this in words; ``docs/mu.md`` says what
is and is not covered.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from polyrob._threads import single_blas_thread
from polyrob.analysis.mu import upper as mu_upper
from polyrob.analysis.mu.blocks import BlkLike, BlockStructure, as_block_structure
from polyrob.analysis.mu.frequency import default_grid
from polyrob.analysis.mu.gradient import GradientUpper
from polyrob.analysis.mu.lower import lower_bound
from polyrob.analysis.mu.results import MuBoundsResult, MussvResult
from polyrob.analysis.mu.sweep import (
    AB13MD_SAFETY_TIMEOUT,
    MANY_REAL_SCALARS,
    relaxation_note,
    run_sweep,
)
from polyrob.analysis.mu.upper import LmiUpper
from polyrob.errors import ArgumentError

__all__ = [
    "MussvResult",
    "MuBoundsResult",
    "mussv",
    "mu_bounds",
    "resolve_method",
]

Method = Literal["auto", "ab13md", "lmi", "gradient", "relaxed"]


# ================================================================ mussv
def resolve_method(st: BlockStructure, method: str) -> str:
    """The upper-bound method ``method`` stands for on ``st`` (``"auto"`` resolved; checked).

    The choice depends on the structure alone, never on the matrix, the
    machine or the clock, so the same sweep gives the same figures anywhere:
    ``"auto"`` is AB13MD when the structure has no repeated scalar block
    (real scalars and full complex blocks, AB13MD's domain) and at most
    :data:`MANY_REAL_SCALARS` real scalars, else descent on the D-G scalings
    (full scalings on repeated blocks, re-checked exactly).  The D-G LMI
    (``"lmi"``) reaches the same bound on small structures at many times the
    cost (``benchmarks/mu.py --choice`` times both on finger_edu's
    computed-torque loop, a repeated real block of 3), so it is asked for by name only.
    """
    if method == "auto":
        if not st.has_repeated:
            many = sum(b.kind == "real" for b in st.blocks) > MANY_REAL_SCALARS
            return "gradient" if many else "ab13md"
        return "gradient"
    if method not in ("ab13md", "lmi", "gradient", "relaxed"):
        raise ArgumentError(f"method must be 'auto', 'ab13md', 'lmi', 'gradient' or 'relaxed', got {method!r}")
    if method == "ab13md" and st.has_repeated:
        raise ArgumentError("AB13MD cannot handle repeated scalar blocks; use method='lmi', 'gradient' or 'relaxed'")
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
    solver: str | None = None,
) -> MussvResult:
    """Bounds on the structured singular value of a complex matrix.

    Parameters
    ----------
    M : (nc, nr) array_like
        Matrix closing the loop with :math:`\\Delta` (``nr x nc``).
    blk : BlockStructure or array_like
        MATLAB ``blk`` encoding, see :mod:`polyrob.analysis.mu.blocks`.
    method : {"auto", "ab13md", "lmi", "gradient", "relaxed"}
        Upper bound: SLICOT AB13MD (real scalars, full complex blocks), the
        D-G LMI solved by bisection with cvxpy (also repeated scalars), the
        same scalings found by descent (:class:`~polyrob.analysis.mu.gradient.GradientUpper`,
        fast on large repeated structures, re-certified exactly) or AB13MD on
        a superset structure (``"relaxed"``).  ``"auto"``: :func:`resolve_method`.
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
    >>> from polyrob.analysis.mu.bounds import mussv
    >>> M = np.array([[2.0, 2.0], [-1.0, -1.0]])
    >>> r = mussv(M, [[1, 0], [1, 0]])
    >>> print(f"{r.lower:.4f} <= mu <= {r.upper:.4f}")
    3.0000 <= mu <= 3.0000
    >>> bool(abs(np.linalg.det(np.eye(2) - M @ r.delta)) < 1e-9)
    True
    """
    st = as_block_structure(blk)
    M = st.check_m(M)
    meth = resolve_method(st, method)
    with single_blas_thread():
        return _mussv(M, st, meth, lower, refine, starts, seed, rtol, solver)


def _mussv(M, st, meth, lower, refine, starts, seed, rtol, solver) -> MussvResult:
    Ms = st.pad(M)
    n = Ms.shape[0]
    lo, dsq, notes = 0.0, np.zeros((n, n), complex), ()
    if meth in ("ab13md", "relaxed"):
        up, D, G, _ = mu_upper.upper_ab13md(Ms, st.relaxed())
        notes = (relaxation_note(st),) if meth == "relaxed" else ()
    elif meth == "gradient":
        up, D, G, _ = GradientUpper(st)(Ms)
    else:
        # a verified lower bound narrows the bisection bracket for free
        lo, dsq, _ = lower_bound(Ms, st, starts=1, refine=False, seed=seed)
        lmi = LmiUpper(st, solver)
        up, D, G = lmi(Ms, lo=lo * (1 - 1e-9), rtol=rtol)
        notes = tuple(lmi.events)
    if lower:
        lo2, dsq2, _ = lower_bound(Ms, st, starts=starts, refine=refine, seed=seed, target=up, D=D)
        if lo2 >= lo:
            lo, dsq = lo2, dsq2
    else:
        lo, dsq = 0.0, np.zeros((n, n), complex)
    # Rounding can leave the certified upper bound a hair below a verified
    # lower bound when both are tight; they bound the same number.
    up = max(up, lo)
    Dl, Dr = st.restrict_scaling(D)
    return MussvResult(float(up), float(lo), st.unpad_delta(dsq), D, G, Dl, Dr, st, meth, notes)


# ============================================================ frequency
def mu_bounds(
    sys,
    blk: BlkLike,
    omega: np.ndarray | None = None,
    *,
    method: Method = "auto",
    refine_peak: bool = True,
    warm_start: bool = False,
    warm_timeout: float = AB13MD_SAFETY_TIMEOUT,
    ab13md_timeout: float | None = AB13MD_SAFETY_TIMEOUT,
    progress: bool | None = None,
    rtol: float = 1e-4,
    solver: str | None = None,
    response_bits: int | None = None,
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
    method : {"auto", "ab13md", "lmi", "gradient", "relaxed"}
        Upper-bound method, see :func:`mussv`; ``"gradient"`` warm-starts
        each frequency from the previous one's scalings.  ``"auto"`` is
        resolved from the structure alone (:func:`resolve_method`), and the
        method it names computes every frequency, however long it takes.
    refine_peak : bool
        Golden-section search of the upper-bound peak between the grid points
        around the best local maxima, so a sharp resonance is not missed.
    warm_start : bool
        Warm-start AB13MD from the previous frequency.  Such calls run in a
        worker process killed after ``warm_timeout`` s of wall clock (AB13MD
        warm starts can hang; default :data:`AB13MD_SAFETY_TIMEOUT`); then
        the sweep falls back to cold calls, said in the result's notes.
    ab13md_timeout : float or None
        Safety net against a hung cold AB13MD call on a structure with real
        blocks: wall-clock seconds after which the call is killed and that
        frequency's upper bound comes from the D-G LMI (descent on the D-G
        scalings above :data:`DESCENT_ABOVE` padded channels) instead, said
        in the result's notes, since such figures depend on the machine.
        The default, :data:`AB13MD_SAFETY_TIMEOUT`, is far above the slowest
        call measured, so a slow AB13MD (or a busy machine) still gives
        AB13MD's value; a small limit trades that for speed.  ``None``: no
        limit (calls run in-process).  On structures above
        :data:`DESCENT_ABOVE` padded channels the limit is at least
        :data:`LARGE_AB13MD_TIMEOUT`.
    progress : bool, optional
        tqdm progress bar; default: shown on a terminal for long sweeps.
    rtol, solver
        LMI method options, see :func:`mussv`.
    response_bits : int, optional
        Evaluate the frequency response of a state-space ``sys`` in this
        extended precision (python-flint) instead of double: for badly
        conditioned realisations, see
        :func:`polyrob.analysis.mu.frequency.response_error`.

    Returns
    -------
    MuBoundsResult

    Examples
    --------
    >>> import control
    >>> from polyrob.analysis.mu.bounds import mu_bounds
    >>> G = control.tf([1], [1, 0.2, 1])          # |G| peaks at 1/(2 zeta sqrt(1-zeta^2))
    >>> r = mu_bounds(G, [[1, 1]])
    >>> print(f"{r.peak_upper:.4f} {r.peak_lower:.4f} {r.peak_upper_frequency:.4f}")
    5.0252 5.0252 0.9899
    """
    import control

    st = as_block_structure(blk)
    if not isinstance(sys, control.LTI):
        raise ArgumentError(f"mu_bounds needs a python-control LTI system, got {type(sys).__name__}")
    if (sys.noutputs, sys.ninputs) != st.m_shape:
        raise ArgumentError(f"system is {sys.noutputs}x{sys.ninputs} but block structure {st} needs {st.m_shape}")
    is_frd = isinstance(sys, control.FrequencyResponseData)
    if omega is None:
        omega = np.asarray(sys.omega if is_frd else default_grid(sys), dtype=float)
    omega = np.unique(np.asarray(omega, dtype=float).ravel())
    # near-duplicates (a pole frequency next to a grid point) would make a
    # degenerate bracket for the peak refinement
    omega = omega[np.r_[True, np.diff(omega) > 1e-9 * np.abs(omega[1:])]] if omega.size else omega
    if omega.size == 0 or np.any(omega < 0) or not np.all(np.isfinite(omega)):
        raise ArgumentError("omega must be a non-empty array of finite non-negative frequencies")
    meth = resolve_method(st, method)
    with single_blas_thread():
        return run_sweep(
            sys,
            st,
            omega,
            is_frd,
            meth,
            refine_peak,
            warm_start,
            warm_timeout,
            progress,
            rtol,
            solver,
            response_bits,
            ab13md_timeout,
        )
