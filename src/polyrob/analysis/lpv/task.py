"""The moving robot on a task domain: scheduled on positions, velocities and accelerations.

On a task domain (:class:`~polyrob.domains.task.TaskDomain`) the torque is
the inverse dynamics of the motion, ``u = M(q) qddot + C(q, qdot) qdot +
g(q) + D qdot``, so the Jacobians of the forward dynamics at ``(q, qdot, u)``
are functions of ``(q, qdot, qddot)``:

.. math:: A = A(q, \\dot q, \\ddot q), \\qquad B = B(q),

affine in ``qddot`` (``df/dq`` is affine in ``u``, ``u`` affine in
``qddot``).  :func:`task_scheduling` schedules the loop on the positions
that enter, the velocities and the accelerations, with the task's rates:
``dq/dt = qdot`` and ``dqdot/dt = qddot`` exactly at every grid point (the
next parameter's value), ``|dqddot/dt| <= jerk`` (:func:`minimum_jerk_bound`
by default, ``--qdddot-max`` otherwise).

The Lyapunov matrix ``X`` of :func:`task_motion_certificate` does not depend
on the accelerations: the bounded-real LMI at a point is then affine in
``qddot`` (the plant, and the rate term ``dX/dqdot . qddot``), so its two
ends per joint carry every acceleration between them exactly, and the
certificate holds for **any jerk**: the jerk bound is not used by it (it
says so), and is there for an ``X`` that follows the accelerations.

Minimum-jerk default (:func:`minimum_jerk_bound`): a rest-to-rest move of
size ``D`` in time ``T`` along ``q = D (10 s^3 - 15 s^4 + 6 s^5)``,
``s = t/T``, peaks at ``|qdot| = 1.875 D/T``, ``|qddot| = 5.7735 D/T^2``
(``10/sqrt 3``), ``|qdddot| = 60 D/T^3``.  The move of the task that reaches
its velocity bound ``v`` and its acceleration bound ``a`` together has
``T = (10/sqrt 3) v / (1.875 a)`` and jerk ``60 D/T^3 = (27/8) a^2 / v``; when
that move is longer than the task's range ``2 r``, the move over the range at
the acceleration bound (``T = sqrt(5.7735 * 2 r / a)``, jerk ``120 r / T^3``).
A shorter move at the same acceleration has a larger jerk: the default is a
planning convention, not a bound of every motion of the task.

Examples
--------
>>> import numpy as np, polyrob
>>> from polyrob.domains.task import TaskDomain
>>> robot = polyrob.load_robot("planar_2r")
>>> task = TaskDomain.from_robot(robot, pose=[0.0, 1.5708], q_radius=0.5, qdot_max=1.0, qddot_max=2.0)
>>> minimum_jerk_bound(task).tolist()           # (27/8) a^2 / v
[13.5, 13.5]
>>> model = task_scheduling(robot, task, points=(3, 3))
>>> model.names
('q2', 'qdot1', 'qdot2', 'qddot1', 'qddot2')
>>> rho = np.array([1.7, 0.3, -0.5, 1.0, -2.0])
>>> u = robot.inverse_dynamics([0.0, 1.7], [0.3, -0.5], [1.0, -2.0])[0]
>>> bool(np.allclose(model.plant(rho)[0], robot.jacobians([0.0, 1.7], [0.3, -0.5], u)[0]))
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from polyrob.analysis.lpv.robot import MovingRobotModel
from polyrob.errors import ArgumentError, NotApplicable, SolverError

__all__ = [
    "TaskMotionModel",
    "task_scheduling",
    "recheck_points",
    "minimum_jerk_bound",
    "jerk_bounds",
    "task_rate_bounds",
    "task_motion_certificate",
    "any_rate_motion_certificate",
    "MIN_JERK_VELOCITY",
    "MIN_JERK_ACCELERATION",
    "MIN_JERK_JERK",
    "AUTO_STATES",
]

#: Peaks of the minimum-jerk move ``D (10 s^3 - 15 s^4 + 6 s^5)`` per ``D/T``, ``D/T^2``, ``D/T^3``.
MIN_JERK_VELOCITY = 1.875
MIN_JERK_ACCELERATION = 10.0 / np.sqrt(3.0)
MIN_JERK_JERK = 60.0
#: Largest closed loop (states) the task's rate-bounded search runs on by default (``analyze``, ``run``).  The main
#: job's 16-state loop runs on ``--moving`` only: its search (the structured solver, X on the positions) takes about
#: as long as the rest of the job and proves no bound below 1 (moving_task records, docs/certificates.md); a larger
#: loop also takes the structured solver (``solver="auto"``).
AUTO_STATES = 8
#: Search grid (points per position, per velocity; the accelerations: their two ends) and its re-check, the least
#: one (``recheck="auto"``: at least this, and twice as dense as the search grid along positions and velocities).
DEFAULT_POINTS = (5, 3)
DEFAULT_RECHECK = (9, 5)
#: With cells: rounds of adding the re-check grid's points where the searched X fails (constraint generation), and
#: at most this many points per round: an X fitted at three points per velocity may fail midway between them, and
#: the cells then stop at once (tests/test_task_cells.py).
RECHECK_ROUNDS = 3
ROUND_POINTS = 40


def recheck_points(points) -> tuple[int, int]:
    """The re-check grid of ``recheck="auto"``: :data:`DEFAULT_RECHECK` or finer, twice as dense as ``points``.

    Every search point and one point midway between each two neighbours, along
    the positions and along the velocities.  A fixed grid is not finer than a
    search grid as dense as itself (at ``points=(9, 3)`` a fixed 9 x 3 was
    the search grid), and a re-check that kept the velocities' points passed
    ``X`` that fail midway between them (the main job's loop with ``--as 0.3``,
    ``benchmarks/results/moving_task.json``).

    Examples
    --------
    >>> recheck_points((5, 3)), recheck_points((9, 3)), recheck_points((3, 2))
    ((9, 5), (17, 5), (9, 5))
    """
    q, v = (2 * (int(n) - 1) + 1 for n in points)
    return max(DEFAULT_RECHECK[0], q), max(DEFAULT_RECHECK[1], v)


def minimum_jerk_bound(domain) -> np.ndarray:
    """Per joint, the peak jerk of the task's fastest minimum-jerk move (module docstring): ``(27/8) a^2 / v``.

    ``a``, ``v``: the task's acceleration and velocity bounds; a move longer than
    the position range ``2 r`` is replaced by the move over the range at the
    acceleration bound.  A joint that cannot move (``a = 0`` or ``v = 0`` or no
    range) gets ``0``.
    """
    a = np.maximum(np.abs(domain.qddot_lower), np.abs(domain.qddot_upper)).astype(float)
    v = np.maximum(np.abs(domain.qdot_lower), np.abs(domain.qdot_upper)).astype(float)
    span = np.asarray(domain.q_upper, float) - np.asarray(domain.q_lower, float)
    out = np.zeros_like(a)
    for j in range(a.size):
        if a[j] <= 0 or v[j] <= 0 or span[j] <= 0:
            continue
        T = MIN_JERK_ACCELERATION * v[j] / (MIN_JERK_VELOCITY * a[j])  # both bounds reached
        D = v[j] * T / MIN_JERK_VELOCITY
        if D > span[j]:  # longer than the range: the move over the range at the acceleration bound
            D = span[j]
            T = np.sqrt(MIN_JERK_ACCELERATION * D / a[j])
        out[j] = MIN_JERK_JERK * D / T**3
    return out


def jerk_bounds(value, m: int) -> np.ndarray:
    """``(m,)`` jerk bounds from a number or ``m`` numbers, each finite and >= 0 (:class:`ArgumentError` otherwise)."""
    arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if arr.size == 1:
        arr = np.full(m, float(arr[0]))
    if arr.size != m:
        raise ArgumentError(f"--qdddot-max: give 1 or {m} jerk bounds (rad/s^3), got {arr.size}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ArgumentError(f"--qdddot-max: jerk bounds must be finite and >= 0 (rad/s^3), got {arr.tolist()}")
    return arr


@dataclass(frozen=True, eq=False)
class TaskMotionModel(MovingRobotModel):
    """:class:`~polyrob.analysis.lpv.robot.MovingRobotModel` with accelerations: kinds ``q``, ``qdot``, ``qddot``.

    Attributes
    ----------
    jerk : ndarray
        ``(m,)`` bounds of ``|d qddot_j/dt|``.
    jerk_source : str
        Where they come from.
    """

    jerk: np.ndarray = None
    jerk_source: str = ""

    def motion(self, rho) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, qdot, qddot)`` at the parameter point ``rho`` (the fixed joints at the task's midpoint, rest)."""
        m = self.robot.m
        out = {"q": self.q_fixed.copy(), "qdot": np.zeros(m), "qddot": np.zeros(m)}
        for value, kind, j in zip(np.asarray(rho, float), self.kinds, self.joints):
            out[kind][j] = value
        return out["q"], out["qdot"], out["qddot"]

    def state(self, rho) -> tuple[np.ndarray, np.ndarray]:
        q, qdot, _ = self.motion(rho)
        return q, qdot

    def torque(self, rho) -> np.ndarray:
        """``u`` by inverse dynamics at ``rho``."""
        return np.asarray(self.robot.inverse_dynamics(*self.motion(rho)), float).reshape(-1)

    def plant(self, rho) -> tuple[np.ndarray, np.ndarray]:
        """The Jacobians ``(A, B)`` of the forward dynamics at ``(q, qdot, u(q, qdot, qddot))``."""
        q, qdot, _ = self.motion(rho)
        return self.robot.jacobians(q, qdot, self.torque(rho))

    def words(self) -> str:
        sizes = " x ".join(str(a.size) for a in self.axes)
        return (
            f"{sizes} = {self.n_points} points of ({', '.join(self.names)}; the accelerations at the ends of their "
            "ranges, exact for X free of them)"
        )


