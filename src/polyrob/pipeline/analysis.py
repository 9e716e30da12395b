"""A controller judged on a problem: nominal and robust stability/performance, sampling, one verdict.

``polyrob analyze`` and ``polyrob run`` call :func:`analyze_controller`; its
verdict is the robust-performance :class:`~polyrob.analysis.certificate.Certificate`'s
(status decided in :mod:`polyrob.analysis.certificate`, nowhere else).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from polyrob.errors import ArgumentError

__all__ = [
    "ControllerAnalysis",
    "analyze_controller",
    "frequency_grid",
    "controller_order",
    "instead_line",
    "reusable_certificate",
]


def instead_line(problem, analysis, limit: dict | None = None) -> str:
    """One line, when robust performance is not certified: what the controller certifies instead, and what stands in the way.

    Instead: robust stability when its own certificate holds, the worst-case
    gain over the whole set when it was asked for and proved, and the
    robust-performance margin (``analysis.margin``: the μ level proved at every
    frequency, i.e. the performance level kept on a share of the modelled
    parameter ranges).  In the way: the frequency of the μ peak and the
    weighted signal that dominates there, and the performance limit of the
    robot's unstable poles when it excludes μ < 1.  Empty when certified.
    """
    from polyrob.analysis.margins import dominant_weight

    cert = analysis.robust_performance.certificate  # the continuous loop's (a sampled one has its own line)
    if cert.certified:
        return ""
    rs, m = analysis.robust_stability.certificate, analysis.margin
    got = [rs.verdict] if rs.certified else []  # the words of its own certificate
    wc = analysis.worst_case
    if wc is not None and wc.proved:  # the whole set at a weaker performance level
        got.append(f"on the whole set, {wc.sentence()}")
    if m is not None and (m.proved or not got):
        got.append(m.sentence())
    instead = "; ".join(got) or "no margin computed"
    w = float(cert.mu.peak_upper_frequency) if cert.mu is not None else np.nan
    stable = cert.closed_loop is not None and cert.stable_at_delta0 is not None and cert.stable_at_delta0.stable
    label = dominant_weight(problem.P, cert.closed_loop, w) if stable and np.isfinite(w) else None
    shares = _shares_at_peak(problem, cert.closed_loop, w) if stable and np.isfinite(w) else ()
    said = [f"{label} dominates"] if label else []
    if shares:
        said.append("without one block mu there: " + ", ".join(b.phrase() for b in shares[:SHARES_SAID]))
    way = "mu peaks " + ("as omega -> 0" if w == 0 else f"at {w:.3g} rad/s") + (f" ({'; '.join(said)})" if said else "")
    if limit and limit.get("excludes_mu_below_one"):
        way += f"; the unstable poles keep mu >= {limit['bound']:.3g} at these weights"
    return (
        f"instead: {instead}; in the way: {way}; try --max-bandwidth (the largest bandwidth factor that "
        "certifies) or a smaller domain"
    )


#: Uncertainty blocks beyond which the leave-one-out figures are not computed (one μ bound each).
SHARES_MAX_BLOCKS = 12
#: How many of them the line says (the blocks whose removal lowers μ most).
SHARES_SAID = 3


def _shares_at_peak(problem, N, w: float) -> tuple:
    """:func:`~polyrob.analysis.margins.block_shares` of the loop ``N`` at the μ peak ``w`` (empty for one block)."""
    from polyrob.analysis.margins import block_shares, block_words
    from polyrob.analysis.mu.frequency import freqresp

    blk = np.asarray(problem.P.block_structure_rp)
    if not 2 <= len(blk) - 1 <= SHARES_MAX_BLOCKS:
        return ()
    M = np.asarray(freqresp(N, np.array([max(float(w), 0.0)])))[0]
    return block_shares(M, blk, block_words(problem.P.uncertain, blk))


def reusable_certificate(cert, P, K, scope):
    """``cert`` rescoped when it is ``certify_loop(P, K)``'s on the loop's own grid, else ``None``.

    Same block structure and the same closed loop ``lft(P, K)`` (matrices
    equal): a caller that would sweep that loop again decides this sweep instead.
    """
    from polyrob.analysis.certificate import rescoped
    from polyrob.plant.loops import lft

    if cert is None or not cert.default_grid or cert.mu is None or cert.closed_loop is None:
        return None
    if np.asarray(cert.mu.structure.matlab).tolist() != np.asarray(P.block_structure_rp).tolist():
        return None
    N = lft(P, K)
    if any(not np.array_equal(np.asarray(getattr(N, x)), np.asarray(getattr(cert.closed_loop, x))) for x in "ABCD"):
        return None
    return rescoped(cert, scope)


def frequency_grid(lo: float, hi: float, n: int):
    """``n`` log-spaced frequencies from ``lo`` to ``hi`` (rad/s)."""
    if not (0 < lo < hi and n >= 2):
        raise ArgumentError(f"frequency grid: need 0 < LO < HI and N >= 2, got {lo}:{hi}:{n}")
    return np.logspace(np.log10(lo), np.log10(hi), int(n))


def controller_order(K) -> int:
    """Number of states of a minimal-looking realisation of ``K`` (``control.ss(K).nstates``)."""
    import control

    return int(control.ss(K).nstates)


def _check_sizes(problem, K) -> None:
    import control

    Kss = control.ss(K)
    P = problem.P
    if (Kss.noutputs, Kss.ninputs) != (P.n_u, P.n_y):
        raise ArgumentError(
            f"the controller has {Kss.ninputs} input(s) and {Kss.noutputs} output(s); "
            f"{problem.robot.name} needs {P.n_y} measurement input(s) and {P.n_u} torque output(s)"
        )


@dataclass(frozen=True, eq=False)
class ControllerAnalysis:
    """What :func:`analyze_controller` found.

    Attributes
    ----------
    robust_stability, robust_performance : RobustnessResult
    nominal_performance : float
        ``||N_zw||∞`` around the nominal plant (``inf`` if the loop is unstable).
    sampling : StabilitySampling
    order : int
    covers : str
        What the μ verdict covers.
    time_varying : TimeVaryingCertificate or None
        The certificate for Jacobians varying in time (the moving robot),
        :func:`polyrob.analysis.time_varying.certificate.time_varying_certificate`;
        ``None`` when not asked for.
    moving : MovingRobotCertificate or None
        Robust performance of the linearised robot moving within the domain's
        rates (:func:`polyrob.analysis.lpv.moving.moving_robot_certificate`);
        ``None`` when not asked for.
    margin : RobustMargin or None
        When robust performance is not certified: the μ level proved at every
        frequency, read as a margin (:func:`polyrob.analysis.margins.robust_margin`).
    instead : str
        The one line of what the controller certifies instead and what stands
        in the way (:func:`instead_line`); empty when certified.
    worst_case : WorstCaseGain or None
        The worst-case weighted gain over the whole set with its upper bound
        at every frequency (:func:`polyrob.analysis.worst_case.wcgain`,
        MATLAB's ``wcgain``); ``None`` when not asked for.
    true_robots : TrueRobotCheck or None
        On a task domain behind an inner layer with something to draw (a
        robot-uncertainty set, or the layer's model error or payload range):
        the controller's frozen loops on true robots drawn from the set
        (:func:`polyrob.synthesis.true_robots.check_of_problem`), a sampled
        lower bound of the set's worst case printed beside μ (how much of μ is
        the model's); ``None`` otherwise.
    frozen_cells : TaskCellsCertificate or None
        When asked for and the whole task's certificate fails: the frozen
        robot's certificate over cells of the task
        (:func:`polyrob.analysis.frozen_cells.frozen_cells_certificate`); when
        it certifies, it is the verdict (the same robots, the same frozen
        variation, another model per cell).
    """

    robust_stability: object
    robust_performance: object
    nominal_performance: float
    sampling: object
    order: int
    covers: str
    time_varying: object = None
    moving: object = None
    margin: object = None
    instead: str = ""
    sampled: object = None
    true_robots: object = None
    worst_case: object = None
    frozen_cells: object = None

    @property
    def certificate(self):
        """The robust-performance certificate: the verdict of the analysis (the sampled loop's, when asked for;
        the task cells' when they certify what the whole task's model did not)."""
        if self.sampled is not None:
            return self.sampled.certificate
        if self.frozen_cells is not None and self.frozen_cells.certified:
            return self.frozen_cells.certificate
        return self.robust_performance.certificate

    @property
    def verdict(self) -> str:
        """The one verdict line (the certificate's)."""
        return "verdict: " + self.certificate.verdict

    def summary(self) -> dict:
        s = self.sampling
        rs, rp = self.robust_stability.summary(), self.robust_performance.summary()
        return {
            "controller_order": self.order,
            "nominal_stability": bool(self.robust_stability.nominally_stable),
            "nominal_performance_hinf": float(self.nominal_performance),
            "robust_stability": rs,
            "robust_performance": rp,
            "monte_carlo": {"samples": s.random, "stable_fraction": s.random_stable},
            "corners": {"count": s.corners, "stable_fraction": s.corners_stable},
            "worst_sampled": {
                "delta": [float(x) for x in s.worst_delta.ravel()],
                "max_pole_real_part": float(s.worst_abscissa),
            },
            "covers": self.covers,
            "status": self.certificate.status.value,
            "certified": self.certificate.certified,
            "verdict": self.verdict,
            "time_varying": None if self.time_varying is None else self.time_varying.summary(),
            "moving": None if self.moving is None else self.moving.summary(),
            "margin": None if self.margin is None else self.margin.summary(),
            "instead": self.instead or None,
            "sampled": None if self.sampled is None else self.sampled.summary(),
            "true_robots": None if self.true_robots is None else self.true_robots.to_dict(),
            "worst_case": None if self.worst_case is None else self.worst_case.summary(),
            "frozen_cells": None if self.frozen_cells is None else self.frozen_cells.summary(),
        }


def analyze_controller(
    problem,
    K,
    *,
    omega=None,
    mc: int = 500,
    seed: int = 0,
    progress: bool | None = None,
    time_varying: bool = True,
    stability: str = "sweep",
    moving: bool | None = None,
    moving_options: dict | None = None,
    limit: dict | None = None,
    certificate=None,
    sampled_loop=None,
    worst_case: bool = False,
    frozen_cells: int | None = None,
    cells_dir=None,
) -> ControllerAnalysis:
    """Nominal/robust stability and performance of ``K`` on ``problem``, and sampled stability.

    Parameters
    ----------
    problem : Problem
    K : LTI
        ``n_u x n_y`` controller.
    omega : array_like, optional
        Frequency grid (default: automatic, peak-refined).
    mc : int
        Random parameter sets for the sampled stability check (>= 1).
    seed : int
    progress : bool, optional
        Progress bars of the μ sweeps.
    time_varying : bool
        Also compute the time-varying certificate (quadratic stability and
        performance on the PLDI's vertices, or the constant-D small gain).
    stability : {"sweep", "implied"}
        ``"sweep"``: robust-stability μ by its own sweep; ``"implied"``: read
        from the robust-performance certificate when that one is certified
        (:func:`~polyrob.analysis.robust.robstab_implied`: a bound of
        robust-stability μ, not its value), else swept.
    moving : bool or None
        The moving-robot certificate (rate-bounded LPV analysis scheduled on
        the robot's state, :mod:`polyrob.analysis.lpv.moving`): ``None``
        computes it for small closed loops only (its ``AUTO_STATES``),
        ``False`` records that it was not asked for.
    moving_options : dict, optional
        Options of the rate-bounded search
        (:func:`~polyrob.analysis.lpv.moving.moving_robot_certificate`, e.g.
        ``harmonics=2``); not used on an inner-gain model.  ``jerk``: the
        task's jerk bound (``--qdddot-max``), a task domain only
        (:func:`polyrob.analysis.lpv.task.task_motion_certificate`, which
        takes the grid, basis and cell options and no symmetry).
    limit : dict, optional
        The robot's performance limit (``PerformanceLimit.to_dict()``), quoted
        by :attr:`ControllerAnalysis.instead` when it excludes μ < 1.
    certificate : Certificate, optional
        The robust-performance certificate of ``K`` on ``problem`` already
        made (a design's): decided again instead of swept when it is of the
        same closed loop on the loop's own grid (``omega`` not given).
    sampled_loop : SamplingSpec, optional
        The loop sampled at a rate with a delay
        (:func:`polyrob.analysis.sampled_data.sampled_certificate`): its
        certificate is then the verdict; the continuous figures stay beside it.
    worst_case : bool
        Also bound the worst-case weighted gain over the whole set
        (:func:`polyrob.analysis.worst_case.wcgain`: a bisection on the
        performance level, then one more certificate sweep), and the moving
        robot's on the constant-parameter route when it is computed.  A
        figure beside the verdict, not a verdict.
    frozen_cells : int, optional
        When robust performance over the whole task is not certified, cut
        the task's positions into at most this many cells, each with its own
        model (:func:`polyrob.analysis.frozen_cells.frozen_cells_certificate`;
        a per-link set on a task domain, the continuous loop): the verdict
        when every cell is certified.
    cells_dir : str or Path, optional
        Where each finished cell's certificate is kept, and found again by a
        later call on the same cell, controller and code (``None``: nothing kept).
    """
    from polyrob.analysis.robust import nominal_performance, robperf, robstab, robstab_implied, sample_stability

    if int(mc) < 1:
        raise ArgumentError(f"Monte Carlo samples must be >= 1, got {mc}")
    _check_sizes(problem, K)
    options = {"progress": progress, "scope": problem.scope()}
    if stability not in ("sweep", "implied"):
        raise ArgumentError(f"stability must be 'sweep' or 'implied', got {stability!r}")
    from polyrob.progress import report, span

    own = reusable_certificate(certificate, problem.P, K, problem.scope()) if omega is None else None
    # the job's line: the two μ sweeps are most of the stage unless the moving robot's search follows (minutes)
    ends = (0.2, 0.27, 0.3) if moving is not False else (0.6, 0.85, 1.0)
    last = 0.95
    if frozen_cells:  # the cells (a model and a sweep each, minutes) would be most of the stage
        ends, last = tuple(e / 4 for e in ends), 0.3
    with span(0.0, ends[0]):
        rp = robperf(problem.P, K, omega, certificate=own, **options)
    rs = robstab_implied(rp) if stability == "implied" else None
    if rs is None:
        with span(ends[0], ends[1]):
            rs = robstab(problem.P, K, omega, **options)
    from polyrob.synthesis.true_robots import check_of_problem

    with span(ends[1], ends[2]):
        npf = nominal_performance(problem.P, K)
        sampling = sample_stability(problem.unc, K, n=int(mc), seed=seed)
        true_robots = check_of_problem(problem, K)  # None without true robots to draw
        tv = None
        if time_varying:
            from polyrob.analysis.time_varying.certificate import time_varying_certificate

            tv = time_varying_certificate(problem, K)
    covers = rp.certificate.scope.sentence()
    from polyrob.analysis.lpv.constant import check_jerk, robot_in_motion_certificate
    from polyrob.analysis.lpv.moving import MovingRobotCertificate

    check_jerk(problem, (moving_options or {}).get("jerk"))  # refused even when the moving robot is not asked for
    if moving is False:
        mv = MovingRobotCertificate.not_computed("not asked for (--no-moving)")
    else:  # a task domain's goes to polyrob.analysis.lpv.task (its Jacobians depend on the accelerations too)
        with span(ends[2], last):  # asked for, the search is most of the stage (minutes); its solves report inside
            mv = robot_in_motion_certificate(problem, K, auto=moving is None, time_varying=tv,
                                             worst_case=worst_case, **dict(moving_options or {}))  # fmt: skip
    from polyrob.analysis.margins import robust_margin

    margin = None if rp.certificate.certified else robust_margin(rp.certificate)
    cells = None
    if frozen_cells and not rp.certificate.certified and sampled_loop is None:
        from polyrob.analysis.frozen_cells import frozen_cells_certificate

        with span(last, 1.0):
            cells = frozen_cells_certificate(
                problem,
                K,
                max_cells=int(frozen_cells),
                screen_at=[rp.critical_frequency],
                progress=report,
                cells_dir=cells_dir,
            )
        margin = None if cells.certified else margin
    sampled = None
    if sampled_loop is not None:
        from polyrob.analysis.sampled_data import sampled_certificate

        sampled = sampled_certificate(problem.P, K, sampled_loop, scope=problem.scope(), progress=progress)
    wc = None
    if worst_case:
        from polyrob.analysis.worst_case import wcgain

        wc = wcgain(problem.P, K, omega=omega, scope=problem.scope(), progress=progress)
    analysis = ControllerAnalysis(
        robust_stability=rs,
        robust_performance=rp,
        nominal_performance=float(npf),
        sampling=sampling,
        order=controller_order(K),
        covers=str(
            sampled.certificate.scope.sentence()
            if sampled is not None
            else cells.certificate.scope.sentence()
            if cells is not None and cells.certified
            else covers
        ),  # the verdict's
        time_varying=tv,
        moving=mv,
        margin=margin,
        sampled=sampled,
        true_robots=true_robots,
        worst_case=wc,
        frozen_cells=cells,
    )
    if sampled is not None and not sampled.certificate.certified and margin is None:
        return replace(analysis, instead=sampled.instead_line(rp.certificate))
    if margin is None:
        return analysis
    return replace(analysis, instead=instead_line(problem, analysis, limit))
