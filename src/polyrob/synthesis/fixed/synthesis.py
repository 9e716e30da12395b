"""Fixed-structure μ-synthesis: a D-G-K iteration over a parametrised controller.

:func:`fixed_structure_musyn` searches a controller of a prescribed structure
(:mod:`polyrob.synthesis.fixed.structures`: ``"tfN"``, ``"pid"``, ``"ss:N"``) that
minimises the peak over frequency of the mixed-μ upper bound of the closed
loop ``N(θ) = lft(P, K(θ))``, the paper's fixed-structure ``musyn`` (section 3).

The method (what is implemented, and why)
-----------------------------------------
The μ upper bound at one frequency is ``min over (D, G)`` of
``β_{D,G}(M)``, the smallest ``β`` with
``M^H D² M + j(G M - M^H G) ⪯ β² D²`` (Fan-Tits-Doyle).  For any fixed
admissible scalings ``β_{D,G}(N(jω; θ))`` is an upper bound of μ for every
``θ``; ``β²`` is the largest eigenvalue of the Hermitian matrix
``A = M̃^H M̃ + j(G̃ M̃ - M̃^H G̃)``, ``M̃ = D M D⁻¹``, ``G̃ = D⁻¹ G D⁻¹``, with
an analytic derivative ``dλ = 2 Re(u^H dM̃ v)``, ``u = (M̃ - jG̃) v``
(``v`` the unit eigenvector), ``dN = P₁₂ (I - K P₂₂)⁻¹ dK (I - P₂₂ K)⁻¹ P₂₁``
and ``dK/dθ`` from the structure.

Each iteration (what musyn's fixed-structure mode alternates, tightened):

1. **K-step** — ``min_θ max_ω μ̄(N(jω; θ))`` over the frequencies near the
   peak, in epigraph form ``min t s.t. β_{ω,i}(θ) ≤ t`` solved by SLSQP in a
   trust region (well-scaled parameters), the two largest eigenvalues per
   frequency as separate constraints (a multiple eigenvalue — the rule at
   optimal scalings — is then modelled by its cutting planes, not by one
   arbitrary gradient) and the closed-loop spectral abscissa as a constraint.
   By default (``kstep="live"``) the scalings are re-optimised at every trial
   point by a warm-started batched BFGS on ``(log d, g̃)``, so the K-step
   minimises the μ bound itself (its gradient at optimal scalings is the one
   above, envelope theorem).  With the scalings frozen instead (classic D-K,
   ``kstep="frozen"``) the iteration stalled on the paper's 2R at μ ≈ 1.61
   where the live K-step went on to ≈ 1.45 from the same start.
2. **Acceptance** — backtracking until the loop is internally stable and
   the bound decreased on the working grid *and*, rigorously, on a fine
   screening grid (40/decade, plus the closed-loop pole frequencies, plus
   ``certify_omega``) checked with the nearest grid scalings; so a step
   cannot buy its progress with a resonance between grid points.
3. **D-step** — scalings refreshed where the bound is near the peak (batched
   BFGS warm-started from the previous ones; SLICOT AB13MD via
   :func:`polyrob.analysis.mu.bounds.mussv` when progress stalls and for new frequencies);
   the working grid is refined around the peaks.

The grid peak therefore never increases.  Starts: the given ``init`` (e.g.
``"paper"``: ``K*``), or a generic H2 design fitted to the structure, then
random perturbations of it (HIFOO's multi-start); a start that does not
stabilise the loop first goes through a spectral-abscissa minimisation
(HIFOO's stabilisation phase).

The best start is certified by :func:`polyrob.analysis.mu.bounds.mu_bounds` of
``lft(P, K)`` (upper and lower bounds, peak-refined): ``peak_mu`` is that
certificate's peak, independent of the optimiser.  If the certificate finds
a peak above the optimised one, it is added to the grid and the iteration
resumes (``certify_rounds``).

Examples
--------
>>> import control, numpy as np
>>> from polyrob.synthesis.fixed.synthesis import fixed_structure_musyn
>>> # a 1-state plant x' = x + d + u, v = x, y = x, z = 0.5 x; blk: one real δ
>>> # (robust stability) and a 1x1 performance block
>>> P = control.ss([[1.0]], [[1.0, 0.0, 1.0]], [[1.0], [0.5], [1.0]], np.zeros((3, 3)))
>>> w = np.logspace(-2, 2, 41)
>>> r = fixed_structure_musyn(P, [[-1, 0], [1, 1]], "tf0", n_u=1, n_y=1, init=-3.0, starts=1,
...                           max_iter=5, omega=w, certify_omega=w)
>>> r.order, bool(r.peak_mu < 0.5)      # a static gain k < -1 stabilises; large |k| is robust
(0, True)
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from control.exception import ControlArgument
from slycot.exceptions import SlycotError

from polyrob._threads import single_blas_thread
from polyrob.analysis.certificate import certify_loop
from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.errors import ArgumentError, PolyrobError, SynthesisError
from polyrob.plant.generalized import paper_controller
from polyrob.progress import span
from polyrob.synthesis.fixed.iteration import (
    StartRun,
    check_grid,
    grid_span,
    log_grid,
    optimise_start,
    reporter,
    screen_grid,
)
from polyrob.synthesis.fixed.kstep import default_controller, stabilise
from polyrob.synthesis.fixed.loop import FixedLoop, closed_loop_response, plant_parts
from polyrob.synthesis.fixed.options import FixedStructureOptions
from polyrob.synthesis.fixed.scalings import dstep, scalings_from
from polyrob.synthesis.fixed.structures import ControllerStructure, controller_structure
from polyrob.synthesis.options import FixedStructure, MusynOptions
from polyrob.synthesis.result import MusynResult

__all__ = ["fixed_structure_musyn", "FixedStructureOptions", "closed_loop_response"]

#: Shares of the job's line (guesses: the line never goes back): the starts' iterations, then the certificate;
#: within a start, its first scalings (a cold μ bound per frequency of the working grid), then its iterations.
STARTS_SHARE = 0.8
FIRST_SCALINGS_SHARE = 0.2


def fixed_structure_musyn(
    P,
    blk=None,
    structure: str | ControllerStructure | None = None,
    *,
    options: MusynOptions | FixedStructureOptions | None = None,
    n_u: int | None = None,
    n_y: int | None = None,
    deadline=None,
    **keywords,
) -> MusynResult:
    """Fixed-structure μ-synthesis (MATLAB ``musyn`` with a tunable controller).

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        Inputs ``[d; w; u]``, outputs ``[v; z; y]``.  A bare ``StateSpace``
        needs ``n_u`` and ``n_y`` (the last inputs / outputs).
    blk : BlockStructure or array_like, optional
        Structure of ``diag(Δ, Δ_perf)`` for ``lft(P, K)``; default
        ``P.block_structure_rp`` (robust performance).
    structure : str or ControllerStructure, optional
        ``"tfN"`` (each ``K_ij`` of order ``N``), ``"pid"`` or ``"ss:N"``
        (:func:`~polyrob.synthesis.fixed.structures.controller_structure`);
        default the method's (``"tf3"``).
    options : MusynOptions or FixedStructureOptions, optional
        A :class:`~polyrob.synthesis.options.MusynOptions` whose method is a
        :class:`~polyrob.synthesis.options.FixedStructure`: its ``starts``
        (``init``, or a generic H2 design fitted to the structure, then random
        perturbations of it), ``seed`` (same seed, same result), ``init``
        (``"paper"``: the paper's ``K*``, :func:`~polyrob.plant.paper_controller`,
        exact in ``"tf3"``; a lower-order result is a start for a richer
        structure) and ``tuning`` (a :class:`FixedStructureOptions`); and the
        common ``max_iter`` (per start, default 40), ``omega`` (the working
        grid, refined around the peaks; default ``grid_density`` points per
        decade over the closed-loop poles of the first start, widened by a
        decade each side), ``certify_omega`` (grid of the final certificate,
        also screened during the iteration), ``initial_controller`` (alias
        of ``init``), ``progress`` (``True``: a line per iteration; a
        callable gets a dict per iteration), ``tol`` (overrides the tuning's),
        ``target`` (stop a start once its grid peak is below it) and ``mixed``
        (``False``: every real block complex, plain D-K).  A bare
        :class:`FixedStructureOptions` is the tuning.
    n_u, n_y : int, optional
        Sizes for a bare ``StateSpace`` plant.
    deadline : UserTimeLimit, optional
        The time limit the user set (:class:`polyrob.clock.UserTimeLimit`): past it
        no new iteration or start begins; the best controller so far is
        certified (its notes name the limit).
    **keywords
        Fields of the options, flat (:meth:`MusynOptions.build`): ``starts``,
        ``init``, ``max_iter``, ...

    Returns
    -------
    MusynResult
        ``peak_mu`` is the peak of the certificate :func:`~polyrob.analysis.mu.bounds.mu_bounds`
        of ``lft(P, K)``; ``info`` holds ``theta``, the structure's
        coefficients (``"coefficients"``, for ``"tfN"`` the ``num``/``den`` of
        every ``K_ij``), the per-start summary and the grids.

    Raises
    ------
    PolyrobError
        Unknown structure (the message lists the valid ones), bad sizes.
    SynthesisError
        No start could be made to stabilise the closed loop.

    Examples
    --------
    See the module docstring.
    """
    t_start = time.perf_counter()
    chosen = {} if structure is None else {"structure": structure}
    opts = MusynOptions.build(options, default_method=FixedStructure(), **chosen, **keywords)
    method = opts.method
    if not isinstance(method, FixedStructure):
        raise ArgumentError("fixed_structure_musyn needs a FixedStructure method (musyn runs the full order)")
    tuning = method.tuning or FixedStructureOptions()
    if opts.tol is not None:
        tuning = replace(tuning, tol=float(opts.tol))
    max_iter = 40 if opts.max_iter is None else int(opts.max_iter)
    sysP, n_u, n_y = plant_parts(P, n_u, n_y)
    strc = controller_structure(method.structure, n_u, n_y)
    st = _block_structure(P, blk, opts.mixed, sysP, n_u, n_y)
    if int(method.starts) < 1:
        raise ArgumentError(f"starts must be >= 1, got {method.starts}")
    omega, certify_omega = check_grid(opts.omega, "omega"), check_grid(opts.certify_omega, "certify_omega")
    if method.init is not None and opts.initial_controller is not None:
        raise ArgumentError("give init or initial_controller, not both")
    init = opts.initial_controller if method.init is None else method.init
    fallbacks: list[str] = []
    search = _Search(sysP, FixedLoop(sysP, n_u, n_y, strc, st), tuning, max_iter, reporter(opts.progress), opts.target)

    with single_blas_thread():
        candidates = _starts(search.loop, sysP, init, method, tuning, fallbacks)
        with span(0.0, STARTS_SHARE):
            runs, failures, screen = search.run_starts(candidates, omega, certify_omega, deadline, fallbacks)
        if not runs:
            raise SynthesisError(
                f"no start stabilises the closed loop with a {strc.name} controller "
                f"({'; '.join(failures)}); try another structure, a higher order or an init controller"
            )
        best = min(runs, key=lambda r: r.peak)
        with span(STARTS_SHARE, 1.0):
            K, sweep, cert = search.certify(P, best, certify_omega, screen)

    N = cert.closed_loop
    poles = np.linalg.eigvals(np.asarray(N.A)) if N.nstates else np.zeros(0)
    if poles.size and np.max(poles.real) >= 0:  # pragma: no cover - guarded by every accepted step
        raise SynthesisError("the final closed loop is not stable")
    info = {
        "method": f"D-G-K over per-frequency scalings ({tuning.kstep} K-step: SLSQP epigraph, trust region, "
        "closed-loop spectral abscissa constraint; scalings by warm-started batched BFGS and "
        "AB13MD); adaptive grid with rigorous screening; certificate by mu_bounds",
        "theta": best.theta.tolist(),
        "coefficients": strc.describe(best.theta),
        "start": best.notes[0] if best.notes else "",
        "starts": [
            {"start": r.notes[0] if r.notes else "", "grid_peak_mu": r.peak, "iterations": r.iterations} for r in runs
        ],
        "failed_starts": failures,
        # what was done instead of the planned route (e.g. a random start after a failed H2 start)
        "fallbacks": fallbacks + list(search.loop.notes),
        "notes": best.notes[1:],
        "grid_omega": best.sc.omega.copy(),
        "certify_omega": None if certify_omega is None else certify_omega.copy(),
        "block_structure": st.matlab.tolist(),
        "closed_loop_poles": poles,
    }
    return MusynResult.certified(
        K,
        strc.name,
        cert,
        mu_history=best.history + [sweep.peak_upper],
        gamma_history=best.gammas,
        scalings=(best.sc.omega.copy(), best.sc.Dm.copy(), best.sc.G.copy()),
        iterations=best.iterations,
        seconds=time.perf_counter() - t_start,
        info=info,
    )


def _block_structure(P, blk, mixed, sysP, n_u: int, n_y: int):
    """The block structure of ``lft(P, K)`` (default ``P``'s robust performance), complex throughout when ``mixed is False``."""
    if blk is None:
        if not hasattr(P, "block_structure_rp"):
            raise ArgumentError("give blk for a bare StateSpace plant")
        blk = P.block_structure_rp
    st = as_block_structure(blk)
    if mixed is False and st.has_real:
        # complex μ: every real block becomes a complex one of the same size
        st = as_block_structure([[b.rows, 0] if b.kind == "real" else list(b.matlab) for b in st.blocks])
    if st.m_shape != (sysP.noutputs - n_y, sysP.ninputs - n_u):
        raise ArgumentError(
            f"blk {st} needs a {st.m_shape} closed loop; lft(P, K) is {sysP.noutputs - n_y}x{sysP.ninputs - n_u}"
        )
    return st


def _starts(loop: FixedLoop, sysP, init, method, tuning: FixedStructureOptions, fallbacks: list) -> list:
    """``(label, theta)`` of every start: ``init`` (or an H2 design, or at worst a random point), then perturbations."""
    strc, seed = loop.structure, int(method.seed)
    if isinstance(init, str):
        if init != "paper":
            raise ArgumentError(f"init must be 'paper', a controller or None, got {init!r}")
        init = paper_controller()
    if isinstance(init, MusynResult):
        init = init.controller_value  # from_controller takes a Controller as it is
    if init is not None:
        theta0, origin = strc.from_controller(init), "init"
    else:
        try:
            theta0, origin = strc.from_controller(default_controller(sysP, loop.n_u, loop.n_y)), "h2"
        except (ValueError, ArithmeticError, np.linalg.LinAlgError, SlycotError, ControlArgument, PolyrobError) as exc:
            # e.g. an unstabilisable plant (no LQR/Kalman solution): a random start, recorded
            theta0, origin = strc.initial(seed), "random"
            fallbacks.append(f"H2 start failed ({type(exc).__name__}: {exc}); random start (seed {seed}) used")
    rng_seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=int(method.starts))
    return [(origin, theta0)] + [
        (f"perturbed#{k}", strc.initial(int(rng_seeds[k]), around=theta0, spread=tuning.spread))
        for k in range(1, int(method.starts))
    ]


class _Search:
    """What every start shares: the plant and its loop, the tuning, the iteration budget, the reporter, the target."""

    def __init__(self, sysP, loop: FixedLoop, tuning: FixedStructureOptions, max_iter: int, report, target):
        self.sysP, self.loop, self.st = sysP, loop, loop.st
        self.tuning, self.max_iter, self.report, self.target = tuning, max_iter, report, target

    def run_starts(self, candidates, omega, certify_omega, deadline, fallbacks: list):
        """Optimise every start that can be stabilised: ``(runs, failures, screening grid)``."""
        loop, tuning = self.loop, self.tuning
        runs, failures = [], []
        extent = screen = work = None
        for label, th in candidates:
            if runs and deadline is not None and deadline.passed():
                fallbacks.append(f"starts after {len(runs)} not run: {deadline.words}")
                break
            th, a = stabilise(loop, th, tuning.min_decay)
            if not a <= -tuning.min_decay:
                failures.append(f"{label}: spectral abscissa {a:.3g}")
                continue
            if not loop.abscissa(th, full=True) < 0:
                # modes of P that no controller moves (not in the u -> y channel)
                failures.append(
                    f"{label}: P has unstable modes outside the u -> y channel "
                    f"({np.round(loop.fixed_modes[loop.fixed_modes.real >= 0], 4).tolist()})"
                )
                continue
            if extent is None:
                extent = grid_span(loop, th, omega)
                work = omega if omega is not None else log_grid(*extent, tuning.grid_density)
                screen = log_grid(*extent, tuning.screen_density)
                if certify_omega is not None:
                    screen = np.union1d(screen, certify_omega[certify_omega > 0])
            k, n = len(runs) + len(failures), len(candidates)
            with span(k / n, (k + 1) / n):  # the job's line: each start its part, its first scalings a fifth of it
                with span(0.0, FIRST_SCALINGS_SHARE):
                    sc = dstep(loop, th, work, self.st)
                run = StartRun(theta=th, sc=sc, peak=float(np.max(sc.mu)))
                run.history.append(run.peak)
                screen_grid(loop, run, screen, self.st, tuning)
                run.history[-1] = run.peak
                with span(FIRST_SCALINGS_SHARE, 1.0):
                    optimise_start(
                        loop, run, self.st, tuning, self.max_iter, screen, self.report, label, self.target, deadline
                    )
            run.notes.insert(0, label)
            runs.append(run)
        return runs, failures, screen

    def certify(self, P, best: StartRun, certify_omega, screen):
        """``(K, μ sweep, certificate)`` of the best start; a peak the grids missed sends it back to the iteration."""
        loop, tuning = self.loop, self.tuning
        kw = {} if hasattr(P, "block_structure_rp") else {"n_u": loop.n_u, "n_y": loop.n_y}
        for rnd in range(tuning.certify_rounds + 1):
            K = loop.structure.controller(best.theta)
            decided = certify_loop(P if not kw else self.sysP, K, self.st, certify_omega, **kw)
            sweep = decided.mu
            if sweep.peak_upper <= best.peak * (1 + 1e-3) or rnd == tuning.certify_rounds:
                break
            # a peak the grids missed: take its scalings, iterate a little more
            i = int(np.argmax(sweep.upper))
            extra = scalings_from(sweep.D[[i]], sweep.G[[i]], sweep.omega[[i]], sweep.upper[[i]])
            best.sc = best.sc.merged(extra)
            best.peak = float(np.max(best.sc.mu))
            best.notes.append(
                f"certificate round {rnd}: peak {sweep.peak_upper:.5g} at {sweep.omega[i]:.4g} rad/s "
                "above the grid peak; added"
            )
            screen = np.union1d(screen, sweep.omega[sweep.omega > 0])
            optimise_start(
                loop, best, self.st, tuning, max(3, self.max_iter // 4), screen, self.report, "certify", self.target
            )
        return K, sweep, decided
