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
from polyrob.analysis.mu.frequency import default_grid, freqresp, refine_peaks
from polyrob.analysis.mu.gradient import GradientUpper
from polyrob.analysis.mu.lower import lower_bound
from polyrob.analysis.mu.results import MuBoundsResult, MussvResult
from polyrob.analysis.mu.upper import LmiUpper
from polyrob.analysis.timelimit import TimeLimitedCall
from polyrob.errors import PolyrobError

__all__ = [
    "MussvResult",
    "MuBoundsResult",
    "mussv",
    "mu_bounds",
    "resolve_method",
    "TimeLimitedCall",
]

Method = Literal["auto", "ab13md", "lmi", "gradient", "relaxed"]


# ================================================================ mussv
#: ``method="auto"`` bounds repeated scalar blocks by descent on the D-G scalings above this padded
#: size: the D-G LMI of an 89-channel structure (ur5's axes model) takes minutes per frequency.
DESCENT_ABOVE = 24
#: Wall-clock seconds a cold AB13MD call of a sweep may take before it is taken for hung (default
#: of :func:`mu_bounds`' ``ab13md_timeout`` and ``warm_timeout``).  A safety net, not a choice of
#: method: it must never fire on a call that is merely slow or on a busy machine.  Slow calls do
#: happen on structures with real blocks: measured 49 s of CPU time for one cold call (eight real
#: scalars, the robust-stability loop of ``tests/fixtures/validate_planar_2r_K.json`` on the
#: ``paper_2r`` plant of ``tests/test_report.py``, at 10**3.2 rad/s).
AB13MD_SAFETY_TIMEOUT = 300.0
#: The least AB13MD safety limit on structures above :data:`DESCENT_ABOVE` padded channels
#: (measured: AB13MD on ur5's relaxed structure 26-37 s per frequency; on a random matrix against
#: a 114-channel structure 196 s on a busy machine).
LARGE_AB13MD_TIMEOUT = 1200.0


def resolve_method(st: BlockStructure, method: str) -> str:
    """The upper-bound method ``method`` stands for on ``st`` (``"auto"`` resolved; checked).

    The choice depends on the structure alone, never on the matrix, the
    machine or the clock, so the same sweep gives the same figures anywhere:
    ``"auto"`` is AB13MD when the structure has no repeated scalar block
    (real scalars and full complex blocks, AB13MD's domain), else the D-G LMI
    up to :data:`DESCENT_ABOVE` padded channels and descent on the D-G
    scalings above.
    """
    if method == "auto":
        if not st.has_repeated:
            return "ab13md"
        return "gradient" if st.padded_size > DESCENT_ABOVE else "lmi"
    if method not in ("ab13md", "lmi", "gradient", "relaxed"):
        raise PolyrobError(f"method must be 'auto', 'ab13md', 'lmi', 'gradient' or 'relaxed', got {method!r}")
    if method == "ab13md" and st.has_repeated:
        raise PolyrobError("AB13MD cannot handle repeated scalar blocks; use method='lmi', 'gradient' or 'relaxed'")
    return method


