"""The moving robot's gain from below: the largest L2 gain found along admissible trajectories of the domain.

The moving-robot certificate (:mod:`polyrob.analysis.lpv.moving`) proves an
upper bound ``gamma`` of the induced L2 gain of the linearised loop over
every trajectory of ``rho`` in the box with the certificate's rates.  Here
the analogue of μ's lower bound: the gain that particular admissible
trajectories really reach, so the user sees how much of ``gamma`` is left.

* **At rest** (``frozen_gamma``): the largest H-infinity norm of the frozen
  loops at the points of the box where every scheduled position's velocity is
  zero (a position cannot stay put at a non-zero velocity, so a frozen loop
  there is not a trajectory).  Constant trajectories are admissible, so
  these are exact gains (to the H-infinity norm's accuracy).
* **Moving** (:func:`admissible_trajectories`): rotations of a position at
  its full speed (when the box is the whole circle and the loop periodic),
  swings of each velocity at the acceleration limit (sinusoids of the
  largest amplitude the velocity, acceleration and position bounds allow),
  bang-bang velocities (triangle waves at the acceleration limit), chirps,
  and random runs (piecewise-constant accelerations within the bounds).
  Every trajectory keeps ``dq_i/dt = qdot_i`` exactly, its velocities in
  the box and ``|dqdot_i/dt|`` within the rate bounds; on a task
  (:class:`~polyrob.analysis.lpv.task.TaskMotionModel`) its acceleration
  parameters are the velocities' derivatives (0 where a velocity is not
  scheduled), so the loop is the robot's along a motion it can make.
* **The gain along a trajectory** (:func:`trajectory_gains`): the loop
  ``xdot = A(rho(t)) x + B(rho(t)) d, e = C x + D d`` on a finite horizon,
  frozen over each step of length ``h`` and integrated exactly there (zero-
  order hold of ``d``, matrix exponential); the largest singular value of
  that finite-horizon operator by power iteration on ``T* T`` (the adjoint
  by a backward sweep), every iterate's ratio ``||T d|| / ||d||`` a gain
  the loop reaches for that input.

What it is: gains *found*, an estimate from below of the worst case over the
admissible trajectories -- not a certificate.  The moving part is simulated
(the loop frozen over each step of ``h``), so it carries that discretisation;
the at-rest part is an H-infinity norm.  A found gain above the proved upper
bound would contradict the proof (``tests/test_lower_bound.py`` checks
that it never happens); a found gain above 1 shows robust performance fails
for the linearised loop along that trajectory.

Examples
--------
>>> b = TrajectoryLowerBound(0.72, 0.70, "rotation qdot2 = 9.956", 3, 1e-4, 1.0, 0.5)
>>> b.words()
'>= 0.72 found along 3 admissible trajectories (worst: rotation qdot2 = 9.956; simulated, step 0.0001 s)'
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError, NotApplicable

__all__ = ["TrajectoryLowerBound", "admissible_trajectories", "trajectory_gains", "trajectory_lower_bound",
           "rest_peak", "affine_evaluation", "long_runs"]  # fmt: skip

#: Power iterations per trajectory (each iterate is a gain reached: more only tightens).
ITERATIONS = 25
#: Steps per period of the frozen loops' peak frequency.
STEPS_PER_PERIOD = 24
#: Largest number of time steps of one trajectory (the cost bound).
MAX_STEPS = 1500
#: The long runs (a loop slower than the short horizon): at most this many seconds and steps, the step at most
#: this fraction of a bang-bang velocity's period, over this many of the loop's slowest time constants.  The main
#: job's loop has the poles of the paper's W_S, 0.002 and 0.005 rad/s: its gain along a bang-bang velocity grows
#: over hundreds of seconds, far past the short horizon's tens.
LONG_HORIZON_MAX = 1000.0
LONG_STEPS = 6000
LONG_TIME_CONSTANTS = 4.0
LONG_STEP_PER_PERIOD = 1.0 / 16.0


@dataclass(frozen=True)
class TrajectoryLowerBound:
    """The largest L2 gain found along admissible trajectories.

    Attributes
    ----------
    gamma : float
        The largest gain found (at rest or moving).
    frozen_gamma : float
        The largest frozen H-infinity norm at rest (velocities of the scheduled positions 0).
    worst : str
        The trajectory that reached ``gamma``.
    n_trajectories : int
        Moving trajectories simulated.
    step : float
        The simulation's step (physical seconds).
    horizon : float
        The simulated horizon (physical seconds).
    seconds : float
    gains : tuple of (str, float)
        Each moving trajectory and the gain found along it.
    """

    gamma: float
    frozen_gamma: float
    worst: str
    n_trajectories: int
    step: float
    horizon: float
    seconds: float
    gains: tuple = ()

    def words(self) -> str:
        return (f">= {self.gamma:.4g} found along {self.n_trajectories} admissible trajectories (worst: {self.worst}; "
                f"simulated, step {self.step:.3g} s)")  # fmt: skip

    def summary(self) -> dict:
        return {
            "gamma": float(self.gamma),
            "frozen_gamma": float(self.frozen_gamma),
            "worst": self.worst,
            "trajectories": int(self.n_trajectories),
            "step": float(self.step),
            "horizon": float(self.horizon),
            "seconds": round(float(self.seconds), 1),
            "gains": [[name, float(g)] for name, g in self.gains],
            "words": self.words(),
        }


def _periodic(model, i: int) -> bool:
    """Position ``i`` may rotate: its box is the whole circle and the Jacobians are 2 pi periodic in it."""
    a = model.axes[i]
    if model.kinds[i] != "q" or a[-1] - a[0] < 2 * np.pi * (1 - 1e-9):
        return False
    rho = np.array([0.5 * (x[0] + x[-1]) for x in model.axes])
    shifted = rho.copy()
    shifted[i] += 2 * np.pi
    return all(np.allclose(x, y, rtol=1e-9, atol=1e-12) for x, y in zip(model.plant(rho), model.plant(shifted)))


def _velocity_index(model) -> dict:
    """``position parameter -> its velocity parameter`` (both scheduled)."""
    where = {(k, j): i for i, (k, j) in enumerate(zip(model.kinds, model.joints))}
    return {i: where[("qdot", j)] for (k, j), i in where.items() if k == "q" and ("qdot", j) in where}


#: The families of :func:`admissible_trajectories`.
FAMILIES = ("constant", "swing", "bang-bang", "chirp", "random")


def admissible_trajectories(model, rates, t, *, seed: int = 0, random_runs: int = 3, levels: bool = False,
                            families=FAMILIES):  # fmt: skip
    """Trajectories of ``rho`` in the box with ``dq_i/dt = qdot_i`` and ``|dqdot_i/dt|`` within ``rates``.

    Parameters
    ----------
    model : MovingRobotModel
    rates : sequence of (float, float)
        The certificate's rate bounds (a velocity's: its acceleration bound).
    t : ndarray
        The times (physical seconds).
    seed : int
    random_runs : int
    levels : bool
        Run each bang-bang velocity with the scheduled positions that stay
        put at every combination of their lower end, midpoint and upper end
        (default: at their midpoints only).
    families : sequence of str
        Which of :data:`FAMILIES` to build (default: all).

    Returns
    -------
    list of (str, ndarray)
        Name and ``rho`` at the times ``t`` (``(len(t), p)``).
    """
    lo = np.array([a[0] for a in model.axes], float)
    hi = np.array([a[-1] for a in model.axes], float)
    mid, p = 0.5 * (lo + hi), lo.size
    vel_of = _velocity_index(model)
    acc = np.array([min(abs(r[0]), abs(r[1])) if k == "qdot" else np.inf for r, k in zip(rates, model.kinds)])
    acc = np.where(np.isfinite(acc), acc, 1e6)  # an arbitrary-velocity search: any bound is admissible
    vel = [i for i, k in enumerate(model.kinds) if k == "qdot"]
    rng = np.random.default_rng(seed)
    T = float(t[-1] - t[0]) if t.size > 1 else 1.0

    # a task's accelerations (kind qddot): the derivative of their joint's velocity, 0 for a velocity not scheduled
    acc_of = {i: next((w for w in vel if model.joints[w] == model.joints[i]), None)
              for i, k in enumerate(model.kinds) if k == "qddot"}  # fmt: skip

    def with_positions(name, v, start=None, a=None):
        """``rho`` from velocity profiles ``v`` and their derivatives ``a`` (``(len(t), p)``, velocity columns set).

        Positions integrated, accelerations ``a`` (``None``: constant velocities, ``0``).
        """
        rho = np.tile(mid if start is None else start, (t.size, 1))
        for i in vel:
            rho[:, i] = v[:, i]
        for i, w in acc_of.items():
            rho[:, i] = 0.0 if a is None or w is None else a[:, w]
            if np.any(rho[:, i] < lo[i] - 1e-9 * (1 + abs(lo[i]))) or np.any(rho[:, i] > hi[i] + 1e-9 * (1 + abs(hi[i]))):
                return None  # an acceleration outside the task's box: not a trajectory of it
            rho[:, i] = np.clip(rho[:, i], lo[i], hi[i])
        dt = np.diff(t, prepend=t[0])
        for i, w in vel_of.items():
            q = rho[0, i] + np.cumsum(0.5 * (v[:, w] + np.concatenate([v[:1, w], v[:-1, w]])) * dt)
            if _periodic(model, i):
                q = lo[i] + np.mod(q - lo[i], hi[i] - lo[i])
            elif np.any(q < lo[i] - 1e-12) or np.any(q > hi[i] + 1e-12):
                return None
            rho[:, i] = np.clip(q, lo[i], hi[i])
        return name, rho

    out = []

    def add(item):
        if item is not None:
            out.append(item)

    vmax = np.maximum(np.abs(lo), np.abs(hi))
    # rotations: constant velocities at the corners of the velocity box
    for signs in np.ndindex(*([2] * len(vel))) if "constant" in families else ():
        v = np.zeros((t.size, p))
        for s, i in zip(signs, vel):
            v[:, i] = hi[i] if s else lo[i]
        add(with_positions("constant velocities " + ", ".join(f"{model.names[i]} = {v[0, i]:.4g}" for i in vel), v))
    # swings at the acceleration limit: the largest sinusoid the velocity, acceleration and position bounds allow
    for periods in (1.0, 2.0, 4.0, 8.0) if "swing" in families else ():
        om = 2 * np.pi * periods / T
        v, a = np.zeros((t.size, p)), np.zeros((t.size, p))
        for i in vel:
            amp = min(vmax[i], acc[i] / om)
            for q, w in vel_of.items():
                if w == i and not _periodic(model, q):
                    amp = min(amp, 0.5 * (hi[q] - lo[q]) * om)
            v[:, i] = amp * np.sin(om * (t - t[0]))
            a[:, i] = amp * om * np.cos(om * (t - t[0]))
        start = mid.copy()
        for q, w in vel_of.items():
            if not _periodic(model, q):
                start[q] = mid[q] - v[:, w].max() / om if v[:, w].max() > 0 else mid[q]
        add(with_positions(f"swing at {om:.3g} rad/s", v, start, a))
    # bang-bang velocities: triangle waves at the acceleration limit between the velocity bounds
    for i in vel if "bang-bang" in families else ():
        v, a = np.zeros((t.size, p)), np.zeros((t.size, p))
        phase = np.mod(acc[i] * (t - t[0]) / (2 * vmax[i]) + 0.25, 2.0)
        v[:, i] = vmax[i] * (2 * np.abs(phase - 1.0) - 1.0)
        a[:, i] = np.where(phase >= 1.0, acc[i], -acc[i])
        name = f"bang-bang {model.names[i]} (|d/dt| = {acc[i]:.4g})"
        still = [q for q, w in vel_of.items() if w != i] if levels else []  # positions that stay put
        for where in np.ndindex(*([3] * len(still))):
            start = mid.copy()
            for q, k in zip(still, where):
                start[q] = (lo[q], mid[q], hi[q])[k]
            at = ", ".join(f"{model.names[q]} = {start[q]:.4g}" for q in still)
            add(with_positions(name + (f" at {at}" if at else ""), v, start, a))
    # chirp: a velocity sweeping 0.5 to 16 oscillations over the horizon, within the acceleration bound
    if "chirp" in families:
        v, a = np.zeros((t.size, p)), np.zeros((t.size, p))
        tau = (t - t[0]) / T
        for i in vel:
            phase = 2 * np.pi * (0.5 * tau + 7.75 * tau**2)
            rate = 2 * np.pi * (0.5 + 15.5 * tau) / T
            amp = np.minimum(vmax[i], acc[i] / rate.max())
            v[:, i], a[:, i] = amp * np.sin(phase), amp * rate * np.cos(phase)
        add(with_positions("chirp", v, None, a))
    # random runs: piecewise-constant accelerations within the bounds, the velocities kept in the box
    for r in range(random_runs if "random" in families else 0):
        v, a = np.zeros((t.size, p)), np.zeros((t.size, p))
        for i in vel:
            knots = rng.uniform(-1, 1, size=16) * acc[i]
            ak = knots[np.minimum((16 * (t - t[0]) / T).astype(int), 15)]
            x = rng.uniform(lo[i], hi[i])
            for k in range(t.size):
                v[k, i] = x
                if k + 1 < t.size:
                    step = float(np.clip(x + ak[k] * (t[k + 1] - t[k]), lo[i], hi[i]))
                    a[k, i] = (step - x) / (t[k + 1] - t[k])  # the velocity's slope over the step (0 at a bound)
                    x = step
        start = np.where([model.kinds[i] == "q" for i in range(p)], rng.uniform(lo, hi), mid)
        add(with_positions(f"random run {r + 1}", v, start, a))
    return out


def _expm_batch(M: np.ndarray) -> np.ndarray:
    """Matrix exponentials of a stack (scaling and squaring, Taylor of degree 12 at 1-norm <= 1/2: error < 3e-14).

    One scaling for the stack, numpy's batched products throughout (scipy's
    ``expm`` of a stack goes matrix by matrix).
    """
    norm = float(np.abs(M).sum(axis=-2).max()) if M.size else 0.0
    s = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0 else 0
    X = M / 2.0**s
    E = np.broadcast_to(np.eye(M.shape[-1]), M.shape) + X
    term = X
    for k in range(2, 13):
        term = term @ X / k
        E = E + term
    for _ in range(s):
        E = E @ E
    return E


def _step_matrices(system, rhos, h: float, scale):
    """``Phi_k, Gamma_k, Rx_k, Rd_k`` of the loop frozen at ``rhos[k]`` over a step ``h``, input held.

    ``x_{k+1} = Phi_k x_k + Gamma_k d_k`` exactly, and the output's energy over
    the step, ``int |C x(s) + D d_k|^2 ds = |Rx_k x_k + Rd_k d_k|^2``, exactly
    too (Van Loan's exponential of ``[[-F^T, H^T H], [0, F]] h``,
    ``F = [[A, B], [0, 0]]``, ``H = [C, D]``): the ratio of energies is the
    loop's own, with no aliasing of the sampled output.  ``scale``: the
    power-of-two state scaling (``x = diag(scale) x~``; exact).
    """
    mats = [system(r) for r in rhos]
    A = np.array([m[0] for m in mats]) / scale[None, :, None] * scale[None, None, :]
    B = np.array([m[1] for m in mats]) / scale[None, :, None]
    C = np.array([m[2] for m in mats]) * scale[None, None, :]
    D = np.array([m[3] for m in mats])
    K, n, md = B.shape
    N = n + md
    F = np.zeros((K, N, N))
    F[:, :n, :n], F[:, :n, n:] = A, B
    H = np.concatenate([C, D], axis=2)
    M = np.zeros((K, 2 * N, 2 * N))
    M[:, :N, :N] = -np.transpose(F, (0, 2, 1))
    HH = np.einsum("kji,kjl->kil", H, H)
    # Q is linear in H^T H: a power of two brings it to F's size (the exponential's squarings follow the largest)
    w = 2.0 ** np.round(np.log2(max(np.abs(F).max(), 1e-300) / max(np.abs(HH).max(), 1e-300)))
    M[:, :N, N:] = HH * w
    M[:, N:, N:] = F
    # Van Loan's block holds exp(-F^T h): on a stiff loop (|F| h >> 1) its growth wipes out the Gramian in
    # cancellation (gains of 1e13 on the main job's loop).  So Van Loan on h / 2^j, |F| h / 2^j <= 1/2, then
    # doubling, Q(2t) = Q(t) + Phi(t)^T Q(t) Phi(t), Phi(2t) = Phi(t)^2: only the stable exp(F t) is formed.
    growth = float(np.abs(F).sum(axis=-2).max()) * h
    halvings = max(0, int(np.ceil(np.log2(growth / 0.5)))) if growth > 0 else 0
    E = _expm_batch(M * (h / 2.0**halvings))
    Phi = E[:, N:, N:]
    Q = np.einsum("kji,kjl->kil", Phi, E[:, :N, N:]) / w
    for _ in range(halvings):
        Q = Q + np.swapaxes(Phi, 1, 2) @ Q @ Phi
        Phi = Phi @ Phi
    lam, V = np.linalg.eigh(0.5 * (Q + np.transpose(Q, (0, 2, 1))))
    R = np.sqrt(np.maximum(lam, 0.0))[:, :, None] * np.transpose(V, (0, 2, 1))  # R^T R = Q
    return Phi[:, :n, :n], Phi[:, :n, n:], R[:, :, :n], R[:, :, n:]


def trajectory_gains(system, trajectories, h: float, *, iterations: int = ITERATIONS, start=None, seed: int = 0):
    """The largest gain found along each trajectory: power iteration on the finite-horizon operator.

    Parameters
    ----------
    system : callable
        ``rho -> (A, B, C, D)``.
    trajectories : list of (str, ndarray)
        ``rho`` at the step starts (equal lengths).
    h : float
        The step (the time unit of ``system``).
    iterations : int
    start : ndarray, optional
        ``(steps, inputs)``: the first input (default: random).
    seed : int

    Returns
    -------
    ndarray
        Per trajectory, the largest ``||T d|| / ||d||`` over the iterates.
    """
    if not trajectories:
        return np.zeros(0)
    steps = trajectories[0][1].shape[0]
    if any(r.shape[0] != steps for _, r in trajectories):
        raise ArgumentError("trajectory_gains: every trajectory must have the same number of steps")
    from polyrob.analysis.lpv.norm import state_scaling

    scale = state_scaling(np.array([system(rho[0])[0] for _, rho in trajectories]))
    # the step matrices once per distinct rho (a bang-bang velocity on a step that divides its period repeats
    # every period); rho agreeing to 12 significant digits is the same loop to far below the gain's accuracy
    stacked = np.concatenate([rho for _, rho in trajectories])
    top = float(np.abs(stacked).max())
    decimals = min(12 - int(np.floor(np.log10(top))), 300) if top > 0 else 12
    _, first, inverse = np.unique(np.round(stacked, decimals), axis=0, return_index=True, return_inverse=True)
    once = _step_matrices(system, stacked[first], h, scale)
    index = np.asarray(inverse).reshape(len(trajectories), steps).T  # (steps, trajectories)
    Phi, Gam, C, D = once
    Gam, D = Gam / np.sqrt(h), D / np.sqrt(h)  # the input d~_k = sqrt(h) d_k: ||d~||_2 is d's L2 norm
    L, n, m, p = len(trajectories), Gam.shape[1], Gam.shape[2], C.shape[1]
    # one product per step each way: [y_k; x_k+1] = S_k [x_k; d_k], S_k = [[C_k, D_k], [Phi_k, Gam_k]], kept once
    # per distinct rho and gathered at each step (a copy per step and trajectory would take gigabytes)
    S = np.concatenate([np.concatenate([C, D], axis=2), np.concatenate([Phi, Gam], axis=2)], axis=1)
    St = np.ascontiguousarray(np.swapaxes(S, 1, 2))
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((steps, L, m)) if start is None else np.broadcast_to(start[:, None, :], (steps, L, m)).copy()
    best = np.zeros(L)
    xd = np.zeros((L, n + m, 1))
    ylam = np.zeros((L, p + n, 1))
    y = np.empty((steps, L, p))
    new = np.empty_like(d)
    for _ in range(int(iterations)):
        xd[:, :n, 0] = 0.0
        for k in range(steps):  # forward: y = T d
            xd[:, n:, 0] = d[k]
            out = S[index[k]] @ xd
            y[k] = out[:, :p, 0]
            xd[:, :n] = out[:, p:]
        nd = np.sqrt(np.einsum("kli,kli->l", d, d))
        ny = np.sqrt(np.einsum("kli,kli->l", y, y))
        best = np.maximum(best, np.where(nd > 0, ny / np.where(nd > 0, nd, 1.0), 0.0))
        ylam[:, p:, 0] = 0.0
        for k in range(steps - 1, -1, -1):  # backward: T* y, the adjoint state lam_k = C_k^T y_k + Phi_k^T lam_k+1
            ylam[:, :p, 0] = y[k]
            back = St[index[k]] @ ylam
            new[k] = back[:, n:, 0]
            ylam[:, p:] = back[:, :n]
        scale = np.sqrt(np.einsum("kli,kli->l", new, new))
        d = new / np.where(scale > 0, scale, 1.0)[None, :, None]
    return best


def _sweep_peak(A, B, C, D, w) -> tuple[float, float]:
    """``(largest singular value of the frequency response over w, its frequency)``: a gain a sinusoid reaches."""
    n = A.shape[0]
    resolvent = 1j * np.asarray(w)[:, None, None] * np.eye(n)[None] - A[None]
    sv = np.linalg.svd(C[None] @ np.linalg.solve(resolvent, np.broadcast_to(B, (len(w),) + B.shape)) + D[None],
                       compute_uv=False)[:, 0]  # fmt: skip
    i = int(np.argmax(sv))
    return float(sv[i]), float(w[i])


def rest_peak(model, system, points: int = 9) -> tuple[float, np.ndarray, float]:
    """``(peak, rho, frequency)``: the largest frozen gain at rest found on a grid of the box and of frequencies.

    At rest: every scheduled position's velocity is 0 and every acceleration
    of a task is 0 (a velocity that stays put; the other parameters on a grid
    of ``points`` values).  The frequency response's largest singular
    value on a logarithmic grid, refined about its peak: a gain a sinusoid
    reaches (at most the H-infinity norm); ``inf`` for an unstable loop.
    """
    vel_of = _velocity_index(model)
    still = set(vel_of.values()) | {i for i, k in enumerate(model.kinds) if k == "qddot"}  # constant velocities
    axes = []
    for i, a in enumerate(model.axes):
        if i in still and a[0] <= 0.0 <= a[-1]:
            axes.append(np.zeros(1))
        elif i in still:
            return float("nan"), np.array([]), float("nan")  # no rest in the box: no constant trajectory
        else:
            axes.append(np.linspace(a[0], a[-1], points) if a.size > 1 else a)
    w = np.logspace(-3, 5, 321)
    best, where, w_best = -1.0, None, 1.0
    for rho in np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(axes), -1).T:
        A, B, C, D = system(rho)
        if np.max(np.linalg.eigvals(A).real) >= 0:
            return float("inf"), rho, float("nan")
        g, wp = _sweep_peak(A, B, C, D, w)
        if g > best:
            best, where, w_best = g, rho, wp
    g, w_best = _sweep_peak(*system(where), w_best * np.logspace(-0.05, 0.05, 101))
    return float(max(best, g)), where, float(w_best)


def affine_evaluation(model, system):
    """``rho -> (A, B, C, D)`` of ``system`` from the robot's Jacobians at ``rho`` by the loop's affine map.

    The closed loop is affine in the robot's varying ``(A, B)`` entries
    (:class:`~polyrob.analysis.lpv.cells.loop.AffineLoop`, which checks it):
    its matrices at the centre plus the entries' changes times their unit
    responses -- the same loop as ``system`` (to rounding), without
    realising the weights and the controller at every step.  ``system``
    itself when it has no ``of_plant``.
    """
    from polyrob.analysis.lpv.cells.loop import AffineLoop

    if not hasattr(system, "of_plant"):
        return system
    mid = np.array([0.5 * (a[0] + a[-1]) for a in model.axes], float)
    A0, B0 = model.plant(mid)
    base = system.of_plant(A0, B0)
    try:
        loop = AffineLoop(system.of_plant, 1.0, np.ones(base[0].shape[0]), A0, B0)
    except ValueError:
        return system
    G = [np.array([g[i] for g in loop.G]) for i in range(4)]
    where = [(0 if kind == "A" else 1, i, j) for kind, i, j in loop.entries]

    def fast(rho):
        P = model.plant(rho)
        w = np.array([P[k][i, j] - (A0, B0)[k][i, j] for k, i, j in where])
        return tuple(b + np.tensordot(w, g, axes=1) for b, g in zip(base, G))

    return fast


def trajectory_lower_bound(model, system, rates, *, horizon=None, step=None, iterations: int = ITERATIONS,
                           seed: int = 0, random_runs: int = 3, long_horizon=None) -> TrajectoryLowerBound:  # fmt: skip
    """The largest L2 gain found along admissible trajectories of ``model``'s box with ``rates``.

    Parameters
    ----------
    model : MovingRobotModel
    system : callable
        :func:`~polyrob.analysis.lpv.robot.closed_loop_system` (physical time, the loop's coordinates).
    rates : sequence of (float, float)
        The rate bounds the certificate covers (:func:`~polyrob.analysis.lpv.robot.rate_bounds`).
    horizon : float, optional
        Seconds simulated (default: two rotations at the largest velocity, at
        least 40 periods of the frozen peak's frequency, within :data:`MAX_STEPS` steps).
    step : float, optional
        The step (default: :data:`STEPS_PER_PERIOD` per period of the frozen peak's frequency).
    iterations, seed, random_runs
        Power iterations per trajectory; the random runs' seed and number.
    long_horizon : float, bool or None
        The long runs' horizon in seconds (:func:`long_runs`); ``None``
        (default): :data:`LONG_TIME_CONSTANTS` times the frozen loop's
        slowest time constant at the rest peak, at most
        :data:`LONG_HORIZON_MAX`, and no long runs when that is within twice
        the short horizon; ``False``: none.

    Returns
    -------
    TrajectoryLowerBound

    Raises
    ------
    NotApplicable
        A frozen loop at rest is unstable (no finite gain to find).
    """
    t0 = time.perf_counter()
    system = affine_evaluation(model, system)
    frozen, where, w_peak = rest_peak(model, system)
    if not np.isfinite(frozen) and not np.isnan(frozen):
        raise NotApplicable(f"the frozen loop at {np.round(where, 4).tolist()} is unstable: its gain is unbounded")
    if not np.isfinite(w_peak) or w_peak <= 0:
        w_peak = 1.0
    period = 2 * np.pi / w_peak
    h = float(step) if step is not None else period / STEPS_PER_PERIOD
    if horizon is None:
        vmax = max((float(np.abs(a).max()) for a, k in zip(model.axes, model.kinds) if k == "qdot"), default=0.0)
        horizon = max(40 * period, 4 * np.pi / vmax if vmax > 0 else 0.0)
        horizon = min(horizon, MAX_STEPS * h)
    steps = max(8, int(round(float(horizon) / h)))
    t = np.arange(steps) * h
    trajs = admissible_trajectories(model, rates, t, seed=seed, random_runs=random_runs)
    # the first input: the frozen peak's sinusoid (power iteration then climbs from there)
    m = system(np.array([a[0] for a in model.axes]))[1].shape[1]
    rng = np.random.default_rng(seed)
    start = np.sin(w_peak * t)[:, None] * rng.standard_normal(m)[None, :] + 0.1 * rng.standard_normal((steps, m))
    gains = trajectory_gains(system, trajs, h, iterations=iterations, start=start, seed=seed)
    named = [(name, float(g), h, float(steps * h)) for (name, _), g in zip(trajs, gains)]
    if long_horizon is None:
        A = system(where if np.size(where) else np.array([0.5 * (a[0] + a[-1]) for a in model.axes]))[0]
        slowest = float(np.min(np.abs(np.linalg.eigvals(A).real)))
        long_horizon = min(LONG_TIME_CONSTANTS / slowest, LONG_HORIZON_MAX) if slowest > 0 else LONG_HORIZON_MAX
        long_horizon = long_horizon if long_horizon > 2.0 * steps * h else False
    if long_horizon:
        named += long_runs(model, system, rates, float(long_horizon), h, iterations=iterations, seed=seed)
    best_name, best, h_best, t_best = ("at rest (frozen)", frozen if np.isfinite(frozen) else 0.0, h, steps * h)
    for name, g, hk, tk in named:
        if g > best:
            best_name, best, h_best, t_best = name, g, hk, tk
    return TrajectoryLowerBound(float(best), float(frozen), best_name, len(named), h_best, float(t_best),
                                time.perf_counter() - t0, tuple((name, g) for name, g, _, _ in named))  # fmt: skip


def long_runs(model, system, rates, horizon: float, h: float, *, iterations: int = ITERATIONS, seed: int = 0):
    """Gains along long runs: ``[(name, gain, step, horizon)]``, the names ending in ``over N s``.

    A loop with a slow pole (the main job's: 0.002 rad/s, from its weights'
    near-integrators) keeps gaining along a bang-bang velocity for hundreds
    of seconds, so the short horizon of :func:`trajectory_lower_bound` (tens
    of seconds) misses it.  The bang-bang velocities of
    :func:`admissible_trajectories` (triangle waves at the acceleration
    limit), each with the positions that stay put at their ends and
    midpoints, over ``horizon`` seconds (slow swings there stayed at the
    frozen gain on the main job's loop).  The step: ``h`` or
    ``horizon / LONG_STEPS``, whichever is longer, then shortened to a whole
    number of steps per shortest bang-bang period, at least
    ``1 / LONG_STEP_PER_PERIOD`` of them (finer than ``h`` when that period
    asks for it); at most :data:`LONG_STEPS` steps, the horizon shortened
    when it would take more.
    """
    acc = [min(abs(r[0]), abs(r[1])) for r, k in zip(rates, model.kinds) if k == "qdot"]
    vmax = [float(np.abs(a).max()) for a, k in zip(model.axes, model.kinds) if k == "qdot"]
    periods = [4.0 * v / a for v, a in zip(vmax, acc) if v > 0 and np.isfinite(a) and a > 0]
    h_long = max(h, horizon / LONG_STEPS)
    if periods:  # a whole number of steps per shortest period: its bang-bang repeats, step for step
        shortest = min(periods)
        h_long = shortest / max(np.ceil(shortest / h_long), 1.0 / LONG_STEP_PER_PERIOD)
    steps = max(8, min(LONG_STEPS, int(round(horizon / h_long))))
    t = np.arange(steps) * h_long
    trajs = admissible_trajectories(model, rates, t, seed=seed, levels=True, families=("bang-bang",))
    gains = trajectory_gains(system, trajs, h_long, iterations=iterations, seed=seed)
    over = f" over {steps * h_long:.4g} s"
    return [(name + over, float(g), h_long, float(steps * h_long)) for (name, _), g in zip(trajs, gains)]