def _enters(robot, domain, j: int, rng) -> bool:
    """Does joint position ``j`` enter the Jacobians along the task (a few random task states)?"""
    for _ in range(4):
        q = rng.uniform(domain.q_lower, domain.q_upper)
        qd = rng.uniform(domain.qdot_lower, domain.qdot_upper)
        qdd = rng.uniform(domain.qddot_lower, domain.qddot_upper)
        q2 = q.copy()
        q2[j] += 0.7
        A, B = robot.jacobians(q, qd, robot.inverse_dynamics(q, qd, qdd)[0])
        A2, B2 = robot.jacobians(q2, qd, robot.inverse_dynamics(q2, qd, qdd)[0])
        scale = max(np.abs(A).max(), np.abs(B).max(), 1.0)
        if max(np.abs(A2 - A).max(), np.abs(B2 - B).max()) > 1e-12 * scale * (robot.m + 1):
            return True
    return False


def task_scheduling(robot, domain, *, points=DEFAULT_POINTS, jerk=None, max_joints: int = 3) -> TaskMotionModel:
    """The scheduling parameters of ``robot`` on the task ``domain`` and their grid.

    Parameters
    ----------
    robot : Manipulator
        An analytic robot or a Pinocchio one of at most ``max_joints`` joints.
    domain : TaskDomain
    points : (int, int)
        Grid points per position and per velocity parameter; each acceleration
        gets the two ends of its range.
    jerk : float or array_like, optional
        ``|d qddot/dt|`` bounds (default :func:`minimum_jerk_bound`).
    max_joints : int

    Raises
    ------
    NotApplicable
        Not a task domain, a robot with an inner layer (the any-rate route
        covers those) or too many joints.
    ArgumentError
        A negative or NaN jerk bound.
    """
    if getattr(domain, "kind", "") != "task" or not hasattr(domain, "qddot_upper"):
        raise NotApplicable("not a task domain (q, qdot, qddot bounded, torques by inverse dynamics)")
    if getattr(robot, "inner", None) is not None or type(robot).__name__.startswith("Inner"):
        raise NotApplicable("an inner loop: the task's scheduled grid is for a robot without one")
    m = robot.m
    if m > max_joints:
        raise NotApplicable(f"{m} joints: the task's scheduled grid is built for at most {max_joints}")
    if jerk is None:
        jerk_arr, source = minimum_jerk_bound(domain), "the task's minimum-jerk move, (27/8) qddot_max^2 / qdot_max"
    else:
        jerk_arr, source = jerk_bounds(jerk, m), "given (--qdddot-max)"
    rng = np.random.default_rng(0)
    names, kinds, joints, axes = [], [], [], []
    groups = (
        ("q", domain.q_lower, domain.q_upper, int(points[0])),
        ("qdot", domain.qdot_lower, domain.qdot_upper, int(points[1])),
        ("qddot", domain.qddot_lower, domain.qddot_upper, 2),
    )
    for kind, lo, hi, n in groups:
        for j in range(m):
            if hi[j] <= lo[j] or (kind == "q" and not _enters(robot, domain, j, rng)):
                continue
            names.append(f"{kind}{j + 1}"), kinds.append(kind), joints.append(j)
            axes.append(np.linspace(float(lo[j]), float(hi[j]), n))
    if not names:
        raise NotApplicable("the Jacobians do not vary over the task: the frozen-robot certificate covers it")
    mid = 0.5 * (np.asarray(domain.q_lower, float) + np.asarray(domain.q_upper, float))
    return TaskMotionModel(
        robot, tuple(names), tuple(kinds), tuple(joints), tuple(axes), mid, np.zeros(m),
        jerk=jerk_arr, jerk_source=source,
    )  # fmt: skip


