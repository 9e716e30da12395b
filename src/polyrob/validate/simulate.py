"""The robot's true nonlinear dynamics in closed loop with the controller.

:func:`simulate` integrates ``xdot = f(x, u)`` of the robot itself (Pinocchio's
``aba`` with the URDF damping added, or an analytic model's formulas) with

* the continuous controller ``xK' = A_K xK + B_K e``, ``u = u_eq + C_K xK + D_K e``,
  ``e = r - q`` (one ODE for robot and controller, ``scipy.integrate.solve_ivp``), or
* its discretisation (``rate`` in Hz): ``e`` sampled every ``h = 1/rate``,
  the discrete controller updated and ``u`` held constant over each period
  (the robot integrated by ``solve_ivp`` from one sample to the next).

``u_eq`` is the torque of the PLDI's nominal (the equilibrium the linear
plant is the linearisation at: the gravity torque at ``q0``), so that the
controller's output is the deviation the linear design assumes.

The result reports per joint the rise time, overshoot, settling time and
steady-state error of a step, the peak torque against the effort limit and
whether the trajectory ``(q, qdot, u)`` ever left the domain over which the
PLDI was computed: outside it the Jacobians are not bounded and **no
certificate applies** (:attr:`SimulationResult.stayed_in_domain`).  Staying
inside is necessary, not sufficient: the frozen-robot μ certificate does not
cover a moving robot at all, the time-varying (arbitrarily fast) one does
only when its own status is CERTIFIED, and a sampled-and-held loop
(``rate``) is covered by neither.

Examples
--------
>>> import control, polyrob
>>> from polyrob.validate.simulate import simulate, step_reference
>>> robot = polyrob.load_robot("planar_2r")
>>> dom = polyrob.Domain.from_robot(robot)
>>> sim = simulate(robot, polyrob.paper_controller(), dom, step_reference([0.005, -0.002]), t_final=10.0)
>>> sim.stayed_in_domain, sim.settled(), bool(abs(sim.q[0, -1] - 0.005) < 1e-4)
(True, True, True)
>>> big = simulate(robot, polyrob.paper_controller(), dom, step_reference([0.2, -0.1]), t_final=2.0)
>>> big.stayed_in_domain, big.domain_exits[0][:9]
(False, 'u[joint1]')
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import control
import numpy as np
from scipy.integrate import solve_ivp

from polyrob.controller import Controller
from polyrob.errors import ArgumentError
from polyrob.validate.reference import Reference, smooth_reference, step_reference
from polyrob.validate.sampled import simulate_sampled
from polyrob.validate.step_metrics import SETTLING_BAND, JointMetrics, domain_check, step_metrics

__all__ = [
    "Reference",
    "JointMetrics",
    "SimulationResult",
    "simulate",
    "step_reference",
    "smooth_reference",
    "equilibrium_torque",
]


def equilibrium_torque(robot, q) -> np.ndarray:
    """The torque that holds the robot still at ``q``: ``g(q) = -M(q) qddot(q, 0, 0)``."""
    m = robot.m
    q = np.asarray(q, float)
    u = -robot.mass_matrix(q) @ robot.acceleration(q, np.zeros(m), np.zeros(m))
    u[np.abs(u) < 1e-12] = 0.0
    return u


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """A closed-loop simulation of the nonlinear robot.

    Attributes
    ----------
    t : ndarray (n_t,)
    q, qdot, u, r : ndarray (m, n_t)
    controller : {"continuous", "discrete"}
    rate : float or None
        Sample rate (Hz) of the discrete controller.
    metrics : tuple of JointMetrics
    left_domain : bool
        Whether ``(q, qdot, u)`` left the PLDI's domain at some time.
    domain_exits : tuple of str
        What left the domain: ``"qdot[joint2] at t = 0.12 s"``.
    first_exit_time : float or None
    time_outside : float
        Fraction of the samples outside the domain.
    u_eq : ndarray
        Torque offset added to the controller's output.
    success : bool
        The integrator reached ``t_final``.
    info : dict
        Solver, evaluations, notes.
    """

    t: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    u: np.ndarray
    r: np.ndarray
    controller: str
    rate: float | None
    reference: Reference
    metrics: tuple
    left_domain: bool
    domain_exits: tuple
    first_exit_time: float | None
    time_outside: float
    u_eq: np.ndarray
    success: bool
    info: dict = field(default_factory=dict)

    @property
    def stayed_in_domain(self) -> bool:
        """The trajectory stayed in the domain (and the integration finished): necessary for a certificate to apply."""
        return bool(self.success and not self.left_domain)

    @property
    def torque_within_limits(self) -> bool:
        return all(mt.torque_within_limit for mt in self.metrics)

    def settled(self, tolerance: float = SETTLING_BAND) -> bool:
        """Final tracking error within ``tolerance`` of each joint's step.

        A joint with a small or zero step is held to ``tolerance`` of a tenth
        of the largest step (coupling moves it too).
        """
        largest = max((abs(mt.step) for mt in self.metrics), default=0.0)
        return all(mt.steady_state_error <= tolerance * max(abs(mt.step), 0.1 * largest, 1e-9) for mt in self.metrics)

    def verdict(self) -> str:
        """One line: whether the run stayed where a certificate can apply, and which one could."""
        if not self.success:
            return "integration failed: " + str(self.info.get("message", ""))
        if self.left_domain:
            return "LEFT THE DOMAIN (" + "; ".join(self.domain_exits) + "): no certificate applies to this trajectory"
        if self.rate:
            return (
                "inside the domain; a sampled-and-held loop: no certificate covers it (they are "
                "for the continuous-time loop)"
            )
        return (
            "inside the domain (necessary for the time-varying certificate to apply; it covers this "
            "run only if its status says certified; the frozen-robot mu does not cover a moving robot)"
        )

    def summary(self) -> dict:
        return {
            "controller": self.controller,
            "rate_hz": self.rate,
            "reference": self.reference.kind,
            "target": None if self.reference.target is None else np.asarray(self.reference.target).tolist(),
            "left_domain": bool(self.left_domain),
            "domain_exits": list(self.domain_exits),
            "stayed_in_domain": self.stayed_in_domain,
            "settled": self.settled(),
            "torque_within_limits": self.torque_within_limits,
            "success": bool(self.success),
            "verdict": self.verdict(),
            "true_robot": self.info.get("true_robot"),  # behind an inner layer: payload, link factor drawn
            "joints": [
                {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in mt.__dict__.items()}
                for mt in self.metrics
            ],
        }


# --------------------------------------------------------------------------- simulation


def _domain_and_offset(robot, domain_or_pldi, u_eq):
    domain = getattr(domain_or_pldi, "domain", domain_or_pldi)
    if not hasattr(domain, "q_lower"):
        raise ArgumentError(f"simulate needs a Domain or a PLDI, got {type(domain_or_pldi).__name__}")
    if tuple(domain.joint_names) != tuple(robot.joint_names):
        raise ArgumentError(f"the domain's joints {domain.joint_names} are not the robot's {robot.joint_names}")
    if u_eq is None:
        point = getattr(domain_or_pldi, "nominal_point", None)
        if point is not None:
            u_eq, source = np.asarray(point["u"], float), "the PLDI's nominal torque"
        else:
            q0 = np.clip(np.zeros(robot.m), domain.q_lower, domain.q_upper)
            u_eq, source = equilibrium_torque(robot, q0), "the gravity torque at q = 0 (clipped)"
    else:
        u_eq, source = np.asarray(u_eq, float), "given"
    return domain, u_eq, source


def simulate(
    robot,
    K,
    domain,
    reference,
    *,
    t_final: float,
    q0=None,
    qdot0=None,
    rate: float | None = None,
    method: str = "tustin",
    prewarp: float | None = None,
    u_eq=None,
    n_points: int = 1001,
    rtol: float = 1e-7,
    atol: float = 1e-9,
    time_budget: float | None = None,
    true_seed: int | None = 0,
    max_evaluations: int | None = None,
) -> SimulationResult:
    """Simulate the robot's nonlinear dynamics in closed loop with ``K``.

    Parameters
    ----------
    robot : Manipulator
        A URDF :class:`~polyrob.model.robots.Robot` (Pinocchio ``aba``, damping
        included) or an :class:`~polyrob.model.analytic.AnalyticRobot`.
    K : LTI system, array, or a discrete controller
        ``m x m`` from ``e = r - q`` to ``u``; continuous-time (discretised
        here when ``rate`` is given), or a discrete-time ``control.StateSpace``
        or :class:`~polyrob.validate.discretize.DiscreteController` (then
        ``rate`` is its own).
    domain : Domain or PLDI
        The box the PLDI was computed over (a PLDI also gives ``u_eq``).
    reference : Reference, array_like or callable
        :func:`step_reference`, :func:`smooth_reference`, a constant target
        (a step) or ``r(t)``.
    t_final : float
    q0, qdot0 : array_like, optional
        Initial state (default: the PLDI's nominal position, clipped ``0``, at rest).
    rate : float, optional
        Sample rate in Hz of the sample-and-hold controller; ``None`` for the
        continuous one.
    method, prewarp
        Discretisation (see :func:`polyrob.validate.discretize.discretize`).
    u_eq : array_like or "hold", optional
        Torque added to the controller output (default: the PLDI's nominal
        torque, else the gravity torque at the clipped ``q = 0``).  ``"hold"``:
        the input that holds the simulated (true) robot at rest at ``q0``, as
        a settled integral action leaves it before a move (behind an inner
        layer with model error, the nominal input accelerates the true robot at t = 0).
    n_points : int
        Output samples of the continuous simulation.
    time_budget : float, optional
        A safety net the caller sets: wall-clock seconds the integration may
        take; past it the simulation stops, keeps what it integrated and
        reports ``success=False`` with a message naming the limit ("stopped by
        the time limit of N s you set").  ``None``: no limit.  Whether it
        fires depends on the machine's load: bound the work with
        ``max_evaluations`` instead.
    true_seed : int or None
        For an inner loop with ranges (:mod:`polyrob.model.inner`): the seed
        of the true robot simulated, its payload and inertia factor drawn
        from their ranges (``info["true_robot"]`` says which; the inner layer
        computes with the model); ``None``: the model itself.  ``u`` is then
        the outer input ``v`` and ``info["motor_torque_peak"]`` the motors'.
    max_evaluations : int, optional
        Evaluations of the dynamics the integration may make (a count of
        work: the same on an idle and on a loaded machine).  A stiff closed
        loop (a fast controller on a light robot) can keep an implicit solver
        on tiny steps for many minutes; past the limit the simulation stops,
        keeps what it integrated and reports ``success=False`` with a message
        saying how far it got.  ``None``: no limit.

    Returns
    -------
    SimulationResult
    """
    from polyrob.validate.discretize import DiscreteController, discretize

    m = robot.m
    ranged = getattr(robot, "payload", None) is not None or getattr(robot, "model_error", 0.0)
    if hasattr(robot, "drawn") and ranged and true_seed is not None:
        robot = robot.drawn(np.random.default_rng(true_seed))
    hold = isinstance(u_eq, str) and u_eq == "hold"
    dom, u_eq, u_source = _domain_and_offset(robot, domain, None if hold else u_eq)
    if not isinstance(reference, Reference):
        reference = Reference("custom", function=reference) if callable(reference) else step_reference(reference)
    if q0 is None:
        point = getattr(domain, "nominal_point", None)
        q0 = np.asarray(point["q"], float) if point else np.clip(np.zeros(m), dom.q_lower, dom.q_upper)
    q0 = np.asarray(q0, float)
    qdot0 = np.zeros(m) if qdot0 is None else np.asarray(qdot0, float)
    if hold:
        u_eq, u_source = robot.inverse_dynamics(q0[None], 0 * q0[None], 0 * q0[None])[0], "the input holding q0 at rest"
    r_of_t = reference.bind(q0)
    if not t_final > 0:
        raise ArgumentError(f"t_final must be positive, got {t_final}")

    discrete = isinstance(K, DiscreteController) or (
        isinstance(K, control.LTI) and getattr(K, "dt", 0) not in (0, None)
    )
    if rate is not None and not discrete:
        K = discretize(K, rate, method=method, prewarp=prewarp)
        discrete = True
    if discrete:
        Kd = K.system if isinstance(K, DiscreteController) else control.ss(K)
        t, X, U, R, ok, info = simulate_sampled(
            robot, Kd, r_of_t, t_final, q0, qdot0, u_eq, rtol, atol, _limits(time_budget, max_evaluations)
        )
        info["u_eq_source"] = u_source
        m = robot.m
        return _result(robot, dom, t, X[:m], X[m:], U, R, "discrete", 1.0 / float(Kd.dt), reference, q0, u_eq, ok, info)

    Ak, Bk, Ck, Dk = Controller.of(K, m, m).matrices
    nk = Ak.shape[0]
    limits = _limits(time_budget, max_evaluations)
    calls = [0]

    def rhs(t, z):
        calls[0] += 1
        if limits.exceeded(calls[0]):
            raise _OutOfTime
        q, qd, xk = z[:m], z[m : 2 * m], z[2 * m :]
        e = r_of_t(t) - q
        u = u_eq + Ck @ xk + Dk @ e
        return np.concatenate([qd, robot.acceleration(q, qd, u), Ak @ xk + Bk @ e])

    # Without a budget one solve_ivp call; with one, CHUNKS calls, so that
    # what was integrated before the budget ran out is kept.
    edges = np.linspace(0.0, t_final, (1 if limits.none else CHUNKS) + 1)
    z = np.concatenate([q0, qdot0, np.zeros(nk)])
    pieces, step_times, nfev, ok, message = [], [np.zeros(1)], 0, True, ""
    for a, b in zip(edges[:-1], edges[1:]):
        try:
            sol = solve_ivp(rhs, (a, b), z, method="LSODA", dense_output=True, rtol=rtol, atol=atol)
        except _OutOfTime:
            ok = False
            message = f"{limits.words(calls[0])} (integrated to t = {a:.4g} s of {t_final:.4g} s)"
            break
        nfev += int(sol.nfev)
        pieces.append((float(sol.t[-1]), sol.sol))
        step_times.append(sol.t)
        ok, message = bool(sol.success), sol.message
        if not ok:
            break
        z = sol.y[:, -1]
    t_end = pieces[-1][0] if pieces else 0.0
    # the output grid plus every accepted step: fast transients (torque peaks,
    # domain exits) fall on the solver's own short steps
    t = np.union1d(np.linspace(0.0, t_end, n_points), np.concatenate(step_times))
    y = _evaluate(pieces, t, np.concatenate([q0, qdot0, np.zeros(nk)]))
    q, qd, xk = y[:m], y[m : 2 * m], y[2 * m :]
    r = np.array([r_of_t(ti) for ti in t]).T.reshape(m, len(t))
    u = u_eq[:, None] + Ck @ xk + Dk @ (r - q)
    info = {"solver": "solve_ivp LSODA", "nfev": nfev, "message": message, "u_eq_source": u_source}
    return _result(robot, dom, t, q, qd, u, r, "continuous", None, reference, q0, u_eq, ok, info)


#: Pieces of a continuous simulation run under a time budget.
CHUNKS = 20


class _OutOfTime(Exception):
    """The simulation's limit (evaluations, or the wall clock the caller set) ran out (raised from the ODE's right-hand side)."""


@dataclass(frozen=True)
class SimulationLimits:
    """When a simulation stops early: a count of dynamics evaluations, and a wall-clock safety net the caller sets."""

    max_evaluations: int | None = None
    time_budget: float | None = None
    deadline: float | None = None

    @property
    def none(self) -> bool:
        return self.max_evaluations is None and self.deadline is None

    def exceeded(self, evaluations: int) -> bool:
        if self.max_evaluations is not None and evaluations > self.max_evaluations:
            return True
        return self.deadline is not None and time.monotonic() > self.deadline

    def words(self, evaluations: int) -> str:
        """Why it stopped, naming the limit."""
        if self.max_evaluations is not None and evaluations > self.max_evaluations:
            return f"not finished within its limit of {self.max_evaluations} evaluations of the dynamics"
        return f"stopped by the time limit of {self.time_budget:g} s you set"


def _limits(time_budget, max_evaluations) -> SimulationLimits:
    if max_evaluations is not None and not int(max_evaluations) >= 1:
        raise ArgumentError(f"max_evaluations must be >= 1, got {max_evaluations}")
    if time_budget is None:
        return SimulationLimits(None if max_evaluations is None else int(max_evaluations))
    if not time_budget > 0:
        raise ArgumentError(f"time_budget must be positive seconds, got {time_budget}")
    deadline = time.monotonic() + float(time_budget)
    return SimulationLimits(None if max_evaluations is None else int(max_evaluations), float(time_budget), deadline)


def _evaluate(pieces, t, z0):
    """The state at times ``t`` from the dense outputs of consecutive pieces."""
    y = np.empty((len(z0), len(t)))
    if not pieces:
        y[:] = z0[:, None]
        return y
    start = 0.0
    for end, dense in pieces:
        sel = (t >= start) & (t <= end)
        y[:, sel] = dense(t[sel])
        start = end
    return y


def _result(robot, dom, t, q, qd, u, r, kind, rate, reference, q0, u_eq, success, info) -> SimulationResult:
    exits, first, outside = domain_check(dom, robot, t, q, qd, u)
    if hasattr(robot, "torque"):  # an inner loop: u is the outer input v; the motors give torque(q, qdot, v)
        info["true_robot"] = robot.scenario
        info["inner"] = robot.inner
        info["motor_torque_peak"] = np.abs(robot.torque(q.T, qd.T, u.T)).max(axis=0).tolist()
    return SimulationResult(
        t=t,
        q=q,
        qdot=qd,
        u=u,
        r=r,
        controller=kind,
        rate=rate,
        reference=reference,
        metrics=step_metrics(robot, t, q, r, u, q0),
        left_domain=bool(exits),
        domain_exits=exits,
        first_exit_time=first,
        time_outside=outside,
        u_eq=np.asarray(u_eq, float),
        success=success,
        info=info,
    )
