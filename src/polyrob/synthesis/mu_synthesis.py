"""``musyn`` (MATLAB's name): robust controller by μ-synthesis, full order (D-K / D-G-K) or fixed structure.

The full-order iteration is :class:`~polyrob.synthesis.dk.iteration.DKIteration`; a
fixed structure (``"tfN"``, ``"pid"``, ``"ss:N"``) goes to
:func:`~polyrob.synthesis.fixed.synthesis.fixed_structure_musyn` with the common
options passed through unchanged (``None`` meaning "that method's default")
and its own options (``starts``, ``seed``, ``init``, ``options``, a
:class:`~polyrob.synthesis.fixed.options.FixedStructureOptions`) as given.
Whatever the iteration optimised, the controller is certified by
:func:`~polyrob.synthesis.dk.frequency.certify`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

import control
import numpy as np

from polyrob._threads import single_blas_thread
from polyrob.analysis.certificate import certify_loop
from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.errors import PolyrobError, SynthesisError
from polyrob.plant.generalized import as_controller_ss
from polyrob.synthesis.dk.frequency import frequency_grid, performance_lower_bound
from polyrob.synthesis.dk.iteration import DKIteration
from polyrob.synthesis.fixed.synthesis import fixed_structure_musyn
from polyrob.synthesis.hinf.checks import check_stabilizable
from polyrob.synthesis.result import MusynResult
from polyrob.synthesis.scalings.dfit import LogMagnitudeFit

__all__ = ["musyn", "scaling_order_defaults", "LARGE_STRUCTURE_ORDERS"]

log = logging.getLogger("polyrob")

#: Above this many padded channels (:data:`polyrob.analysis.mu.sweep.DESCENT_ABOVE`, a 6-7 joint
#: arm's axes model) the D and G scalings default to constants: a fitted order ``o`` on a block
#: repeated ``r`` times adds ``o * r`` states on each side of the plant, and on ur5 (twelve blocks
#: of six) the fits and K-steps of order 1-4 took most of a 15-minute budget per iteration.
LARGE_STRUCTURE_ORDERS = {"d_order": (0,), "g_order": (0,)}

#: defaults of the full-order iteration for the options left at ``None``
FULL_ORDER_DEFAULTS = {
    "max_iter": 20,
    "tol": 1e-3,
    "patience": 2,
    "d_order": (0, 1, 2, 3, 4),
    "g_order": (0, 1, 2),
    "fit_tol": 0.01,
}


def scaling_order_defaults(st) -> dict:
    """Candidate D and G fit orders of a D-K iteration on ``st`` (constant above 24 padded channels).

    Examples
    --------
    >>> from polyrob.analysis.mu.blocks import as_block_structure
    >>> scaling_order_defaults(as_block_structure([[-2, 0], [2, 2]]))
    {'d_order': (0, 1, 2, 3, 4), 'g_order': (0, 1, 2)}
    >>> scaling_order_defaults(as_block_structure([[-6, 0]] * 5))
    {'d_order': (0,), 'g_order': (0,)}
    """
    from polyrob.analysis.mu.sweep import DESCENT_ABOVE

    if st.padded_size > DESCENT_ABOVE:
        return dict(LARGE_STRUCTURE_ORDERS)
    return {k: FULL_ORDER_DEFAULTS[k] for k in ("d_order", "g_order")}


def _parse_plant(P, blk, n_u, n_y):
    from polyrob.plant.generalized import GeneralizedPlant

    if isinstance(P, GeneralizedPlant):
        Psys = P.system
        n_u = P.n_u if n_u is None else int(n_u)
        n_y = P.n_y if n_y is None else int(n_y)
        if blk is None:
            blk = P.block_structure_rp
    elif isinstance(P, control.StateSpace):
        Psys = P
        if n_u is None or n_y is None:
            raise PolyrobError("musyn of a bare StateSpace needs n_u and n_y")
        if blk is None:
            raise PolyrobError("musyn of a bare StateSpace needs blk")
    else:
        raise PolyrobError(f"musyn needs a GeneralizedPlant or a StateSpace, got {type(P).__name__}")
    st = as_block_structure(blk)
    nr, nc = st.m_shape
    if (Psys.noutputs - n_y, Psys.ninputs - n_u) != (nr, nc):
        raise PolyrobError(
            f"the plant has {Psys.noutputs - n_y} outputs and {Psys.ninputs - n_u} inputs besides y and u, "
            f"but the block structure {st} needs {nr} and {nc}"
        )
    if Psys.dt not in (0, None):
        raise PolyrobError("musyn: the plant must be continuous-time")
    return Psys, st, int(n_u), int(n_y)


def musyn(
    P,
    blk=None,
    *,
    structure: str = "full",
    mixed: bool | None = None,
    max_iter: int | None = None,
    tol: float | None = None,
    patience: int | None = None,
    d_order: Sequence[int] | None = None,
    g_order: Sequence[int] | None = None,
    fit_tol: float | None = None,
    omega=None,
    progress: bool | None = None,
    target: float | None = None,
    initial_controller=None,
    mu_bound=None,
    d_fit=None,
    hinf_step=None,
    certify_omega=None,
    check_weights: bool = True,
    n_u: int | None = None,
    n_y: int | None = None,
    time_limit: float | None = None,
    **structure_options,
) -> MusynResult:
    """Robust controller by μ-synthesis (MATLAB's ``musyn``), with its μ certificate.

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        The generalized plant; a ``StateSpace`` needs ``blk``, ``n_u``, ``n_y``
        (uncertainty/performance channels first, ``u`` and ``y`` last).
    blk : BlockStructure or array_like, optional
        Default: ``P.block_structure_rp`` (uncertainty blocks and the
        performance block).
    structure : str
        ``"full"`` (full-order D-K here) or a fixed structure (``"tf3"``,
        ``"pid"``, ``"ss:N"``, see :func:`~polyrob.synthesis.fixed.structures.controller_structure`)
        handled by :func:`polyrob.synthesis.fixed.synthesis.fixed_structure_musyn`, which
        receives ``mixed``, ``max_iter``, ``tol``, ``omega``, ``progress``,
        ``target``, ``initial_controller``, ``n_u``, ``n_y``,
        ``certify_omega`` as given (``None``: its own default) and
        ``structure_options`` (``starts``, ``seed``, ``init``, ``options``).
        The full-order options ``patience``, ``d_order``, ``g_order``,
        ``fit_tol``, ``mu_bound``, ``d_fit``, ``hinf_step`` are refused
        with a fixed structure.
    mixed : bool, optional
        D-G-K with real blocks kept real; ``False``: every block complex
        (D-K).  Default: D-G-K when ``blk`` has real blocks.
    max_iter, tol, patience : int, float, int, optional
        Stopping rules, see :class:`DKIteration` (full order: 20, 1e-3, 2).
    d_order, g_order : sequence of int, optional
        Candidate orders of the D and G fits (the lowest that fits is used;
        default ``0..4`` and ``0..2``; constant scalings, :data:`LARGE_STRUCTURE_ORDERS`,
        on structures above :data:`~polyrob.analysis.mu.sweep.DESCENT_ABOVE` padded channels).
    fit_tol : float, optional
        Relative tolerance of the fitted bound (default 0.01), see
        :class:`~polyrob.synthesis.scalings.dfit.LogMagnitudeFit`.
    omega : array_like, optional
        D-step grid (rad/s); default :func:`frequency_grid` (8 points per
        decade); lightly damped closed-loop poles are added each iteration.
    progress : bool, optional
        One line per iteration; default only on a terminal.
    target : float, optional
        Stop once the grid peak μ is below it (a PID start: its certificate).
    initial_controller : LTI or "pid", optional
        Start with a D-step on this controller instead of the unscaled H∞
        one; for a mixed problem the iteration then goes straight to D-G-K
        steps (warm start, e.g. from a complex D-K result).  ``"pid"``: the
        per-joint PID tuned to ``P``'s weights
        (:func:`polyrob.synthesis.pid_tuning.tuned_pid`), the start of an
        arm behind computed torque; ``info["start"]`` says which start was used.
    mu_bound, d_fit, hinf_step : strategy objects, optional
        Replace :class:`MuUpperBound`, :class:`~polyrob.synthesis.scalings.dscale.LogMagnitudeFit`,
        :class:`HinfStep`.
    certify_omega : array_like, optional
        Grid of the final certificate (default: the loop's own grid of
        :func:`polyrob.analysis.certificate.certify_loop`, the one ``analyze`` uses).
    check_weights : bool
        Raise :class:`SynthesisError` when ``W_S`` and ``W_T`` alone force
        μ > 1 (:func:`performance_lower_bound`).
    n_u, n_y : int, optional
        For a bare ``StateSpace``.
    time_limit : float, optional
        Seconds after which no new iteration (or fixed-structure start)
        begins; the best controller so far is certified and ``info["stopped_by"]``
        says what stopped it.  A safety net on wall-clock time: the figures of
        the iterations that ran do not depend on it.

    Returns
    -------
    MusynResult
        ``peak_mu`` is the certified upper bound of ``Fl(P, K)`` against
        ``blk`` with :func:`polyrob.analysis.mu.bounds.mu_bounds` (real blocks real), whatever
        the iteration optimised; ``mu_history`` the grid peak of the D-step
        bound after each K-step (complex μ for D-K, mixed μ for D-G-K).
        ``info`` has ``method``, ``orders`` (D/G per iteration), ``gamma``,
        ``timings``, ``regularization``, ``best_iteration``, ``grid_peak_mu``,
        ``fallbacks`` (rejected K-steps, G steps replaced by D steps, failed
        worker calls: what was done instead of the planned route).

    Raises
    ------
    SynthesisError
        Unstabilisable plant, no K-step solvable, weights that make robust
        performance impossible, unknown structure.
    PolyrobError
        Inconsistent sizes.

    Examples
    --------
    A first-order plant with a 50% input-multiplicative complex uncertainty:

    >>> import control, numpy as np
    >>> from polyrob.synthesis import musyn
    >>> G = control.ss(control.tf([1], [1, 1]))
    >>> # inputs [d, w, u], outputs [v, z, y]:  v = 0.5 u, z = 0.5 e, y = e = w - G (u + d)
    >>> A, B, C = G.A, G.B, G.C
    >>> P = control.ss(A, np.hstack([B, 0 * B, B]),
    ...                np.vstack([0 * C, -0.5 * C, -C]),
    ...                [[0, 0, 0.5], [0, 0.5, 0], [0, 1, 0]])
    >>> res = musyn(P, [[1, 1], [1, 1]], n_u=1, n_y=1, max_iter=3, progress=False)
    >>> res.order >= 1, bool(res.peak_mu < 1)
    (True, True)
    """
    t_start = time.perf_counter()
    deadline = None if time_limit is None else t_start + float(time_limit)
    start_words = None
    if isinstance(initial_controller, str) and initial_controller == "pid":
        from polyrob.synthesis.pid_tuning import pid_start

        stop = {"target": target, "only": max_iter == 1 and structure == "full"} if structure in ("full", "pid") else {}
        initial_controller, start_words, done = pid_start(P, certify_omega=certify_omega, **stop)
        if done is not None:
            return done
    if not isinstance(structure, str):
        raise SynthesisError(f"unknown controller structure {structure!r}: give a string such as 'full' or 'tf3'")
    if structure != "full":
        full_only = {
            "patience": patience,
            "d_order": d_order,
            "g_order": g_order,
            "fit_tol": fit_tol,
            "mu_bound": mu_bound,
            "d_fit": d_fit,
            "hinf_step": hinf_step,
        }
        given = sorted(k for k, v in full_only.items() if v is not None)
        if given:
            raise PolyrobError(f"options {given} apply to the full-order synthesis only, not to {structure!r}")
        # the fixed-structure solver validates the structure name (controller_structure)
        result = fixed_structure_musyn(
            P,
            blk,
            structure,
            mixed=mixed,
            max_iter=max_iter,
            tol=tol,
            omega=omega,
            progress=progress,
            target=target,
            initial_controller=initial_controller,
            n_u=n_u,
            n_y=n_y,
            deadline=deadline,
            certify_omega=certify_omega,
            **structure_options,
        )
        if start_words:
            result.info["start"] = start_words
        return result
    if structure_options:
        raise PolyrobError(f"unexpected options for a full-order synthesis: {sorted(structure_options)}")
    opt = {
        k: (v if v is not None else FULL_ORDER_DEFAULTS[k])
        for k, v in {
            "max_iter": max_iter,
            "tol": tol,
            "patience": patience,
            "d_order": d_order,
            "g_order": g_order,
            "fit_tol": fit_tol,
        }.items()
    }
    Psys, st, n_u, n_y = _parse_plant(P, blk, n_u, n_y)
    defaults = scaling_order_defaults(st)
    opt["d_order"] = d_order if d_order is not None else defaults["d_order"]
    opt["g_order"] = g_order if g_order is not None else defaults["g_order"]
    if check_weights:
        lb, wlb = performance_lower_bound(P)
        if lb >= 1.0:
            raise SynthesisError(
                f"the weights make robust performance impossible: at {wlb:.3g} rad/s, |W_S W_T|/sqrt(|W_S|^2 + "
                f"|W_T|^2) = {lb:.3g} >= 1, so no controller reaches mu < 1 (S + T = I). Lower the bandwidth "
                "of W_S or raise the crossover of W_T (or pass check_weights=False to get the best mu > 1)"
            )
    if mixed is None:
        mixed = st.has_real
    mixed = bool(mixed) and st.has_real
    if omega is None:
        omega = frequency_grid(Psys)
    omega = np.unique(np.asarray(omega, float).ravel())
    if omega.size < 3 or np.any(omega <= 0) or not np.all(np.isfinite(omega)):
        raise PolyrobError("omega must hold at least three positive finite frequencies")
    B = np.asarray(Psys.B, float)
    C = np.asarray(Psys.C, float)
    check_stabilizable(np.asarray(Psys.A, float), B[:, -n_u:], C[-n_y:], list(Psys.state_labels))
    if d_fit is None:
        d_fit = LogMagnitudeFit(orders=opt["d_order"], g_orders=opt["g_order"], tol=opt["fit_tol"])
    loop = DKIteration(
        mu_bound,
        d_fit,
        hinf_step,
        max_iter=opt["max_iter"],
        tol=opt["tol"],
        patience=opt["patience"],
        target=target,
        progress=progress,
        deadline=deadline,
    )
    K0 = None
    if initial_controller is not None:
        K0 = as_controller_ss(initial_controller, n_u, n_y)
    with single_blas_thread():
        # a warm start of a mixed problem goes straight to D-G-K steps: the
        # controller is presumably already the outcome of D-K steps
        phase0 = "DG" if (mixed and K0 is not None) else "D"
        hist = loop.run(Psys, n_u, n_y, st, omega, mixed=mixed, initial_controller=K0, start_phase=phase0)
        if not hist:
            raise SynthesisError("musyn: no iteration completed")
        # certify the best controllers (by grid peak); a sharp peak between
        # grid points can make the runner-up the better one
        order = sorted(range(len(hist)), key=lambda i: hist[i].mu_peak)
        if not np.isfinite(hist[order[0]].mu_peak):
            raise SynthesisError("musyn: no controller stabilised the plant")
        Pc = P if not isinstance(P, control.StateSpace) else Psys
        kw = {} if not isinstance(P, control.StateSpace) else {"n_u": n_u, "n_y": n_y}
        best = None
        for i in order[:2]:
            rec = hist[i]
            if not np.isfinite(rec.mu_peak):
                break
            # the certificate every caller makes: the loop's own grid unless one is given
            t_cert = time.perf_counter()
            cert = certify_loop(Pc, rec.K, st, certify_omega, sweep_unstable=False, **kw)
            log.info(
                f"musyn: certificate of iteration {i + 1} (order {rec.K.nstates}): {cert.status.value}, "
                f"grid peak {cert.mu_upper_grid:.4g}, {time.perf_counter() - t_cert:.1f} s"
            )
            if best is None or cert.mu_upper_grid < best[1].mu_upper_grid:
                best = (i, cert)
            if cert.mu_upper_grid <= rec.mu_peak * 1.02:
                break  # the grid saw the peak: no need to look further
    i_best, cert = best
    peak_mu, peak_lo, N = cert.mu_upper_grid, cert.mu_lower, cert.closed_loop
    peak_w = float(cert.mu.peak_upper_frequency) if cert.mu is not None else float("nan")
    rec = hist[i_best]
    seconds = time.perf_counter() - t_start
    info = {
        "method": "D-G-K" if mixed else "D-K",
        "mixed": mixed,
        "best_iteration": i_best + 1,
        "grid_peak_mu": float(rec.mu_peak),
        "orders": [h.orders for h in hist],
        "scaling_orders": {"d_order": list(opt["d_order"]), "g_order": list(opt["g_order"])},
        "regularization": list(rec.notes),
        # K-steps rejected, G steps replaced by D steps: what the iteration did instead
        "fallbacks": list(loop.failures) + list(getattr(getattr(loop.mu_bound, "sweep", None), "notes", [])),
        "timings": [h.seconds for h in hist],
        "stopped_by": loop.stopped_by,
        "start": start_words or ("the given controller" if K0 is not None else "the unscaled H-infinity controller"),
        "omega": omega,
        "reference": (
            "P. M. Young, Controller design with real parametric uncertainty, IJC 65(3), 1996; "
            "G-scalings via J-spectral factorisation (see polyrob.synthesis.scalings.dscale)"
        )
        if mixed
        else "J. C. Doyle, Structured uncertainty in control system design, CDC 1985 (D-K iteration)",
    }
    return MusynResult(
        controller=rec.K,
        structure="full",
        order=int(rec.K.nstates),
        peak_mu=float(peak_mu),
        peak_mu_lower=float(peak_lo),
        peak_frequency=float(peak_w),
        mu_history=np.array([h.mu_peak for h in hist]),
        gamma_history=np.array([h.gamma for h in hist]),
        scalings=(rec.scalings,),
        closed_loop=N,
        certificate=cert,
        iterations=len(hist),
        seconds=float(seconds),
        info=info,
    )