def task_rate_bounds(model: TaskMotionModel, domain, *, scale: float = 1.0):
    """Bounds of ``d rho_i/dt``: the task's velocities, accelerations and the jerk bound (times ``scale``)."""
    bound = {
        "q": np.maximum(np.abs(domain.qdot_lower), np.abs(domain.qdot_upper)),
        "qdot": np.maximum(np.abs(domain.qddot_lower), np.abs(domain.qddot_upper)),
        "qddot": np.asarray(model.jerk, float),
    }
    return [(-b, b) for b in (float(bound[k][j]) * scale if scale else 0.0 for k, j in zip(model.kinds, model.joints))]


def _rate_words(model: TaskMotionModel, rates, x_uses_accelerations: bool) -> str:
    parts = []
    nxt = {"q": "qdot", "qdot": "qddot"}
    for name, kind, j, (_lo, hi) in zip(model.names, model.kinds, model.joints, rates):
        succ = f"{nxt.get(kind, '')}{j + 1}"
        if kind in nxt and succ in model.names:
            parts.append(f"d{name}/dt = {succ} (|d{name}/dt| <= {hi:.4g})")
        elif kind == "qddot" and not x_uses_accelerations:
            parts.append(f"d{name}/dt any (jerk not needed; {hi:.4g} from {model.jerk_source})")
        else:
            parts.append(f"|d{name}/dt| <= {hi:.4g}" if np.isfinite(hi) else f"d{name}/dt arbitrary")
    return ", ".join(parts)


