"""The moving-robot certificate: robust performance of the linearised robot moving within the domain's rates.

The third certificate beside μ (each frozen robot) and the time-varying one
(arbitrarily fast variation, :mod:`polyrob.analysis.time_varying.certificate`):
the weighted closed loop ``r -> z`` of :func:`~polyrob.analysis.lpv.robot.closed_loop_system`,
scheduled on the robot's state ``rho = (q_i that enter, qdot)``
(:func:`~polyrob.analysis.lpv.robot.scheduling`), has a proved induced L2
gain ``gamma`` (:func:`polyrob.lpvnorm`, parameter-dependent Lyapunov matrix
``X(rho)`` on :func:`~polyrob.analysis.lpv.basis.default_basis`) for every
trajectory of ``rho`` in the domain whose rates stay within the bounds of
:func:`~polyrob.analysis.lpv.robot.rate_bounds`, a position moving at its
own velocity at every grid point (``dq_i/dt = qdot_i``,
:func:`~polyrob.analysis.lpv.robot.kinematic_rates`).  For a large loop
(``velocities="auto"``) ``X`` depends on the positions only and the
velocities may vary arbitrarily fast: a set of trajectories that contains
the bounded-acceleration one, searched with fewer variables and LMIs
(:func:`moving_robot_gain`).  The returned ``X`` is re-checked at the
points of a finer grid (:func:`~polyrob.analysis.lpv.basis.finer_recheck`)
and ``gamma`` is the larger of the two grids' levels (a basis rich enough
to follow the loops also fits the grid).  Robust performance is
``gamma < 1``; the status is decided by
:func:`polyrob.analysis.certificate.decide_gridded_gain`: the LMIs hold at
the grid's points, so a proved ``gamma < 1`` gives GRID_ONLY, not CERTIFIED
(no guarantee between the grid points is available for these
non-affine Jacobians).

It covers the **linearised** robot (the LPV family ``A(rho(t)), B(rho(t))``),
not the nonlinear one: a trajectory's perturbation obeys this family only to
first order.

Examples
--------
>>> from polyrob.analysis.lpv.moving import MovingRobotCertificate
>>> c = MovingRobotCertificate.not_computed("asked not to (--no-moving)")
>>> c.verdict
'moving robot: robust performance not computed (asked not to (--no-moving))'
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from polyrob.analysis.lpv.moving_result import MovingRobotCertificate, rate_words
from polyrob.errors import ArgumentError, NotApplicable, SolverError

__all__ = ["MovingRobotCertificate", "moving_robot_certificate", "moving_robot_gain", "MAX_STATES", "AUTO_STATES"]

#: Largest closed loop (states) the moving-robot LMIs are built for.
MAX_STATES = 40
#: Largest ``X(rho)`` (scalar variables) searched with bounded accelerations by default (``velocities="auto"``).
BOUNDED_VARIABLES = 600
#: The finer grid the returned ``X`` is re-checked on: this many times as many intervals per position, per
#: velocity as the search's grid (every axis finer: a position grid of the search's size would leave its
#: intervals unchecked, and the Jacobians vary most along the positions).
RECHECK_REFINE = (4, 2)
#: Largest closed loop computed by default (``moving=None``): measured cost in docs/certificates.md.
AUTO_STATES = 8


def _velocity_mode(velocities: str, model, n: int, tensor: bool = True, harmonics: int = 1) -> str:
    """``"bounded"`` or ``"arbitrary"`` (``"auto"``: bounded while the search has at most :data:`BOUNDED_VARIABLES` scalars)."""
    from polyrob.analysis.lpv.basis import basis_size

    if velocities not in ("auto", "bounded", "arbitrary"):
        raise ArgumentError(f"velocities must be 'auto', 'bounded' or 'arbitrary' (got {velocities!r})")
    if velocities != "auto":
        return velocities
    k = basis_size(model, tensor=tensor, harmonics=harmonics)
    return "bounded" if k * n * (n + 1) // 2 <= BOUNDED_VARIABLES else "arbitrary"


def moving_robot_gain(
    model,
    system,
    rates,
    *,
    quadratic: bool = False,
    velocities: str = "bounded",
    tensor: bool = True,
    harmonics: int = 1,
):
    """:func:`polyrob.lpvnorm` of ``system`` on ``model``'s grid, conditioned (:func:`~polyrob.analysis.lpv.robot.conditioned`).

    ``rates`` with every bound infinite gives a constant ``X`` (arbitrarily
    fast variation).  Otherwise a position's rate is its velocity at each grid
    point (:func:`~polyrob.analysis.lpv.robot.kinematic_rates`) and
    ``velocities`` says how the velocities move: ``"bounded"`` (``X(rho)``
    on :func:`~polyrob.analysis.lpv.basis.default_basis`, the tensor product
    ``{1, cos q_i, sin q_i} x {1, qdot_j}`` unless ``tensor=False``, the
    accelerations within ``rates``) or ``"arbitrary"`` (``X`` depends on the
    positions only, ``1, cos q_i, sin q_i``: the velocities may vary
    arbitrarily fast, which covers every acceleration bound, with fewer
    variables and LMIs).  A solver failure is returned as an unproved
    result, not raised.  ``harmonics=K``: ``cos k q_i, sin k q_i`` for ``k <= K``.
    """
    return _search(
        model, system, rates, quadratic=quadratic, velocities=velocities, tensor=tensor, harmonics=harmonics
    )[0]


def _search(model, system, rates, *, quadratic: bool, velocities: str, tensor: bool, harmonics: int = 1, level=None):
    """``(result, the system it was run on, its time scale, the basis or None, the rates)``."""
    from polyrob.analysis.lpv.basis import default_basis, even_functions
    from polyrob.analysis.lpv.norm import lpvnorm
    from polyrob.analysis.lpv.result import LpvNormResult
    from polyrob.analysis.lpv.robot import SEARCH_SOLVER, conditioned, in_progress_parts, kinematic_rates, refine

    centre = np.array([0.5 * (a[0] + a[-1]) for a in model.axes])
    rates = list(rates)
    basis = default_basis(model, quadratic=quadratic, tensor=tensor, harmonics=harmonics)
    if velocities == "arbitrary":
        basis = basis[: 1 + 2 * harmonics * sum(kind == "q" for kind in model.kinds)]
        rates = [r if kind == "q" else (-np.inf, np.inf) for r, kind in zip(rates, model.kinds)]
    if model.mirrored:  # an even X loses nothing when the loop is even: the average of X(rho) and X(-rho) works
        basis = even_functions(basis, [-a[-1] for a in model.axes], [a[-1] for a in model.axes])
    fast = all(not np.isfinite(hi) for _, hi in rates)
    c_sys = []
    try:  # the conditioned copy first: in the loop's own coordinates the solver stalls (docs/certificates.md)
        c_sys.append((*conditioned(system, centre), {"eps": 1e-4, "level": level, "solver": SEARCH_SOLVER}))
    except NotApplicable:
        pass
    c = conditioned_time_scale(system, centre)

    def time_scaled(rho):
        a, b, cc, d = system(rho)
        return a / c, b / c, cc, d

    c_sys.append((time_scaled, c, {"level": level, "solver": SEARCH_SOLVER}))

    def solve(sysf, cs, options):
        args = (None, None) if fast else ([(lo / cs, hi / cs) for lo, hi in rates], basis)
        extra = {} if fast else {"rates_at": kinematic_rates(model, rates, cs)}
        try:
            return lpvnorm(sysf, list(model.axes), *args, **options, **extra)
        except SolverError as exc:
            return LpvNormResult.solver_failed(model.n_points, str(exc))

    solve = in_progress_parts(solve)  # the whole job's line moves with each solve
    best = None
    for sysf, cs, options in c_sys:
        r = solve(sysf, cs, options)
        if best is None or r.gamma < best[0].gamma:
            best = (r, sysf, cs, options)
        if best[0].proved:
            break
    # searched again where its X is the identity at the centre (polyrob.analysis.lpv.robot.refine)
    r, sysf, cs, _ = refine(best, solve, None if fast else basis, centre)
    return r, sysf, cs, None if fast else basis, rates


def conditioned_time_scale(system, centre) -> float:
    """The power of two near the geometric mean of the slowest and fastest pole at ``centre``."""
    lam = np.abs(np.linalg.eigvals(system(np.asarray(centre, float))[0]))
    lam = lam[lam > 0] if np.any(lam > 0) else np.ones(1)
    return float(2.0 ** np.round(0.5 * np.log2(lam.min() * lam.max())))


def moving_robot_certificate(
    problem,
    K,
    *,
    points=(5, 3),
    rate_scale: float = 1.0,
    qddot_max=None,
    quadratic: bool = False,
    auto: bool = False,
    velocities: str = "auto",
    tensor: bool = True,
    harmonics: int = 1,
    recheck="auto",
    level=None,
    cells: bool = False,
    cell_level: float | None = None,
    cell_time_limit: float | None = None,
    cell_workers: int | None = None,
    symmetric: bool = False,
    progress: bool = False,
    lower_bound: bool | dict | None = None,
) -> MovingRobotCertificate:
    """The moving-robot certificate of ``K`` on ``problem`` (its robot, domain and weights).

    Parameters
    ----------
    problem : Problem
        ``robot``, ``domain``, ``P`` (its weights ``W_S, W_T, W_KS``) and ``scope()``.
    K : LTI
    points : (int, int)
        Grid points per position and per velocity parameter.
    rate_scale : float
        Multiplies the domain's rate bounds (``0``: frozen; ``inf``: arbitrarily fast).
    qddot_max : array_like, optional
        Acceleration bounds (default: a task domain's, else sampled over the domain).
    quadratic : bool
        Add the velocities' products to the basis of ``X``.
    auto : bool
        Compute it only for a closed loop of at most :data:`AUTO_STATES`
        states (the default of ``analyze`` and ``run``); a larger one says why not.
    velocities : {"auto", "bounded", "arbitrary"}
        How the velocities may move (:func:`moving_robot_gain`); ``"auto"``:
        bounded accelerations while ``X(rho)`` has at most
        :data:`BOUNDED_VARIABLES` scalar variables, else arbitrary.
    tensor : bool
        The tensor-product basis of ``X`` (:func:`~polyrob.analysis.lpv.basis.default_basis`).
    harmonics : int
        ``cos k q_i, sin k q_i`` for ``k <= harmonics`` in that basis.
    recheck : "auto", (int, int) or None
        The finer grid (points per position, per velocity) the returned ``X``
        is re-checked on (:func:`~polyrob.analysis.lpv.basis.finer_recheck`;
        sampled, the status stays GRID_ONLY); ``"auto"``: :data:`RECHECK_REFINE`
        times the search grid's intervals (at least 5 points per velocity); ``None``: not re-checked.
    level : float, optional
        Fix the solver's ``gamma`` there and maximise the LMIs' margin
        (:func:`polyrob.lpvnorm`'s option): an ``X`` well inside the feasible
        set, which a check between the grid points needs.
    cells : bool
        Prove the returned ``X`` between the grid points, on cells covering the
        whole box (:func:`~polyrob.analysis.lpv.cells.check_cells`, at
        ``cell_level``, else as :func:`~polyrob.analysis.lpv.robot.cells_level`
        says), bounded by its number of
        cells (``progress``: a bar); when it holds the status is CERTIFIED.
        ``cell_time_limit``: a wall-clock safety net the caller sets (default
        none), named in the verdict when it fires.  ``cell_workers``: the
        processes the cells run on (default: the available cores; 1: this
        process; the verdict does not depend on it).
    symmetric : bool or "auto"
        When the loop is even in ``rho`` on a symmetric box, search and prove
        on the half box with ``X`` on the even functions of the basis
        (:func:`~polyrob.analysis.lpv.robot.even_half`): ``points[0]`` counts
        the whole position axis, so the grid is as dense for half the points.
        ``"auto"``: the half box when the loop is even, else the whole box.
    lower_bound : bool or dict, optional
        Also the largest gain found along admissible trajectories of the box
        (:func:`~polyrob.analysis.time_varying.trajectory_gains.trajectory_lower_bound`; a dict:
        its options), printed beside the proved bound; default: with ``cells``.

    Returns
    -------
    MovingRobotCertificate
        ``computed=False`` (and why) when the domain or the loop is out of reach.
    """
    from polyrob.analysis.certificate import Scope
    from polyrob.analysis.lpv.basis import finer_recheck
    from polyrob.analysis.lpv.robot import closed_loop_system, even_half, phase_parts, rate_bounds, scheduling
    from polyrob.progress import span

    t0 = time.perf_counter()
    domain, P = problem.domain, problem.P
    if qddot_max is None and hasattr(domain, "qddot_upper"):
        qddot_max = np.maximum(np.abs(domain.qddot_lower), np.abs(domain.qddot_upper))
    try:
        model = scheduling(problem.robot, domain, points=points)
        system = closed_loop_system(model, K, P.W_S, P.W_T, P.W_KS)
        whole = model  # the trajectories of the lower bound run on the whole box
        if symmetric:
            try:
                model = even_half(model, system)
            except NotApplicable:
                if symmetric != "auto":
                    raise
        n = system(np.array([a[0] for a in model.axes]))[0].shape[0]
        if n > MAX_STATES:
            raise NotApplicable(f"the closed loop has {n} states (the LMIs are built for {MAX_STATES}): reduce K")
        if auto and n > AUTO_STATES:
            raise NotApplicable(
                f"the closed loop has {n} states, more than the {AUTO_STATES} computed by default: "
                "--moving computes it (minutes, docs/certificates.md)"
            )
        if np.isinf(rate_scale):
            rates, source = [(-np.inf, np.inf)] * len(model.names), "unbounded"
        else:
            rates, source = rate_bounds(model, domain, qddot_max=qddot_max, scale=rate_scale)
        mode = _velocity_mode(velocities, model, n, tensor, harmonics)
        if mode == "arbitrary" and not np.isinf(rate_scale):
            rates = [r if kind == "q" else (-np.inf, np.inf) for r, kind in zip(rates, model.kinds)]
        parts = phase_parts(cells)
        with span(*parts["search"]):
            result, sysf, cs, basis, used = _search(
                model, system, rates, quadratic=quadratic, velocities=mode, tensor=tensor, harmonics=harmonics,
                level=level,
            )  # fmt: skip
        if isinstance(recheck, str):
            recheck = (RECHECK_REFINE[0] * (points[0] - 1) + 1, max(5, RECHECK_REFINE[1] * (points[1] - 1) + 1))
        with span(*parts["recheck"]):
            finer = {} if recheck is None else finer_recheck(sysf, model, result, used, basis, points=recheck, c=cs)
        between = None
        g_grid = max(result.gamma, finer.get("gamma", result.gamma))
        if cells and result.proved and g_grid < 1:
            from polyrob.analysis.lpv.cells import check_cells
            from polyrob.analysis.lpv.robot import cells_level

            g_cells = cells_level(g_grid, level, cell_level)
            with span(*parts["cells"]):
                between = check_cells(model, system, result.X, basis, used, g_cells, similarity=getattr(
                    sysf, "similarity", None), c=cs, time_limit=cell_time_limit, progress=progress,
                    workers=cell_workers)  # fmt: skip
        found = {}
        if lower_bound or (lower_bound is None and cells):
            from polyrob.analysis.time_varying.trajectory_gains import trajectory_lower_bound

            try:
                opts = lower_bound if isinstance(lower_bound, dict) else {}
                with span(*parts["lower"]):
                    found = trajectory_lower_bound(whole, system, used, **opts).summary()
            except NotApplicable:  # a frozen loop at rest is unstable: no gain to find, the bound says so already
                found = {}
    except NotApplicable as exc:
        return MovingRobotCertificate.not_computed(str(exc))
    base = problem.scope() if hasattr(problem, "scope") else Scope()
    words = rate_words(model.names, rates, source)
    again = f" and the same X re-checked at the {finer['points']} points of a finer grid" if finer.get("points") else ""
    proved_between = between is not None and between.holds
    if proved_between:
        notes = (f"the LMIs on the grid of {model.words()}{again}, and the same X between the grid points: "
                 f"{between.words()} (guaranteed enclosures of the Jacobians over each cell)",)  # fmt: skip
    else:
        why_not = f" ({between.reason})" if between is not None else ""
        notes = (f"on the grid of {model.words()}{again}; not proved between the grid points{why_not}",)
    notes += (
        tuple(result.notes)
        + (
            "the linearised robot (LPV family A(rho(t)), B(rho(t))) with the domain's fixed torque, not the nonlinear one",
        )
        + tuple(base.notes)
    )
    where = f" inside domain {base.domain!r}" if base.domain else ""
    scope = replace(
        base,
        variation=f"the linearised robot {base.robot} (LPV family){where} moving with rates {words}",
        robot="",
        domain="",
        model="",
        coverage=None,
        coverage_points=0,
        enclosure="proved" if proved_between else "sampled",
        vertices_from="",
        notes=notes,
    )
    gamma, why = float(result.gamma), () if result.proved else (result.reason,)
    if finer.get("points") and result.proved:  # the verdict rests on both grids: the finer one may be worse
        gamma = max(gamma, float(finer["gamma"]))
        if not np.isfinite(gamma):
            why = (f"the X proved on the {model.n_points}-point grid fails on the finer grid of {finer['points']} "
                   f"points: {finer.get('reason', '')}",)  # fmt: skip
    if proved_between:
        gamma = float(between.gamma)  # proved on the whole box: the number the verdict rests on
    return MovingRobotCertificate(
        computed=True,
        gamma=gamma,
        frozen_gamma=float(result.frozen_gamma),
        rates=tuple(rates),
        rate_words=words,
        grid_words=model.words(),
        result=result,
        scope=scope,
        notes=why,
        finer=finer,
        cells={} if between is None else between.summary(),
        lower=found,
        seconds=time.perf_counter() - t0,
    )
