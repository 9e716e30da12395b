"""``musyn`` (MATLAB's name): robust controller by μ-synthesis, full order (D-K / D-G-K) or fixed structure.

What to do is a :class:`~polyrob.synthesis.options.MusynOptions` (MATLAB's
``musynOptions``) whose method is a strategy: the full-order iteration
(:class:`~polyrob.synthesis.options.FullOrder`, run here by
:class:`~polyrob.synthesis.dk.iteration.DKIteration`) or a fixed structure
(:class:`~polyrob.synthesis.options.FixedStructure`: ``"tfN"``, ``"pid"``,
``"ss:N"``, run by :func:`~polyrob.synthesis.fixed.synthesis.fixed_structure_musyn`
with the same options, ``None`` meaning "that method's default").
Whatever the iteration optimised, the controller is certified by
:func:`~polyrob.analysis.certificate.certify_loop`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import control
import numpy as np

from polyrob._threads import single_blas_thread
from polyrob.analysis.certificate import certify_loop
from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.clock import UserTimeLimit
from polyrob.controller import as_controller_ss
from polyrob.errors import ArgumentError, SynthesisError
from polyrob.progress import report, span
from polyrob.synthesis.dk.frequency import frequency_grid, performance_lower_bound
from polyrob.synthesis.dk.iteration import DKIteration
from polyrob.synthesis.fixed.synthesis import fixed_structure_musyn
from polyrob.synthesis.hinf.checks import check_stabilizable
from polyrob.synthesis.options import FixedStructure, MusynOptions
from polyrob.synthesis.result import MusynResult
from polyrob.synthesis.scalings.dfit import LogMagnitudeFit

__all__ = ["musyn", "MusynOptions", "scaling_order_defaults", "LARGE_STRUCTURE_ORDERS"]

log = logging.getLogger("polyrob")

#: Above this many padded channels (:data:`polyrob.analysis.mu.sweep.DESCENT_ABOVE`, a 6-7 joint
#: arm's axes model) the D and G scalings default to constants: a fitted order ``o`` on a block
#: repeated ``r`` times adds ``o * r`` states on each side of the plant, and on ur5 (twelve blocks
#: of six) the fits and K-steps of order 1-4 took most of a 15-minute budget per iteration.
LARGE_STRUCTURE_ORDERS = {"d_order": (0,), "g_order": (0,)}
#: The part of a full-order synthesis' progress its D-K iterations fill; the certificate of the best iteration the
#: rest, so the whole job's line does not stand near its end meanwhile (`polyrob synth ur5 --robot-uncertainty
#: default --bandwidth-scale 16 --max-iter 2`: 22 s of iterations, then 120 s of certificate at "97 %, 5 s left").
ITERATIONS_SHARE = 0.5

#: defaults of the full-order iteration for the options left at ``None``
FULL_ORDER_DEFAULTS = {
    "max_iter": 20,
    "tol": 1e-3,
    "patience": 2,
    "d_order": (0, 1, 2, 3, 4),
    "g_order": (0, 1, 2),
    "fit_tol": 0.01,
}


#: What the full-order iterations follow, for ``info["reference"]``.
REFERENCES = {
    "D-G-K": (
        "P. M. Young, Controller design with real parametric uncertainty, IJC 65(3), 1996; "
        "G-scalings via J-spectral factorisation (see polyrob.synthesis.scalings.dscale)"
    ),
    "D-K": "J. C. Doyle, Structured uncertainty in control system design, CDC 1985 (D-K iteration)",
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
            raise ArgumentError("musyn of a bare StateSpace needs n_u and n_y")
        if blk is None:
            raise ArgumentError("musyn of a bare StateSpace needs blk")
    else:
        raise ArgumentError(f"musyn needs a GeneralizedPlant or a StateSpace, got {type(P).__name__}")
    st = as_block_structure(blk)
    nr, nc = st.m_shape
    if (Psys.noutputs - n_y, Psys.ninputs - n_u) != (nr, nc):
        raise ArgumentError(
            f"the plant has {Psys.noutputs - n_y} outputs and {Psys.ninputs - n_u} inputs besides y and u, "
            f"but the block structure {st} needs {nr} and {nc}"
        )
    if Psys.dt not in (0, None):
        raise ArgumentError("musyn: the plant must be continuous-time")
    return Psys, st, int(n_u), int(n_y)


def musyn(
    P, blk=None, *, options: MusynOptions | None = None, n_u: int | None = None, n_y: int | None = None, **keywords
):
    """Robust controller by μ-synthesis (MATLAB's ``musyn``), with its μ certificate.

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        The generalized plant; a ``StateSpace`` needs ``blk``, ``n_u``, ``n_y``
        (uncertainty/performance channels first, ``u`` and ``y`` last).
    blk : BlockStructure or array_like, optional
        Default: ``P.block_structure_rp`` (uncertainty blocks and the
        performance block).
    options : MusynOptions, optional
        What to do (MATLAB's ``musynOptions``): the method, a
        :class:`~polyrob.synthesis.options.FullOrder` D-K / D-G-K iteration
        (default) or a :class:`~polyrob.synthesis.options.FixedStructure`
        (``"tf3"``, ``"pid"``, ``"ss:N"``, handled by
        :func:`polyrob.synthesis.fixed.synthesis.fixed_structure_musyn`), and
        the stopping rules, grids, start and time limit every method shares.
    n_u, n_y : int, optional
        For a bare ``StateSpace``.
    **keywords
        The fields of :class:`MusynOptions` and the flat keywords of earlier
        versions (``structure``, ``starts``, ``d_order``, ...), applied to
        ``options`` by :meth:`MusynOptions.build`.

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
        worker calls: what was done instead of the planned route),
        ``stopped_by`` (what stopped the iteration: ``time_limit`` says so)
        and ``start`` (``initial_controller="pid"``: the tuned PID's words).

    Raises
    ------
    SynthesisError
        Unstabilisable plant, no K-step solvable, weights that make robust
        performance impossible, unknown structure.
    PolyrobError
        Inconsistent sizes.
    ArgumentError
        Unknown options, or a method's option given to the other.

    Examples
    --------
    A first-order plant with a 50% input-multiplicative complex uncertainty:

    >>> import control, numpy as np
    >>> from polyrob.synthesis import MusynOptions, musyn
    >>> G = control.ss(control.tf([1], [1, 1]))
    >>> # inputs [d, w, u], outputs [v, z, y]:  v = 0.5 u, z = 0.5 e, y = e = w - G (u + d)
    >>> A, B, C = G.A, G.B, G.C
    >>> P = control.ss(A, np.hstack([B, 0 * B, B]),
    ...                np.vstack([0 * C, -0.5 * C, -C]),
    ...                [[0, 0, 0.5], [0, 0.5, 0], [0, 1, 0]])
    >>> res = musyn(P, [[1, 1], [1, 1]], n_u=1, n_y=1, options=MusynOptions(max_iter=3, progress=False))
    >>> res.order >= 1, bool(res.peak_mu < 1)
    (True, True)
    """
    opts = MusynOptions.build(options, **keywords)
    t_start = time.perf_counter()
    deadline = UserTimeLimit.starting_now(opts.time_limit)
    if not isinstance(opts.structure, str):
        raise SynthesisError(f"unknown controller structure {opts.structure!r}: give a string such as 'full' or 'tf3'")
    start_words = None
    if isinstance(opts.initial_controller, str) and opts.initial_controller == "pid":
        opts, start_words, done = _pid_start(P, opts)
        if done is not None:
            return done
    if isinstance(opts.method, FixedStructure):
        # the fixed-structure solver validates the structure name (controller_structure)
        result = fixed_structure_musyn(P, blk, options=opts, n_u=n_u, n_y=n_y, deadline=deadline)
        if start_words:
            result.info["start"] = start_words
        return result
    return _full_order(P, blk, opts, n_u, n_y, t_start, deadline, start_words)


def _pid_start(P, opts: MusynOptions):
    """``initial_controller="pid"``: the options with the tuned PID as the start, its words, and a result when it is the answer."""
    from polyrob.synthesis.pid_tuning import pid_start

    stop = {}
    if opts.structure in ("full", "pid"):
        stop = {"target": opts.target, "only": opts.max_iter == 1 and opts.structure == "full"}
    # a fixed structure fits its own parameters to the start: only the full order keeps a decoupling
    decouple = opts.structure == "full"
    controller, words, done = pid_start(P, certify_omega=opts.certify_omega, decouple=decouple, **stop)
    return replace(opts, initial_controller=controller), words, done


def _full_order_settings(P, blk, opts: MusynOptions, n_u, n_y):
    """The plant, block structure, sizes, grid and scaling fit of a full-order run (checked)."""
    method = opts.method
    Psys, st, n_u, n_y = _parse_plant(P, blk, n_u, n_y)
    orders = scaling_order_defaults(st)
    fit = {
        "d_order": orders["d_order"] if method.d_order is None else method.d_order,
        "g_order": orders["g_order"] if method.g_order is None else method.g_order,
        "fit_tol": FULL_ORDER_DEFAULTS["fit_tol"] if method.fit_tol is None else method.fit_tol,
    }
    if opts.check_weights:
        lb, wlb = performance_lower_bound(P)
        if lb >= 1.0:
            raise SynthesisError(
                f"the weights make robust performance impossible: at {wlb:.3g} rad/s, |W_S W_T|/sqrt(|W_S|^2 + "
                f"|W_T|^2) = {lb:.3g} >= 1, so no controller reaches mu < 1 (S + T = I). Lower the bandwidth "
                "of W_S or raise the crossover of W_T (or pass check_weights=False to get the best mu > 1)"
            )
    mixed = bool(st.has_real if opts.mixed is None else opts.mixed) and st.has_real
    omega = frequency_grid(Psys) if opts.omega is None else opts.omega
    omega = np.unique(np.asarray(omega, float).ravel())
    if omega.size < 3 or np.any(omega <= 0) or not np.all(np.isfinite(omega)):
        raise ArgumentError("omega must hold at least three positive finite frequencies")
    B = np.asarray(Psys.B, float)
    C = np.asarray(Psys.C, float)
    check_stabilizable(np.asarray(Psys.A, float), B[:, -n_u:], C[-n_y:], list(Psys.state_labels))
    return Psys, st, n_u, n_y, mixed, omega, fit


def _full_order(P, blk, opts: MusynOptions, n_u, n_y, t_start, deadline, start_words) -> MusynResult:
    """The full-order D-K / D-G-K iteration, its best controllers certified."""
    method = opts.method
    Psys, st, n_u, n_y, mixed, omega, fit = _full_order_settings(P, blk, opts, n_u, n_y)
    d_fit = method.d_fit
    if d_fit is None:
        d_fit = LogMagnitudeFit(orders=fit["d_order"], g_orders=fit["g_order"], tol=fit["fit_tol"])

    def rule(name):
        value = getattr(opts if name in ("max_iter", "tol") else method, name)
        return FULL_ORDER_DEFAULTS[name] if value is None else value

    loop = DKIteration(
        method.mu_bound,
        d_fit,
        method.hinf_step,
        max_iter=rule("max_iter"),
        tol=rule("tol"),
        patience=rule("patience"),
        target=opts.target,
        progress=opts.progress,
        deadline=deadline,
    )
    K0 = None if opts.initial_controller is None else as_controller_ss(opts.initial_controller, n_u, n_y)
    with single_blas_thread():
        # a warm start of a mixed problem goes straight to D-G-K steps: the
        # controller is presumably already the outcome of D-K steps
        phase0 = "DG" if (mixed and K0 is not None) else "D"
        with span(0.0, ITERATIONS_SHARE):
            hist = loop.run(Psys, n_u, n_y, st, omega, mixed=mixed, initial_controller=K0, start_phase=phase0)
        if not hist:
            raise SynthesisError("musyn: no iteration completed")
        with span(ITERATIONS_SHARE, 1.0):
            i_best, cert = _certify_best(P, Psys, hist, st, opts.certify_omega, n_u, n_y)
    rec = hist[i_best]
    info = {
        "method": "D-G-K" if mixed else "D-K",
        "mixed": mixed,
        "best_iteration": i_best + 1,
        "grid_peak_mu": float(rec.mu_peak),
        "orders": [h.orders for h in hist],
        "scaling_orders": {"d_order": list(fit["d_order"]), "g_order": list(fit["g_order"])},
        "regularization": list(rec.notes),
        # K-steps rejected, G steps replaced by D steps: what the iteration did instead
        "fallbacks": list(loop.failures) + list(getattr(getattr(loop.mu_bound, "sweep", None), "notes", [])),
        "timings": [h.seconds for h in hist],
        "stopped_by": loop.stopped_by,
        "start": start_words or ("the given controller" if K0 is not None else "the unscaled H-infinity controller"),
        "omega": omega,
        "reference": REFERENCES["D-G-K" if mixed else "D-K"],
    }
    return MusynResult.certified(
        rec.K,
        "full",
        cert,
        mu_history=[h.mu_peak for h in hist],
        gamma_history=[h.gamma for h in hist],
        scalings=(rec.scalings,),
        iterations=len(hist),
        seconds=time.perf_counter() - t_start,
        info=info,
    )


def _certify_best(P, Psys, hist, st, certify_omega, n_u, n_y):
    """``(index, certificate)`` of the best iteration: the two lowest grid peaks certified, the lower certificate kept.

    A sharp peak between grid points can make the runner-up the better one.
    """
    order = sorted(range(len(hist)), key=lambda i: hist[i].mu_peak)
    if not np.isfinite(hist[order[0]].mu_peak):
        raise SynthesisError("musyn: no controller stabilised the plant")
    bare = isinstance(P, control.StateSpace)
    Pc, kw = (Psys, {"n_u": n_u, "n_y": n_y}) if bare else (P, {})
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
        report(1, 2)  # at most two certificates: the line moves after the first
        if cert.mu_upper_grid <= rec.mu_peak * 1.02:
            break  # the grid saw the peak: no need to look further
    return best