def any_rate_motion_certificate(time_varying, domain_name: str = ""):
    """The moving-robot certificate a certified arbitrarily-fast one gives (any rate covers the task's), else ``None``."""
    from polyrob.analysis.lpv.moving_result import MovingRobotCertificate

    if time_varying is None or not time_varying.certificate.certified:
        return None
    cert = time_varying.certificate
    where = f" inside {domain_name!r}" if domain_name else " inside the domain"
    scope = replace(
        cert.scope,
        variation=f"the robot moving{where} at any rate (so with the task's rates: any velocity, acceleration and "
        f"jerk inside it), by the arbitrarily fast certificate [{time_varying.method}]",
    )
    return MovingRobotCertificate(
        computed=True,
        gamma=float(cert.bound),
        rate_words="any (covered by the arbitrarily fast certificate)",
        grid_words=f"the time-varying certificate [{time_varying.method}]",
        scope=scope,
        decided=replace(cert, scope=scope),
        seconds=float(time_varying.seconds),
    )


def task_motion_certificate(
    problem,
    K,
    *,
    points=DEFAULT_POINTS,
    jerk=None,
    auto: bool = False,
    velocities: str = "auto",
    recheck="auto",
    time_varying=None,
    lower_bound: bool | dict = True,
    harmonics: int = 1,
    level=None,
    cells: bool = False,
    cell_level: float | None = None,
    cell_time_limit: float | None = None,
    cell_workers: int | None = None,
    progress: bool = False,
    solver: str = "auto",
    recheck_rounds: int | None = None,
):
    """The moving-robot certificate of ``K`` on a task-domain ``problem``.

    When the arbitrarily fast certificate ``time_varying`` holds it decides
    (:func:`any_rate_motion_certificate`).  Otherwise the rate-bounded search:
    :func:`polyrob.lpvnorm` of the weighted closed loop on the task's grid
    (:func:`task_scheduling`), ``X`` on ``1, cos q_i, sin q_i`` (times ``1,
    qdot_j`` while the search has at most
    :data:`~polyrob.analysis.lpv.moving.BOUNDED_VARIABLES` scalars,
    ``velocities="auto"``; else the velocities move arbitrarily fast), the
    rates of :func:`task_rate_bounds` exact at each point, re-checked on a
    finer grid.  Proved at grid points only: GRID_ONLY
    (:func:`polyrob.analysis.certificate.decide_gridded_gain`); with ``cells``
    the same ``X`` is proved between them on cells covering the whole box of
    ``(q_i, qdot, qddot)`` (an analytic robot: the Jacobians' enclosures of
    :func:`~polyrob.bounds.certified.analytic.task_jacobian_enclosure`), and
    then the status is CERTIFIED.  It covers the linearised robot.

    Parameters
    ----------
    problem : Problem
        With a task domain.
    K : LTI
    points : (int, int)
    jerk : float or array_like, optional
        ``--qdddot-max``; default :func:`minimum_jerk_bound`.
    auto : bool
        Run the rate-bounded search only for a loop of at most :data:`AUTO_STATES` states.
    velocities : {"auto", "bounded", "arbitrary"}
    recheck : "auto", (int, int) or None
        The finer grid (points per position, per velocity) the ``X`` is re-checked on
        (``"auto"``: :func:`recheck_points`).
    time_varying : TimeVaryingCertificate, optional
    lower_bound : bool or dict
        The largest gain found along admissible motions of the task
        (:func:`~polyrob.analysis.time_varying.trajectory_gains.trajectory_lower_bound`;
        a dict: its options), computed whether or not the search runs: what
        no bound can go below, and on a loop too large for the search the
        one figure of the moving robot there is.
    harmonics : int
        ``cos k q_i, sin k q_i`` for ``k <= harmonics`` in the basis of ``X``.
    level : float, optional
        Fix the solver's ``gamma`` there and maximise the LMIs' margin: room
        for the cells between the grid points.
    cells : bool
        Prove ``X`` between the grid points (:func:`~polyrob.analysis.lpv.cells.check_cells`,
        at ``cell_level``, else as :func:`~polyrob.analysis.lpv.robot.cells_level` says); ``cell_time_limit``
        (a wall-clock safety net the caller sets), ``cell_workers`` and
        ``progress`` as for :func:`~polyrob.analysis.lpv.moving.moving_robot_certificate`.
    solver : {"auto", "clarabel", "structured", "scs"}
        The search's LMI solver (:func:`polyrob.lpvnorm`'s).  ``"auto"``
        (default): the structured interior point for a loop of more than
        :data:`AUTO_STATES` states, Clarabel up to that.  On the main job's
        16-state loop the structured one is about ten times faster and uses a
        fifth of the memory, for a lower bound (the records in
        docs/certificates.md, ``benchmarks/moving_task.py --solver``); on the
        small tasks of the tests (two points per velocity) its ``X``, of the
        same margin, failed between the points where Clarabel 0.10's held
        (:data:`~polyrob.analysis.lpv.robot.SEARCH_SOLVER`; with ``cells``
        the constraint generation below makes either hold).
    recheck_rounds : int, optional
        Rounds of constraint generation: the re-check grid's points where
        ``X`` is not proved at a level three quarters of the way from the
        grid's bound to the cells' are added to the search (at most
        :data:`ROUND_POINTS` a round) and it runs again (default
        :data:`RECHECK_ROUNDS` with ``cells``, else 0).

    Returns
    -------
    MovingRobotCertificate
    """
    from polyrob.analysis.certificate import Scope
    from polyrob.analysis.lpv.basis import basis_size, default_basis, finer_recheck
    from polyrob.analysis.lpv.moving import BOUNDED_VARIABLES, MAX_STATES, conditioned_time_scale
    from polyrob.analysis.lpv.moving_result import MovingRobotCertificate
    from polyrob.analysis.lpv.norm import lpvnorm
    from polyrob.analysis.lpv.robot import closed_loop_system, conditioned, kinematic_rates, phase_parts
    from polyrob.progress import span

    t0 = time.perf_counter()
    parts = phase_parts(cells)
    domain, P = problem.domain, problem.P
    base = problem.scope() if hasattr(problem, "scope") else Scope()
    if jerk is not None:
        jerk = jerk_bounds(jerk, problem.robot.m)  # refused before any work
    decided = any_rate_motion_certificate(time_varying, getattr(domain, "name", ""))
    if decided is not None:
        return decided
    model = system = None
    try:
        model = task_scheduling(problem.robot, domain, points=points, jerk=jerk)
        system = closed_loop_system(model, K, P.W_S, P.W_T, P.W_KS)
        n = system(np.array([a[0] for a in model.axes]))[0].shape[0]
        limit = AUTO_STATES if auto else MAX_STATES
        if n > limit:
            more = ": --moving computes it (minutes)" if auto and n <= MAX_STATES else ""
            raise NotApplicable(
                f"the closed loop has {n} states (the task's rate-bounded search runs up to {limit}){more}"
            )
        rates = task_rate_bounds(model, domain)
        if solver == "auto":
            solver = "structured" if n > AUTO_STATES else "clarabel"
        if velocities == "auto":
            k = basis_size(model, tensor=True)
            velocities = "bounded" if k * n * (n + 1) // 2 <= BOUNDED_VARIABLES else "arbitrary"
        if velocities not in ("bounded", "arbitrary"):
            raise ArgumentError(f"velocities must be 'auto', 'bounded' or 'arbitrary' (got {velocities!r})")
        basis = default_basis(model, tensor=True, harmonics=harmonics)
        if velocities == "arbitrary":
            basis = basis[: 1 + 2 * harmonics * sum(kind == "q" for kind in model.kinds)]
            rates = [r if kind == "q" else (-np.inf, np.inf) for r, kind in zip(rates, model.kinds)]
        with span(*parts["search"]):
            result, sysf, cs = _search(model, system, rates, basis, lpvnorm, conditioned, conditioned_time_scale,
                                       kinematic_rates, level, solver)  # fmt: skip
        if isinstance(recheck, str):
            recheck = recheck_points(points)
        with span(*parts["recheck"]):
            finer = {} if recheck is None else finer_recheck(sysf, model, result, rates, basis, points=recheck, c=cs)
            added, rounds = (), (RECHECK_ROUNDS if cells else 0) if recheck_rounds is None else int(recheck_rounds)
            if recheck is not None and rounds > 0 and result.proved:
                from polyrob.analysis.lpv.robot import cells_level

                target = result.gamma + 0.75 * (cells_level(result.gamma, level, cell_level) - result.gamma)
                result, finer, added = _add_failing_points(model, sysf, cs, result, finer, rates, basis, recheck,
                                                           target, rounds, {"eps": 1e-4, "level": level,
                                                                            "solver": solver})  # fmt: skip
        between = None
        g_grid = max(result.gamma, finer.get("gamma", result.gamma))
        if cells and result.proved and g_grid < 1:
            from polyrob.analysis.lpv.cells import check_cells
            from polyrob.analysis.lpv.robot import cells_level

            # X is free of the accelerations: their rate (the jerk) does not enter, so no rate box for them
            used = [(-np.inf, np.inf) if kind == "qddot" else r for r, kind in zip(rates, model.kinds)]
            g_cells = cells_level(g_grid, level, cell_level)
            with span(*parts["cells"]):
                between = check_cells(model, system, result.X, basis, used, g_cells, similarity=getattr(
                    sysf, "similarity", None), c=cs, time_limit=cell_time_limit, progress=progress,
                    workers=cell_workers)  # fmt: skip
    except NotApplicable as exc:
        with span(*parts["lower"]):
            found = _found(model, system, domain, lower_bound) if system is not None else {}
        return replace(MovingRobotCertificate.not_computed(str(exc)), lower=found, seconds=time.perf_counter() - t0)
    with span(*parts["lower"]):
        found = _found(model, system, domain, lower_bound)
    x_on_acc = False  # default_basis has no acceleration functions: the LMI is affine in qddot
    words = _rate_words(model, task_rate_bounds(model, domain), x_on_acc) + (
        "; the velocities at any rate (X on the positions only)" if velocities == "arbitrary" else ""
    )
    again = f" and the same X re-checked at the {finer['points']} points of a finer grid" if finer.get("points") else ""
    proved_between = between is not None and between.holds
    if proved_between:
        grid_note = (f"the LMIs on the grid of {model.words()}{again}, and the same X between the grid points: "
                     f"{between.words()} (guaranteed enclosures of the Jacobians over each cell)")  # fmt: skip
    else:
        grid_note = f"on the grid of {model.words()}{again}; not proved between the grid points" + (
            f" ({between.reason})" if between is not None else ""
        )
    if len(added):
        grid_note += (f"; {len(added)} points of the finer grid, where an earlier X failed, added to the search's "
                      "LMIs (constraint generation)")  # fmt: skip
    notes = (
        grid_note,
        "the linearised robot (LPV family A(rho(t)), B(rho(t))) with the torques of the task's inverse dynamics, "
        "not the nonlinear one",
    ) + tuple(result.notes) + tuple(base.notes)  # fmt: skip
    where = f" inside domain {base.domain!r}" if base.domain else ""
    scope = replace(
        base, variation=f"the linearised robot {base.robot} (LPV family){where} moving with rates {words}",
        robot="", domain="", model="", coverage=None, coverage_points=0,
        enclosure="proved" if proved_between else "sampled", vertices_from="", notes=notes,
    )  # fmt: skip
    gamma, why = float(result.gamma), () if result.proved else (result.reason,)
    if finer.get("points") and result.proved:
        gamma = max(gamma, float(finer["gamma"]))
        if not np.isfinite(gamma):
            why = (f"the X proved on the grid fails on the finer grid of {finer['points']} points: "
                   f"{finer.get('reason', '')}",)  # fmt: skip
    if proved_between:
        gamma = float(between.gamma)  # proved on the whole box: the number the verdict rests on
    return MovingRobotCertificate(
        computed=True, gamma=gamma, frozen_gamma=float(result.frozen_gamma),
        rates=tuple(task_rate_bounds(model, domain)), rate_words=words, grid_words=model.words(), result=result,
        scope=scope, notes=why, finer=finer, cells={} if between is None else between.summary(), lower=found,
        seconds=time.perf_counter() - t0,
    )  # fmt: skip