def _relaxation_note(st: BlockStructure) -> str:
    return (
        f"upper bound on the relaxed structure {st.relaxed()} (each repeated scalar as independent scalars or a "
        "full block, a superset: conservative, still an upper bound); lower bound on the structure itself"
    )


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
        a superset structure (``"relaxed"``).  ``"auto"`` picks AB13MD
        whenever it applies, else the LMI up to :data:`DESCENT_ABOVE`
        padded channels and the descent above.
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
        notes = (_relaxation_note(st),) if meth == "relaxed" else ()
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
        raise PolyrobError(f"mu_bounds needs a python-control LTI system, got {type(sys).__name__}")
    if (sys.noutputs, sys.ninputs) != st.m_shape:
        raise PolyrobError(f"system is {sys.noutputs}x{sys.ninputs} but block structure {st} needs {st.m_shape}")
    is_frd = isinstance(sys, control.FrequencyResponseData)
    if omega is None:
        omega = np.asarray(sys.omega if is_frd else default_grid(sys), dtype=float)
    omega = np.unique(np.asarray(omega, dtype=float).ravel())
    # near-duplicates (a pole frequency next to a grid point) would make a
    # degenerate bracket for the peak refinement
    omega = omega[np.r_[True, np.diff(omega) > 1e-9 * np.abs(omega[1:])]] if omega.size else omega
    if omega.size == 0 or np.any(omega < 0) or not np.all(np.isfinite(omega)):
        raise PolyrobError("omega must be a non-empty array of finite non-negative frequencies")
    meth = resolve_method(st, method)
    with single_blas_thread():
        return _sweep(
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


def _sweep(
    sys, st, omega, is_frd, meth, refine_peak, warm_start, warm_timeout, progress, rtol, solver, bits, cold_timeout
):
    from tqdm import tqdm

    # "relaxed": AB13MD on a superset structure (repeated scalars split); the lower bound stays on st
    st_up = st.relaxed()
    lmi = LmiUpper(st, solver) if meth == "lmi" else None
    descent = GradientUpper(st) if meth == "gradient" else None
    large = st.padded_size > DESCENT_ABOVE
    if cold_timeout and large:
        cold_timeout = max(cold_timeout, LARGE_AB13MD_TIMEOUT)
    cold = None
    if meth in ("ab13md", "relaxed"):
        # the safety net's fallback is fixed by the structure too: the LMI takes minutes on large ones
        cold = mu_upper.TimedAb13md(st_up, cold_timeout, solver, rtol, fallback="gradient" if large else "lmi")
    guard = None
    if warm_start and meth in ("ab13md", "relaxed"):
        guard = TimeLimitedCall(mu_upper.worker_function(), warm_timeout)
    fallbacks, notes = 0, ([_relaxation_note(st)] if meth == "relaxed" else [])
    state = {"x": None, "pi": None, "xg": None}
    n = st.padded_size

    def upper_at(Ms, lo=0.0):
        nonlocal fallbacks, guard
        if not np.all(np.isfinite(Ms)):  # on a pole of M: mu is infinite
            return np.inf, np.eye(n), np.zeros((n, n))
        if lmi is not None:
            return lmi(Ms, lo=lo, rtol=rtol)
        if descent is not None:
            up, D, G, state["xg"] = descent(Ms, state["xg"])
            return up, D, G
        res = None
        if guard is not None and state["x"] is not None and np.any(Ms):
            ok, val = guard(Ms, *st_up.ab13md_args, state["x"])
            if ok:
                res = val
            else:  # hung or failed once: stop warm-starting for this sweep
                fallbacks += 1
                notes.append(
                    f"AB13MD warm start failed or exceeded its {warm_timeout:g} s wall-clock safety limit ({val}); "
                    "cold calls from then on"
                )
                guard.close()
                guard = None
        up, D, G, x = mu_upper.upper_ab13md(Ms, st_up, res) if res is not None else cold(Ms, lo)
        state["x"] = x if x is not None else state["x"]
        return up, D, G

    def lower_at(Ms, refine=False, target=np.inf, D=None):
        if not np.all(np.isfinite(Ms)):
            return np.inf, np.zeros((n, n), complex)
        lo, dsq, pi = lower_bound(
            Ms, st, starts=1 if not refine else 4, refine=refine, init=state["pi"], target=target, D=D
        )
        state["pi"] = pi if pi is not None else state["pi"]
        return lo, dsq

    H = st.pad(freqresp(sys, omega, bits=bits))
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
            extra = refine_peaks(omega, up, lambda w: upper_at(st.pad(freqresp(sys, np.array([w]), bits=bits))[0])[0])
        # refined points (and the best lower-bound points) get the full treatment
        w_new = np.array([w for w in extra if w not in omega])
        if w_new.size:
            Hn = st.pad(freqresp(sys, w_new, bits=bits))
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
        if cold is not None:
            cold.close()
    up = np.maximum(up, lo)
    order = np.argsort(omega)
    iu, il = int(np.argmax(up)), int(np.argmax(lo))
    return MuBoundsResult(
        omega=omega[order],
        upper=up[order],
        lower=lo[order],
        D=Ds[order],
        G=Gs[order],
        peak_upper=float(up[iu]),
        peak_upper_frequency=float(omega[iu]),
        peak_lower=float(lo[il]),
        critical_frequency=float(omega[il]),
        worst_delta=st.unpad_delta(deltas[il]),
        structure=st,
        method=meth,
        warm_start_fallbacks=fallbacks,
        notes=tuple(
            notes
            + ([] if lmi is None else lmi.events)
            + (
                [
                    f"AB13MD exceeded its {cold_timeout:g} s wall-clock safety limit at {cold.fallbacks} "
                    f"frequencies (taken for hung): {cold.fallback_name} upper bound used there, a true bound "
                    "but not AB13MD's figure, so these points depend on the machine's speed"
                ]
                if cold is not None and cold.fallbacks
                else []
            )
            + ([] if cold is None else cold.events)
            + ([] if bits is None else [f"frequency responses evaluated at {bits} bits"])
        ),
    )


# Public name for the D-scale fit of the synthesis stage; the private spelling
# stays until polyrob.synthesis.scalings.dscale has moved over to the public one.
upper_bound_ab13md = mu_upper.upper_ab13md
_upper_ab13md = upper_bound_ab13md
