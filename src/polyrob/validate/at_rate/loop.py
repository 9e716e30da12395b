"""The loop as it runs on a real arm: sampled, delayed, quantised encoders, friction the model does not have.

:func:`simulate_real_loop` closes a discrete controller on the robot's own
nonlinear dynamics (Pinocchio's ``aba`` of a *true* robot) the way a motor
drive runs it:

* **the rate**: every ``h = 1/rate`` the encoders are read, the controller
  (and the inner layer, when there is one) computes a torque, which is held
  (zero-order hold) until the next command;
* **the computation delay**: the torque computed from the samples at ``t_k``
  is applied from ``t_{k + d}`` (``d`` samples, default one: the command
  reaches the motors one period after its measurements were taken);
* **encoder quantisation**: positions are read to the nearest multiple of
  ``LSB = 2 pi / 2^B`` (``B`` bits per turn; the error is at most ``LSB/2``);
  the inner layer's velocity is the backward difference of two readings (no
  tachometer: each reading's ``LSB/2`` error becomes up to ``LSB/h`` of velocity);
* **joint friction not in the inner model**: ``tau_f = -b qdot - c tanh(qdot / v_s)``
  per joint (viscous ``b`` N m s/rad, Coulomb ``c`` N m, smoothed over the
  velocity scale ``v_s``: within 0.5 % of ``c`` beyond ``3 v_s``; a smooth
  model, not a stick-slip event model: a joint near rest sees a steep viscous
  slope ``c / v_s`` instead of sticking exactly);
* **the motors' saturation**: the applied torque is clipped to the effort limit.

The robot between two samples is integrated by a fixed-step Runge-Kutta
scheme (RK4) with ``n_sub`` steps per period, chosen so that the friction's
slope ``(b + c / v_s) / lambda_min(M)`` stays inside RK4's stability region: the
work of a run is known before it starts (``4 n_sub`` evaluations of the
dynamics per sample), and :attr:`RealLoopConditions.max_evaluations` bounds it.

Examples
--------
>>> import numpy as np
>>> quantize_position(np.array([0.0, 1e-5, -3e-5]), 18) / encoder_lsb(18)
array([ 0.,  0., -1.])
>>> joint_friction(np.array([0.5, -1.0]), viscous=1.0, coulomb=2.0, velocity_scale=0.01).round(6)
array([-2.5,  3. ])
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from polyrob.errors import ArgumentError

__all__ = [
    "RealLoopConditions",
    "RealLoopTrace",
    "CommandDelay",
    "encoder_lsb",
    "quantize_position",
    "joint_friction",
    "simulate_real_loop",
]

#: RK4's stability interval on the negative real axis is (-2.78, 0); substeps keep ``h lambda`` below this.
RK4_STABLE = 2.5
#: Substeps per period at most (a friction slope needing more is refused, not silently integrated wrong).
MAX_SUBSTEPS = 256


def encoder_lsb(bits: int | None) -> float:
    """The encoder's resolution ``2 pi / 2^bits`` (rad); 0 for an exact measurement (``None``)."""
    return 0.0 if bits is None else 2.0 * math.pi / 2.0 ** int(bits)


def quantize_position(q, bits: int | None) -> np.ndarray:
    """``q`` read by a ``bits``-bit encoder: the nearest multiple of :func:`encoder_lsb` (error at most LSB/2)."""
    q = np.asarray(q, float)
    lsb = encoder_lsb(bits)
    return q.copy() if lsb == 0 else lsb * np.round(q / lsb)


def joint_friction(qdot, *, viscous, coulomb, velocity_scale: float) -> np.ndarray:
    """Friction torque on each joint: ``-b qdot - c tanh(qdot / v_s)`` (N m; it opposes the motion)."""
    qdot = np.asarray(qdot, float)
    return -np.asarray(viscous, float) * qdot - np.asarray(coulomb, float) * np.tanh(qdot / velocity_scale)