def _add_failing_points(model, sysf, cs, result, finer, rates, basis, recheck, target, rounds, options):
    """Constraint generation: ``(result, finer, points added)`` after up to ``rounds`` searches with the re-check
    grid's points where ``X`` is not proved at ``target`` added (a round's result is kept only when proved)."""
    from polyrob.analysis.lpv.basis import failing_points, finer_recheck
    from polyrob.analysis.lpv.norm import lpvnorm
    from polyrob.analysis.lpv.robot import kinematic_rates

    added = np.zeros((0, len(model.axes)))
    scaled = [(lo / cs, hi / cs) for lo, hi in rates]
    for _ in range(int(rounds)):
        new = failing_points(sysf, model, result, rates, basis, points=recheck, c=cs, level=target, most=ROUND_POINTS)
        if not len(new):
            break
        more = np.vstack([added, new])
        try:
            again = lpvnorm(sysf, list(model.axes), scaled, basis, rates_at=kinematic_rates(model, rates, cs),
                            points=more, **options)  # fmt: skip
        except SolverError:
            break
        if not again.proved:
            break
        result, added = again, more
        finer = finer_recheck(sysf, model, result, rates, basis, points=recheck, c=cs)
    return result, finer, added


def _found(model, system, domain, lower_bound) -> dict:
    """The summary of the largest gain found along the task's admissible motions (``{}`` when not asked or none)."""
    if not lower_bound:
        return {}
    from polyrob.analysis.time_varying.trajectory_gains import trajectory_lower_bound

    opts = lower_bound if isinstance(lower_bound, dict) else {}
    try:
        return trajectory_lower_bound(model, system, task_rate_bounds(model, domain), **opts).summary()
    except NotApplicable:  # a frozen loop at rest is unstable: no finite gain to find
        return {}


