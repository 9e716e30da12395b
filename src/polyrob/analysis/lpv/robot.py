"""The moving robot as a gridded LPV system: the weighted closed loop scheduled on the robot's state.

The Jacobians ``A = df/dx``, ``B = df/du`` of a robot are exact functions of
its state.  For a domain with a fixed torque (the paper's domain: ``u = 0``)
they depend on the joint positions and velocities only, and not on every
position: a planar arm without gravity does not depend on ``q1``.  So the
robot linearised along a trajectory that stays in the domain is the LPV
system

.. math:: \\dot x = A(\\rho(t)) x + B(\\rho(t)) u, \\qquad y = [I\\ 0] x,

scheduled on ``rho = (q_i that enter, qdot)``; with the controller and the
weights of the mixed-sensitivity problem (:func:`polyrob.plant.generalized.generalized_plant`,
without the uncertainty channels) it gives the closed loop ``r -> z``
(:func:`closed_loop_system`) whose induced L2 gain :func:`polyrob.lpvnorm`
bounds for rates ``|d q_i/dt| <= qdot_max_i`` (the domain's velocities) and
``|d qdot_i/dt| <= qddot_max_i`` (sampled from the domain: ``qddot =
f(q, qdot, u)``; :func:`rate_bounds`).

Examples
--------
>>> import numpy as np, polyrob
>>> from polyrob.domains.torque_box import Domain
>>> robot = polyrob.load_robot("paper_2r")
>>> model = scheduling(robot, Domain.from_robot(robot, "paper"), points=(5, 3))
>>> model.names, [a.size for a in model.axes]
(('q2', 'qdot1', 'qdot2'), [5, 3, 3])
>>> A, B = model.plant(np.array([0.5, 1.0, -2.0]))
>>> bool(np.allclose(A, robot.jacobians([0.0, 0.5], [1.0, -2.0], [0.0, 0.0])[0]))
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError, NotApplicable

__all__ = ["MovingRobotModel", "scheduling", "rate_bounds", "closed_loop_system", "kinematic_rates", "conditioned",
           "reconditioned", "refine", "in_progress_parts", "phase_parts", "SOLVE_PARTS", "cells_level",
           "REFINE_PASSES", "SEARCH_SOLVER", "REFINE_GAIN", "even_half", "RATE_SAMPLES", "RATE_MARGIN"]  # fmt: skip

#: Domain points the acceleration bounds are sampled on (Sobol, plus the grid's corners).
RATE_SAMPLES = 4096
#: Factor on the sampled acceleration peaks (a sampled maximum is a bound from below).
RATE_MARGIN = 1.05
#: Relative change of the Jacobians below which a joint position does not enter them.
_ENTERS_RTOL = 1e-12
#: The parameter kind that is the time derivative of another (a task model schedules on accelerations too).
_DERIVATIVE = {"q": "qdot", "qdot": "qddot"}


@dataclass(frozen=True, eq=False)
class MovingRobotModel:
    """The scheduling parameters of a robot on a domain and their grid.

    Attributes
    ----------
    robot : Manipulator
    names : tuple of str
        ``"q2"``, ``"qdot1"``, ...: the parameters, positions first.
    kinds : tuple of str
        ``"q"`` or ``"qdot"`` per parameter.
    joints : tuple of int
        The joint (0-based) of each parameter.
    axes : tuple of ndarray
        The grid of each parameter (its box is the domain's range).
    q_fixed : ndarray
        Positions of the joints that do not enter the Jacobians (the domain's midpoint).
    u : ndarray
        The domain's fixed torque.
    """

    robot: object
    names: tuple
    kinds: tuple
    joints: tuple
    axes: tuple
    q_fixed: np.ndarray
    u: np.ndarray
    mirrored: bool = False

    @property
    def n_points(self) -> int:
        return int(np.prod([a.size for a in self.axes]))

    def state(self, rho) -> tuple[np.ndarray, np.ndarray]:
        """``(q, qdot)`` of the robot at the parameter point ``rho``."""
        q, qdot = self.q_fixed.copy(), np.zeros(self.robot.m)
        for value, kind, j in zip(np.asarray(rho, float), self.kinds, self.joints):
            (q if kind == "q" else qdot)[j] = value
        return q, qdot

    def plant(self, rho) -> tuple[np.ndarray, np.ndarray]:
        """The robot's Jacobians ``(A, B)`` at ``rho``."""
        q, qdot = self.state(rho)
        return self.robot.jacobians(q, qdot, self.u)

    def words(self) -> str:
        """The grid in words: ``5 x 3 x 3 = 45 points of (q2, qdot1, qdot2)``."""
        sizes = " x ".join(str(a.size) for a in self.axes)
        half = (
            f", {self.names[0]} >= 0 (the loop is even in rho: the other half by rho -> -rho)" if self.mirrored else ""
        )
        return f"{sizes} = {self.n_points} points of ({', '.join(self.names)}){half}"


def even_half(model: MovingRobotModel, system, *, samples: int = 8, rtol: float = 1e-10) -> MovingRobotModel:
    """``model`` on the half of its box where the first parameter is >= 0, when the loop is even in ``rho``.

    For a symmetric box and ``system(-rho) == system(rho)`` (a planar arm without
    gravity at zero torque: ``f(-x) = -f(x)``), the LMIs at ``(rho, nu)`` and
    ``(-rho, -nu)`` coincide for a Lyapunov matrix on even functions of
    ``rho``, and the rate boxes are symmetric too (a position's rate is its
    velocity): the half box carries the whole proof, on a grid twice as dense
    for the same cost.  Raises :class:`NotApplicable` otherwise.
    """
    from dataclasses import replace

    lo = np.array([a[0] for a in model.axes])
    hi = np.array([a[-1] for a in model.axes])
    if not np.allclose(lo, -hi, rtol=0, atol=1e-12 * (1 + np.abs(hi).max())):
        raise NotApplicable("the state box is not symmetric about 0: no half-box symmetry")
    for rho in np.random.default_rng(0).uniform(lo, hi, size=(samples, lo.size)):
        for a, b in zip(system(rho), system(-rho)):
            if np.abs(a - b).max() > rtol * (1 + np.abs(a).max()):
                raise NotApplicable("the closed loop is not even in rho: no half-box symmetry")
    first = model.axes[0]
    axes = (np.linspace(0.0, first[-1], first.size // 2 + 1),) + tuple(model.axes[1:])
    return replace(model, axes=axes, mirrored=True)


def _enters(robot, domain, j: int, rng) -> bool:
    """Does joint position ``j`` enter the Jacobians (checked at a few random domain states)?"""
    m = robot.m
    for _ in range(4):
        q = rng.uniform(domain.q_lower, domain.q_upper)
        qdot = rng.uniform(domain.qdot_lower, domain.qdot_upper)
        A, B = robot.jacobians(q, qdot, domain.u_lower)
        q2 = q.copy()
        q2[j] += 0.7
        A2, B2 = robot.jacobians(q2, qdot, domain.u_lower)
        scale = max(np.abs(A).max(), np.abs(B).max(), 1.0)
        if max(np.abs(A2 - A).max(), np.abs(B2 - B).max()) > _ENTERS_RTOL * scale * (m + 1):
            return True
    return False


def scheduling(robot, domain, *, points=(9, 3), max_parameters: int = 3) -> MovingRobotModel:
    """The scheduling parameters of ``robot`` on ``domain`` and their tensor grid.

    Parameters
    ----------
    robot : Manipulator
    domain : Domain
        With a fixed torque (``u_lower == u_upper``).
    points : (int, int)
        Grid points per position and per velocity parameter.
    max_parameters : int
        Largest number of parameters (the grid grows like ``points^p``).

    Returns
    -------
    MovingRobotModel

    Raises
    ------
    NotApplicable
        The torque varies in the domain (the Jacobians would depend on it, or
        on the accelerations of a task domain), or too many parameters.
    """
    u_lo, u_hi = np.asarray(domain.u_lower, float), np.asarray(domain.u_upper, float)
    if not np.array_equal(u_lo, u_hi):
        raise NotApplicable(
            "the torque varies in the domain: the Jacobians depend on it (scheduled here on positions and "
            "velocities only, for a domain with a fixed torque such as the paper's u = 0)"
        )
    rng = np.random.default_rng(0)
    q_lo, q_hi = np.asarray(domain.q_lower, float), np.asarray(domain.q_upper, float)
    v_lo, v_hi = np.asarray(domain.qdot_lower, float), np.asarray(domain.qdot_upper, float)
    names, kinds, joints, axes = [], [], [], []
    for j in range(robot.m):
        if q_hi[j] > q_lo[j] and _enters(robot, domain, j, rng):
            names.append(f"q{j + 1}"), kinds.append("q"), joints.append(j)
            axes.append(np.linspace(q_lo[j], q_hi[j], int(points[0])))
    for j in range(robot.m):
        if v_hi[j] > v_lo[j]:
            names.append(f"qdot{j + 1}"), kinds.append("qdot"), joints.append(j)
            axes.append(np.linspace(v_lo[j], v_hi[j], int(points[1])))
    if len(names) > max_parameters:
        raise NotApplicable(
            f"{len(names)} scheduling parameters ({', '.join(names)}): the grid is built for at most {max_parameters}"
        )
    if not names:
        raise NotApplicable("the Jacobians do not vary over the domain: the frozen-robot certificate covers it")
    return MovingRobotModel(robot, tuple(names), tuple(kinds), tuple(joints), tuple(axes), 0.5 * (q_lo + q_hi), u_lo)


def rate_bounds(model: MovingRobotModel, domain, *, qddot_max=None, samples: int = RATE_SAMPLES, scale=1.0):
    """Bounds of ``d rho_i/dt``: the domain's velocities for positions, accelerations for velocities.

    ``d q_i/dt = qdot_i`` lies in the domain's velocity range; ``d qdot_i/dt =
    qddot_i = f(q, qdot, u)`` is bounded by ``qddot_max`` when given (a task
    domain's), else by its largest value on ``samples`` Sobol points of the
    domain and the grid's points, times :data:`RATE_MARGIN` (a sampled bound).

    Parameters
    ----------
    model : MovingRobotModel
    domain : Domain
    qddot_max : array_like, optional
        ``(m,)`` acceleration bounds.
    samples : int
    scale : float
        Multiplies every bound (``0``: frozen; ``inf``: arbitrarily fast).

    Returns
    -------
    rates : list of (float, float)
    source : str
        How the acceleration bounds were obtained.
    """
    from scipy.stats import qmc

    robot, m = model.robot, model.robot.m
    if qddot_max is not None:
        acc, source = np.abs(np.asarray(qddot_max, float)).reshape(m), "given"
    else:
        lo = np.concatenate([domain.q_lower, domain.qdot_lower])
        hi = np.concatenate([domain.q_upper, domain.qdot_upper])
        z = qmc.scale(qmc.Sobol(2 * m, seed=0).random(int(samples)), lo, np.where(hi > lo, hi, lo + 1e-300))
        z = np.clip(z, lo, hi)
        grid = np.array(np.meshgrid(*model.axes, indexing="ij")).reshape(len(model.axes), -1).T
        states = [model.state(r) for r in grid] + [(s[:m], s[m:]) for s in z]
        acc = np.max([np.abs(robot.acceleration(q, qd, model.u)) for q, qd in states], axis=0) * RATE_MARGIN
        source = f"sampled on {len(states)} domain points, x {RATE_MARGIN}"
    vel = np.maximum(np.abs(domain.qdot_lower), np.abs(domain.qdot_upper))
    rates = []
    for kind, j in zip(model.kinds, model.joints):
        b = float((vel if kind == "q" else acc)[j]) * scale if scale else 0.0
        rates.append((-b, b))
    return rates, source


def kinematic_rates(model: MovingRobotModel, rates, c: float = 1.0):
    """``rho -> rate box at rho``: ``d q_j/dt = qdot_j`` exactly when ``qdot_j`` is a parameter too.

    Likewise ``d qdot_j/dt = qddot_j`` on a task model (:mod:`polyrob.analysis.lpv.task`).
    At a grid point where ``qdot_j = v`` the rate of ``q_j`` is ``v`` (times the
    factor by which ``rates`` scale the velocity bound, e.g. 0 for frozen), not
    any value in ``±qdot_max``; the other parameters keep ``rates``; all
    divided by the time scale ``c`` (:func:`conditioned`).

    Parameters
    ----------
    model : MovingRobotModel
    rates : sequence of (float, float)
        From :func:`rate_bounds`.
    c : float

    Returns
    -------
    callable
    """
    where = {(kind, j): i for i, (kind, j) in enumerate(zip(model.kinds, model.joints))}
    peak = {key: float(np.abs(model.axes[i]).max()) for key, i in where.items()}
    plan = []
    for i, (kind, j) in enumerate(zip(model.kinds, model.joints)):
        lo, hi = rates[i]
        nxt = (_DERIVATIVE.get(kind), j)  # a task's qdot moves at its qddot, as q at qdot
        exact = nxt in where and np.isfinite(hi) and peak.get(nxt, 0.0) > 0
        plan.append((where[nxt], hi / peak[nxt]) if exact else None)

    return KinematicRates(tuple(tuple(r) for r in rates), tuple(plan), c)


class KinematicRates:
    """``rho -> rate box at rho`` of :func:`kinematic_rates` (a class, not a closure: the cells' workers pickle it).

    ``exact[i]``: ``None`` (the rate of ``rho_i`` is any value of its box) or ``(w, slope)`` (it is
    ``slope * rho_w`` while inside its box), in the scaled time; what the cells use.
    """

    def __init__(self, rates, plan, c):
        self.rates, self.plan, self.c = rates, plan, c
        self.exact = [None if how is None else (how[0], how[1] / c) for how in plan]

    def __call__(self, rho):
        out = []
        for (lo, hi), how in zip(self.rates, self.plan):
            if how is None:
                out.append((lo / self.c, hi / self.c))
            else:
                v = min(max(rho[how[0]] * how[1], lo), hi) / self.c
                out.append((v, v))
        return out


def closed_loop_system(model: MovingRobotModel, K, W_S=None, W_T=None, W_KS=None):
    """``rho -> (A, B, C, D)``: the closed loop ``r -> z = [W_S e; W_T y; W_KS u]`` at the robot's state ``rho``.

    The realisation is :func:`~polyrob.analysis.time_varying.vertices.performance_vertices`'
    (the weights as :func:`polyrob.plant.generalized.generalized_plant`
    realises them, states ``[x, W_S, W_T, W_KS, x_K]``).
    """
    from polyrob.analysis.time_varying.vertices import controller_mats

    of_plant = LoopOfPlant(controller_mats(K, model.robot.m), W_S, W_T, W_KS)

    def system(rho):
        return of_plant(*model.plant(rho))

    system.of_plant = of_plant  # (A, B) of the robot -> the closed loop: affine (the check between points uses it)
    return system


class LoopOfPlant:
    """``(A, B) of the robot -> (A, B, C, D)`` of the closed loop (a class, not a closure: the cells' workers pickle it)."""

    def __init__(self, Kmats, W_S, W_T, W_KS):
        from polyrob.analysis.time_varying.vertices import weight_mats

        # the weights as (A, B, C, D) arrays: python-control's StateSpace does not pickle (a lambda of its
        # __init__), and the cells' workers receive this object; a weight that failed to pickle sent the cells
        # back to one process
        m = Kmats[3].shape[1]  # D_K: m x m
        self.Kmats = Kmats
        self.W_S, self.W_T, self.W_KS = (weight_mats(W, m, name) for W, name in ((W_S, "W_S"), (W_T, "W_T"),
                                                                                   (W_KS, "W_KS")))

    def __call__(self, A, B):
        from polyrob.analysis.time_varying.vertices import performance_vertices, vertex_set

        return tuple(
            x[0] for x in performance_vertices(vertex_set([(A, B)]), self.Kmats, self.W_S, self.W_T, self.W_KS)
        )


def _brl_solution(A, B, C, D, gamma: float, delta: float = 1e-6):
    """A strictly feasible bounded-real Lyapunov matrix at level ``gamma``, on the balanced copy of the states.

    The stabilising solution of ``A^T X + X A + C^T C + d I + (X B + C^T D) R^{-1} (B^T X + D^T C) = 0``,
    ``R = gamma^2 I - D^T D``, ``d = delta max|C^T C|`` (scipy's
    generalised-Schur Riccati solver), for the power-of-two balanced copy
    ``(S^-1 A S, S^-1 B, C S)``, ``S = diag(s)``; ``d > 0`` makes the
    bounded-real LMI strict (without it the solution lies on its boundary).
    It is returned in those coordinates: mapped back to the loop's own, its
    eigenvalues would drown in rounding.

    Returns
    -------
    Xb : ndarray
    s : ndarray
    """
    import scipy.linalg as sla

    from polyrob.analysis.lpv.norm import state_scaling

    s = state_scaling(A[None])
    Ab, Bb, Cb = A / s[:, None] * s[None, :], B / s[:, None], C * s[None, :]
    R = gamma**2 * np.eye(B.shape[1]) - D.T @ D
    Q = Cb.T @ Cb
    Q = Q + delta * max(1.0, float(np.abs(Q).max())) * np.eye(A.shape[0])
    try:
        Xb = sla.solve_continuous_are(Ab, Bb, Q, -R, s=Cb.T @ D)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise NotApplicable(f"bounded-real Riccati: {exc}") from exc
    Xb = 0.5 * (Xb + Xb.T)
    if not np.all(np.isfinite(Xb)) or np.linalg.eigvalsh(Xb)[0] <= 0:
        raise NotApplicable("bounded-real Riccati: no positive definite solution")
    return Xb, s


def conditioned(system, centre, *, floor: float = 1e-12, method: str = "gramian"):
    """A time-scaled, similarity-transformed copy of ``system`` with the same induced L2 gain.

    Stiff closed loops (poles from 1e-3 to 1e4 rad/s) defeat the LMI solver.
    Time ``tau = c t`` (``c`` a power of two near the geometric mean of the
    slowest and the fastest pole at the centre) maps
    ``(A, B, C, D)`` to ``(A/c, B/c, C, D)`` and every rate to ``rate/c``;
    the state similarity ``T = S Xb^{-1/2}`` makes ``Xb`` the identity:
    ``method="gramian"`` (the default), the observability Gramian at the
    centre point (``S = I``); ``method="riccati"``, a strict bounded-real
    Lyapunov matrix at the centre of the power-of-two balanced copy
    (``S``; :func:`_brl_solution`, level 1.5 times its H-infinity norm), so
    that the Lyapunov matrix there is a multiple of the identity
    (eigenvalues floored at ``floor`` times the largest); the Gramian gave
    the faster proof on the 20-state loop of docs/certificates.md.
    Both leave the gain of every trajectory unchanged; the proof of
    :func:`polyrob.lpvnorm` is made on the copy.

    Returns
    -------
    system_c : callable
        With the attribute ``similarity``: ``T`` (``x = T x~``).
    c : float
        The time scale (rates are divided by it).
    """
    import scipy.linalg as sla

    from polyrob.analysis.norms import hinf_norm

    A, B, C, D = system(np.asarray(centre, float))
    lam = np.abs(np.linalg.eigvals(A))
    lam = lam[lam > 0] if np.any(lam > 0) else np.ones(1)
    c = float(2.0 ** np.round(0.5 * np.log2(lam.min() * lam.max())))
    h = hinf_norm((A, B, C, D))
    if not np.isfinite(h):
        raise NotApplicable("the closed loop at the centre of the grid is unstable")
    s = np.ones(A.shape[0])
    if method == "riccati":
        Xb, s = _brl_solution(A, B, C, D, 1.5 * max(h, 1e-6))
    elif method == "gramian":
        Xb = sla.solve_continuous_lyapunov(A.T, -C.T @ C)
    else:
        raise ArgumentError(f"method must be 'gramian' or 'riccati' (got {method!r})")
    w, V = np.linalg.eigh(0.5 * (Xb + Xb.T))
    w = np.maximum(w, floor * w.max())
    # x = S x_b (balanced), x_b = Xb^-1/2 x~: T = S Xb^-1/2
    T, Ti = s[:, None] * ((V * w**-0.5) @ V.T), ((V * w**0.5) @ V.T) / s[None, :]

    def system_c(rho):
        a, b, cc, d = system(rho)
        return Ti @ (a / c) @ T, Ti @ (b / c), cc @ T, d

    system_c.similarity = T  # x = T x~: a Lyapunov matrix restricted to states S is (E_S T)^T Y (E_S T) here
    return system_c, c


def reconditioned(system_c, X_centre, *, floor: float = 1e-9):
    """``system_c`` in the coordinates where a Lyapunov matrix found for it is the identity at the grid's centre.

    The observability Gramian of :func:`conditioned` is a guess at the
    Lyapunov matrix; once a search has returned one, ``X_c`` at the centre,
    ``x~ = X_c^(1/2) x~~`` makes it the identity there, and a second search
    in those coordinates starts where the solver's accuracy is best.  On the
    main job's 16-state loop (poles from 0.002 to 4846 rad/s) the bound
    proved with ``X(q2)`` on two harmonics and ``q2`` moving at a hundredth of
    its rate fell from 3.88 to 0.686, the frozen peak being 0.685
    (``benchmarks/moving_task.py --parts``).  The similarities compose: the
    result's ``similarity`` maps to the original states, and its time scale
    is ``system_c``'s.

    Raises
    ------
    NotApplicable
        ``X_c`` is not positive definite.
    """
    Xc = 0.5 * (np.asarray(X_centre, float) + np.asarray(X_centre, float).T)
    w, V = np.linalg.eigh(Xc)
    if not w[0] > floor * max(w[-1], 0.0):
        raise NotApplicable("the Lyapunov matrix at the centre is not positive definite: nothing to re-condition on")
    T2, T2i = (V * w**-0.5) @ V.T, (V * w**0.5) @ V.T

    def system_cc(rho):
        a, b, cc, d = system_c(rho)
        return T2i @ a @ T2, T2i @ b, cc @ T2, d

    system_cc.similarity = getattr(system_c, "similarity", np.eye(Xc.shape[0])) @ T2
    return system_cc


#: Searches run again in the coordinates of the last proved ``X`` (:func:`~polyrob.analysis.lpv.robot.reconditioned`),
#: while each lowers the proved bound by at least :data:`REFINE_GAIN` of it.
REFINE_PASSES = 3
#: The LMI solver of the fixed-torque moving-robot search: the structured interior point (polyrob.analysis.lpv.sdp)
#: holds the grid's matrices only; the x4 certificates with Clarabel peaked at 5.9-10.2 GB and took 19-39 minutes,
#: mostly the search, which this solver runs in about 40 s and 0.5 GB (benchmarks/results/moving_robot.json).  The
#: task search keeps Clarabel: on the small tasks of the tests (two points per velocity) the structured solver's X,
#: of the same margin, held on the grid and failed between its points, where Clarabel 0.10's held (0.11's failed
#: too; the re-check grid's failing points added to the search make both hold: tests/test_task_cells.py).
SEARCH_SOLVER = "structured"
REFINE_GAIN = 0.02


def cells_level(g_grid: float, level=None, cell_level=None) -> float:
    """The level the cells prove the searched ``X`` at.

    ``cell_level`` when given; else the search's ``level`` when it is at or
    above ``g_grid`` (the larger of the search grid's and the finer grid's
    bounds); else halfway from ``g_grid`` to 1: room between the points, and
    a bound below 1.

    Examples
    --------
    >>> cells_level(0.8155, level=0.8, cell_level=0.85), cells_level(0.9, level=0.95), cells_level(0.9)
    (0.85, 0.95, 0.95)
    """
    if cell_level is not None:
        if not (np.isfinite(cell_level) and cell_level > 0):
            raise ArgumentError(f"the cells' level must be a positive number (got {cell_level})")
        return float(cell_level)
    if level is not None and level >= g_grid:
        return float(level)
    return 0.5 * (g_grid + 1.0)


#: The parts of the search's progress its successive solves fill: the first one, then the fallback and the
#: :func:`refine` passes (a hint for the job's line; the solves' own reports move it inside each part).
SOLVE_PARTS = (0.45, 0.65, 0.8, 0.9, 1.0)


def in_progress_parts(solve, parts=SOLVE_PARTS):
    """``solve`` whose ``k``-th call fills the part ``[parts[k-1], parts[k]]`` of the enclosing progress span.

    Calls past the last part fill nothing (the line stays where it is).

    Examples
    --------
    >>> import io
    >>> from polyrob.progress import JobProgress, report
    >>> job = JobProgress(["moving-robot"], stream=io.StringIO(), clock=lambda: 0.0)
    >>> job.start() is job and job._stop.set() is None
    True
    >>> job.begin(1, "moving-robot")
    >>> solve = in_progress_parts(lambda: report(1, 2), parts=(0.5, 1.0))
    >>> solve(); round(job.share, 3)       # the first call's part is done
    0.5
    >>> job.stop()
    """
    from polyrob.progress import span

    calls = [0]

    def run(*args, **kwargs):
        k = calls[0]
        calls[0] += 1
        lo = 0.0 if k == 0 else parts[min(k, len(parts)) - 1]
        with span(lo, parts[min(k, len(parts) - 1)]):
            return solve(*args, **kwargs)

    return run


def phase_parts(cells: bool) -> dict:
    """The parts of a moving-robot certificate's progress: the search, the finer re-check, the cells, the lower bound.

    Examples
    --------
    >>> phase_parts(True)["cells"], phase_parts(False)["cells"]
    ((0.45, 0.9), (0.85, 0.85))
    """
    if cells:
        return {"search": (0.0, 0.4), "recheck": (0.4, 0.45), "cells": (0.45, 0.9), "lower": (0.9, 1.0)}
    return {"search": (0.0, 0.75), "recheck": (0.75, 0.85), "cells": (0.85, 0.85), "lower": (0.85, 1.0)}


def refine(best, solve, basis, centre):
    """``best = (result, system, time scale, options)`` searched again where its ``X`` is the identity at the centre.

    ``solve(system, time scale, options)`` runs the search; ``basis`` the functions of ``X`` (``None``: a constant
    ``X``); ``centre`` the grid's centre.  At most :data:`REFINE_PASSES` passes, each kept only when it proves a
    lower bound, stopping once one gains less than :data:`REFINE_GAIN` of it.
    """
    for _ in range(REFINE_PASSES):
        r, sysf, cs, options = best
        if not r.proved:
            break
        f = np.array([float(fn(centre)) for fn, _ in basis]) if basis is not None else np.ones(1)
        X = np.asarray(r.X, float)
        try:
            again = reconditioned(sysf, np.einsum("k,kij->ij", f, X if X.ndim == 3 else X[None]))
        except NotApplicable:
            break
        r2 = solve(again, cs, options)
        if not (r2.proved and r2.gamma < r.gamma):
            break
        best = (r2, again, cs, options)
        if r2.gamma > (1.0 - REFINE_GAIN) * r.gamma:
            break
    return best