class CommandDelay:
    """A FIFO of ``samples`` commands: :meth:`push` takes the new command and gives the one applied now.

    >>> d = CommandDelay(1, np.zeros(1))
    >>> [float(d.push(np.array([k]))[0]) for k in (1.0, 2.0, 3.0)]
    [0.0, 1.0, 2.0]
    """

    def __init__(self, samples: int, initial):
        self.queue = [np.asarray(initial, float).copy() for _ in range(int(samples))]

    def push(self, command) -> np.ndarray:
        self.queue.append(np.asarray(command, float).copy())
        return self.queue.pop(0)


@dataclass(frozen=True)
class RealLoopConditions:
    """What the loop meets on the arm (defaults: 1 kHz, one sample of delay, 18-bit encoders, b = 1, c = 2).

    Attributes
    ----------
    rate : float
        Sample rate, Hz.
    delay_samples : int
        Samples between a measurement and the torque it gives (0: none).
    encoder_bits : int or None
        Bits per turn of the joint encoders; ``None``: exact positions and velocities.
    friction_viscous, friction_coulomb : float
        ``b`` (N m s/rad) and ``c`` (N m) on every joint, on top of the true robot's own damping.
    coulomb_velocity : float
        ``v_s`` (rad/s) of the smoothed Coulomb term.
    method : {"tustin", "zoh"}
        Discretisation of a continuous controller.
    saturate : bool
        Clip the applied torque to the effort limit.
    max_evaluations : int
        Dynamics evaluations one run may make (a count of work; a run that needs more is refused before it starts).
    """

    rate: float = 1000.0
    delay_samples: int = 1
    encoder_bits: int | None = 18
    friction_viscous: float = 1.0
    friction_coulomb: float = 2.0
    coulomb_velocity: float = 0.01
    method: str = "tustin"
    saturate: bool = True
    max_evaluations: int = 20_000_000

    def __post_init__(self):
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise ArgumentError(f"--rate: give a positive sample rate in Hz, got {self.rate}")
        if int(self.delay_samples) != self.delay_samples or self.delay_samples < 0:
            raise ArgumentError(f"the delay must be a whole number of samples >= 0, got {self.delay_samples}")
        if self.encoder_bits is not None and not (4 <= int(self.encoder_bits) <= 40):
            raise ArgumentError(f"--encoder-bits: give 4 to 40 bits per turn, got {self.encoder_bits}")
        for name in ("friction_viscous", "friction_coulomb"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ArgumentError(f"--{name.replace('_', '-')}: give a number >= 0, got {value}")
        if not self.coulomb_velocity > 0:
            raise ArgumentError(f"the Coulomb velocity scale must be > 0 rad/s, got {self.coulomb_velocity}")

    @property
    def lsb(self) -> float:
        return encoder_lsb(self.encoder_bits)

    def words(self) -> str:
        enc = (
            "exact encoders"
            if self.encoder_bits is None
            else f"{self.encoder_bits}-bit encoders (LSB {self.lsb:.3g} rad)"
        )
        return (
            f"{self.rate:g} Hz ({self.method} controller, zero-order hold), {self.delay_samples} sample(s) of delay, "
            f"{enc}, friction not in the inner model: viscous {self.friction_viscous:g} N m s/rad + Coulomb "
            f"{self.friction_coulomb:g} N m per joint (tanh over {self.coulomb_velocity:g} rad/s)"
            + (", torques clipped at the effort limit" if self.saturate else "")
        )

    def to_dict(self) -> dict:
        return {
            "rate_hz": self.rate,
            "delay_samples": int(self.delay_samples),
            "encoder_bits": self.encoder_bits,
            "encoder_lsb_rad": self.lsb,
            "friction_viscous": self.friction_viscous,
            "friction_coulomb": self.friction_coulomb,
            "coulomb_model": f"c tanh(qdot / {self.coulomb_velocity:g} rad/s)",
            "controller_discretisation": self.method,
            "saturate": self.saturate,
        }


@dataclass(frozen=True, eq=False)
class RealLoopTrace:
    """One run at the samples ``t_k = k h``: arrays ``(m, n)``; ``tau_*`` are the motor torques.

    ``tau_commanded[:, k]`` is computed from the readings at ``t_k``; ``tau_applied[:, k]`` acts on
    ``[t_k, t_{k+1})`` (the command of ``k - delay``, clipped).  ``qddot`` is the acceleration at the
    start of each period; ``qddot_peak`` (m,) the largest ``|qddot|`` at any substep.
    """

    t: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    qddot: np.ndarray
    r: np.ndarray
    q_measured: np.ndarray
    tau_commanded: np.ndarray
    tau_applied: np.ndarray
    qddot_peak: np.ndarray
    success: bool
    info: dict = field(default_factory=dict)


def _true_dynamics(plant):
    """``(the robot the torques act on, the inner law tau(q_meas, qdot_meas, v) or None)``."""
    if hasattr(plant, "true_robot") and hasattr(plant, "torque"):
        return plant.true_robot, (lambda q, qd, v: plant.torque(q, qd, v)[0])
    return plant, None


def substeps(robot, q0, conditions: RealLoopConditions) -> int:
    """RK4 steps per period keeping the friction's slope (and the robot's damping) stable."""
    M = np.asarray(robot.mass_matrix(q0), float)
    lam_min = float(np.linalg.eigvalsh(0.5 * (M + M.T)).min())
    damping = float(np.max(np.asarray(getattr(robot, "damping", 0.0), float), initial=0.0))
    slope = (
        damping + conditions.friction_viscous + conditions.friction_coulomb / conditions.coulomb_velocity
    ) / lam_min
    n = max(1, math.ceil(slope / conditions.rate / RK4_STABLE))
    if n > MAX_SUBSTEPS:
        raise ArgumentError(
            f"the friction's slope {slope:.3g} 1/s on this robot needs {n} RK4 steps per sample (> {MAX_SUBSTEPS}): "
            "raise the Coulomb velocity scale"
        )
    return n


def simulate_real_loop(
    plant,
    Kd,
    r_of_t,
    *,
    q0,
    t_final: float,
    v_eq,
    conditions: RealLoopConditions | None = None,
    on_sample=None,
) -> RealLoopTrace:
    """Run the discrete controller ``Kd`` (``control.StateSpace`` with ``dt``) on ``plant`` from rest at ``q0``.

    Parameters
    ----------
    plant : Robot or InnerLoopRobot
        The true robot (an :class:`~polyrob.model.inner.InnerLoopRobot`: its ``true_robot`` moves, its
        inner layer computes from the readings with its model).
    Kd : control.StateSpace
        Discrete, ``dt = 1 / conditions.rate``, ``e = r - q_measured`` to ``v``.
    r_of_t : callable
        The reference ``r(t)``.
    q0 : array_like
    t_final : float
    v_eq : array_like
        Offset added to the controller's output (the input holding the robot at rest at ``q0``).
    conditions : RealLoopConditions, optional
        Default :class:`RealLoopConditions` ``()``.
    on_sample : callable, optional
        Called with the number of samples done (whole-job progress).
    """
    conditions = RealLoopConditions() if conditions is None else conditions
    robot, inner_law = _true_dynamics(plant)
    m = robot.m
    h = 1.0 / conditions.rate
    if abs(float(Kd.dt) - h) > 1e-12 * h:
        raise ArgumentError(f"the controller runs at {1 / float(Kd.dt):g} Hz, not at the loop's {conditions.rate:g} Hz")
    Ad, Bd, Cd, Dd = (np.asarray(X, float) for X in (Kd.A, Kd.B, Kd.C, Kd.D))
    q0 = np.asarray(q0, float)
    n_samples = int(math.ceil(t_final / h - 1e-9))
    n_sub = substeps(robot, q0, conditions)
    evaluations = 4 * n_sub * n_samples
    if evaluations > conditions.max_evaluations:
        raise ArgumentError(
            f"this run needs {evaluations} evaluations of the dynamics ({n_samples} samples x {n_sub} RK4 steps), "
            f"more than its limit of {conditions.max_evaluations}: shorten it or raise the limit"
        )
    limit = np.asarray(robot.effort_limit, float)
    b, c, vs = conditions.friction_viscous, conditions.friction_coulomb, conditions.coulomb_velocity
    bits = conditions.encoder_bits

    def accel(x, tau):
        qd = x[m:]
        return robot.acceleration(x[:m], qd, tau + joint_friction(qd, viscous=b, coulomb=c, velocity_scale=vs))

    v_eq = np.asarray(v_eq, float)
    q_read_prev = quantize_position(q0, bits)
    tau_rest = inner_law(q_read_prev, np.zeros(m), v_eq) if inner_law else v_eq
    delay = CommandDelay(conditions.delay_samples, tau_rest)
    x, xk = np.concatenate([q0, np.zeros(m)]), np.zeros(Ad.shape[0])
    out = {k: np.empty((m, n_samples)) for k in ("q", "qdot", "qddot", "r", "qm", "cmd", "app")}
    peak = np.zeros(m)
    dt, ok, message = h / n_sub, True, "reached t_final"
    for k in range(n_samples):
        tk = k * h
        q_read = quantize_position(x[:m], bits)
        qdot_read = (q_read - q_read_prev) / h if k else np.zeros(m)
        rk = np.asarray(r_of_t(tk), float)
        e = rk - q_read
        v = v_eq + Cd @ xk + Dd @ e
        xk = Ad @ xk + Bd @ e
        cmd = inner_law(q_read, qdot_read, v) if inner_law else v
        tau = delay.push(cmd)
        if conditions.saturate:
            tau = np.clip(tau, -limit, limit)
        out["q"][:, k], out["qdot"][:, k], out["r"][:, k] = x[:m], x[m:], rk
        out["qm"][:, k], out["cmd"][:, k], out["app"][:, k] = q_read, cmd, tau
        for j in range(n_sub):  # RK4 over the hold interval
            k1 = np.concatenate([x[m:], accel(x, tau)])
            if j == 0:
                out["qddot"][:, k] = k1[m:]
            np.maximum(peak, np.abs(k1[m:]), out=peak)
            k2 = np.concatenate([x[m:] + 0.5 * dt * k1[m:], accel(x + 0.5 * dt * k1, tau)])
            k3 = np.concatenate([x[m:] + 0.5 * dt * k2[m:], accel(x + 0.5 * dt * k2, tau)])
            k4 = np.concatenate([x[m:] + dt * k3[m:], accel(x + dt * k3, tau)])
            x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        q_read_prev = q_read
        if not np.all(np.isfinite(x)):
            ok, message = False, f"the state is not finite at t = {tk + h:.4g} s (the loop, or its integration at this step, diverged)"
            n_samples = k + 1
            break
        if on_sample is not None:
            on_sample(k + 1)
    cut = {key: arr[:, :n_samples] for key, arr in out.items()}
    return RealLoopTrace(
        t=h * np.arange(n_samples),
        q=cut["q"],
        qdot=cut["qdot"],
        qddot=cut["qddot"],
        r=cut["r"],
        q_measured=cut["qm"],
        tau_commanded=cut["cmd"],
        tau_applied=cut["app"],
        qddot_peak=peak,
        success=ok,
        info={
            "integrator": f"RK4, {n_sub} step(s) per sample",
            "evaluations": 4 * n_sub * n_samples,
            "message": message,
            "saturated_fraction": float(np.mean(np.abs(cut["cmd"]) > limit[:, None])) if n_samples else 0.0,
        },
    )