def _search(model, system, rates, basis, lpvnorm, conditioned, time_scale, kinematic_rates, level=None,
            solver="clarabel"):  # fmt: skip
    """``(result, the system it ran on, its time scale)``: the conditioned copy first, then the time-scaled loop; a
    proved result is searched again in the coordinates of its own ``X`` (:func:`~polyrob.analysis.lpv.robot.refine`)."""
    from polyrob.analysis.lpv.result import LpvNormResult

    centre = np.array([0.5 * (a[0] + a[-1]) for a in model.axes])
    tries = []
    try:
        tries.append((*conditioned(system, centre), {"eps": 1e-4, "level": level, "solver": solver}))
    except NotApplicable:
        pass
    c = time_scale(system, centre)

    def time_scaled(rho):
        a, b, cc, d = system(rho)
        return a / c, b / c, cc, d

    tries.append((time_scaled, c, {"level": level, "solver": solver}))

    def solve(sysf, cs, options):
        scaled = [(lo / cs, hi / cs) for lo, hi in rates]
        try:
            return lpvnorm(sysf, list(model.axes), scaled, basis, rates_at=kinematic_rates(model, rates, cs), **options)
        except SolverError as exc:
            return LpvNormResult.solver_failed(model.n_points, str(exc))

    from polyrob.analysis.lpv.robot import in_progress_parts, refine

    solve = in_progress_parts(solve)  # the whole job's line moves with each solve
    best = None
    for sysf, cs, options in tries:
        r = solve(sysf, cs, options)
        if best is None or r.gamma < best[0].gamma:
            best = (r, sysf, cs, options)
        if r.proved:
            break
    return refine(best, solve, basis, centre)[:3]
