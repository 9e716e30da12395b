"""What no controller can do: the performance limit of the robot's unstable poles.

At a point ``(q, qdot, u)`` of the domain the frozen plant ``G = C (sI - A)^{-1} B``
(``y = q``) may have unstable poles (a joint accelerating away under gravity
or centrifugal torque).  For an open-loop pole ``p`` in the right half plane
with output direction ``y_p`` (``‖y_p‖ = 1``), every stabilising controller
has ``T(p) y_p = y_p``, so by the maximum modulus principle

    ``‖W_T T‖∞ ≥ ‖W_T(p) y_p‖₂``

(the interpolation constraint of a right-half-plane pole: Skogestad &
Postlethwaite, *Multivariable Feedback Control*, 2nd ed., ch. 6; ``W_T``
stable and proper).  Robust performance with the
weights ``W_S``, ``W_T`` asks ``‖[W_S S; W_T T]‖∞ < 1`` for every plant of
the uncertainty model, and a model that covers the robot (coverage 1.0)
contains this frozen plant: so ``‖W_T(p) y_p‖`` is a lower bound on the
robust-performance μ of **every** controller on **every** covering model,
with constant or time-varying parameters.  When it is at least 1, μ < 1 is
out of reach at these weights, whatever the synthesis.

The bound found is a true bound (it is that of a point of the domain); the
search for the worst point (a Sobol' design, then a local search from the
best points) may miss a larger one, which would only make the limit higher.
The robot's plant has no finite transmission zeros (``B = [0; M(q)^{-1}]``
and ``y = q``: ``G(s) = (s^2 I - s A_22 - A_21)^{-1} M^{-1}``), so the
zeros' counterpart for ``W_S S`` does not arise.

Nothing in python-control or SLICOT computes this over a parameter domain,
hence the code here.

Examples
--------
>>> import polyrob
>>> from polyrob import Domain
>>> from polyrob.plant.weights import paper_weights
>>> robot = polyrob.load_robot("paper_2r")
>>> lim = performance_limit(robot, Domain.from_robot(robot, "paper"), paper_weights()[1], samples=1024)
>>> round(lim.bound, 2), round(lim.pole.real, 1), lim.excludes_mu_below_one
(0.65, 7.5, False)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.errors import ArgumentError

__all__ = ["PerformanceLimit", "performance_limit", "pole_bound", "marginal_tolerance"]


def marginal_tolerance(A) -> float:
    """The real part below which an eigenvalue of ``A`` is 0 to the precision of ``A``.

    ``sqrt(eps) * max(1, ‖A‖_F)``: round-off of size ``eps ‖A‖`` in a
    double eigenvalue at 0 (a double integrator: a joint without gravity or
    stiffness) splits it into ``±sqrt(eps ‖A‖)``, e.g. ``±1.1e-9`` rad/s;
    such a pole is marginal, not unstable.

    >>> f"{marginal_tolerance(np.eye(2)):.3g}"  # sqrt(eps) * sqrt(2)
    '2.11e-08'
    """
    return float(np.sqrt(np.finfo(float).eps) * max(1.0, np.linalg.norm(A)))


@dataclass(frozen=True, eq=False)
class PerformanceLimit:
    """A lower bound on ``‖W_T T‖∞`` (hence on robust-performance μ) for every controller.

    Attributes
    ----------
    bound : float
        ``‖W_T(p) y_p‖`` at the worst point found; 0 when no point of the
        domain has an unstable pole.
    pole : complex or None
        The unstable open-loop pole ``p`` there (rad/s).
    direction : ndarray or None
        Its output direction ``y_p`` (unit norm, over the joints).
    q, qdot, u : ndarray or None
        The point of the domain.
    points : int
        Domain points evaluated (design and local search).
    """

    bound: float
    pole: complex | None
    direction: np.ndarray | None
    q: np.ndarray | None
    qdot: np.ndarray | None
    u: np.ndarray | None
    points: int

    @property
    def excludes_mu_below_one(self) -> bool:
        """True when no controller can reach robust-performance μ < 1 at these weights."""
        return self.bound >= 1.0

    def summary(self) -> str:
        """One or two lines for a person."""
        if self.pole is None:
            return f"performance limit: no unstable open-loop pole at {self.points} points of the domain"
        where = f"q = {np.round(self.q, 3).tolist()}, qdot = {np.round(self.qdot, 3).tolist()}"
        head = (
            f"performance limit: every stabilising controller has mu >= {self.bound:.4f} (||W_T T|| at the "
            f"frozen plant at {where}, unstable pole {self.pole.real:.3g} rad/s; {self.points} points searched)"
        )
        if self.excludes_mu_below_one:
            head += "; mu < 1 is out of reach at these weights: raise the bandwidths (--bandwidth-scale)"
        return head

    def to_dict(self) -> dict:
        return {
            "bound": self.bound,
            "excludes_mu_below_one": self.excludes_mu_below_one,
            "pole": None if self.pole is None else [self.pole.real, self.pole.imag],
            "direction_abs": None if self.direction is None else np.abs(self.direction).tolist(),
            "q": None if self.q is None else self.q.tolist(),
            "qdot": None if self.qdot is None else self.qdot.tolist(),
            "u": None if self.u is None else self.u.tolist(),
            "points": self.points,
        }


class _WeightAt:
    """``W_T(s)`` as an ``m x m`` complex matrix, from state-space matrices computed once.

    (A SISO weight acts on every channel.)  Converting a MIMO transfer
    function to state space costs milliseconds: it must not happen per pole.
    """

    def __init__(self, W_T, m: int):
        import control

        self.m = m
        if isinstance(W_T, (int, float, complex, np.ndarray)):
            D = np.atleast_2d(np.asarray(W_T, dtype=complex))
            self.mats = (np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D)
        else:
            W = control.ss(W_T)
            self.mats = tuple(np.asarray(X, dtype=complex) for X in (W.A, W.B, W.C, W.D))
        shape = self.mats[3].shape
        if shape not in ((1, 1), (m, m)):
            raise ArgumentError(f"W_T must be SISO or {m}x{m}, got {shape}")

    def __call__(self, s: complex) -> np.ndarray:
        A, B, C, D = self.mats
        val = D + (C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B) if A.shape[0] else 0)
        return val[0, 0] * np.eye(self.m) if val.shape == (1, 1) else val


def pole_bound(A: np.ndarray, W_T, m: int) -> tuple[float, complex | None, np.ndarray | None]:
    """``max_p ‖W_T(p) y_p‖`` over the unstable eigenvalues ``p`` of one ``A`` (``y = q``).

    Examples
    --------
    A unit mass pushed away from its equilibrium (``qddot = q + u``: pole at +1),
    with a constant weight 2: every stabilising controller has ``‖2 T‖∞ >= 2``.

    >>> pole_bound(np.array([[0.0, 1.0], [1.0, 0.0]]), 2.0, 1)[:2]
    (2.0, (1+0j))

    A double integrator computed with round-off (poles ``±1.14e-9``) has no
    unstable pole: its poles are 0 to the precision of ``A``.

    >>> pole_bound(np.array([[0.0, 1.0], [1.3e-18, 0.0]]), 2.0, 1)[:2]
    (0.0, None)
    """
    weight = W_T if isinstance(W_T, _WeightAt) else _WeightAt(W_T, m)
    ev, V = np.linalg.eig(A)
    best, pole, direction = 0.0, None, None
    for j in np.flatnonzero(ev.real > marginal_tolerance(A)):
        y = V[:m, j]
        ny = np.linalg.norm(y)
        if ny == 0:  # a pole not seen at the output cannot constrain T
            continue
        y = y / ny
        b = float(np.linalg.norm(weight(complex(ev[j])) @ y))
        if b > best:
            best, pole, direction = b, complex(ev[j]), y
    return best, pole, direction


def performance_limit(robot, domain, W_T, *, samples: int = 4096, starts: int = 4, seed: int = 0) -> PerformanceLimit:
    """The largest ``‖W_T(p) y_p‖`` found over the domain: a floor under every controller's μ.

    Parameters
    ----------
    robot : Manipulator
    domain : Domain
    W_T : LTI system, array or number
        The complementary-sensitivity weight (SISO, or ``m x m``).
    samples : int
        Points of the scrambled Sobol' design.
    starts : int
        Local searches (bounded Powell) from the best design points.
    seed : int

    Returns
    -------
    PerformanceLimit
    """
    from scipy.optimize import minimize

    if samples < 1 or starts < 0:
        raise ArgumentError(f"samples must be >= 1 and starts >= 0, got {samples}, {starts}")
    m = robot.m
    W_T = _WeightAt(W_T, m)
    # box points (a task domain's third group is the acceleration) and the points (q, qdot, u) they stand for
    z_box = domain.sample_box(samples, seed=seed) if hasattr(domain, "sample_box") else None
    q, qd, u = domain.sample(samples, seed=seed) if z_box is None else domain.split(domain.points(z_box))
    z_box = np.hstack([q, qd, u]) if z_box is None else z_box
    A, _ = robot.jacobians_batch(q, qd, u)
    # screen on the largest real part first: only the unstable points matter
    unstable = np.flatnonzero(np.linalg.eigvals(A).real.max(axis=1) > 0)
    scores = np.zeros(samples)
    for k in unstable:
        scores[k] = pole_bound(A[k], W_T, m)[0]
    evaluated = samples
    lo, hi = domain.lower, domain.upper
    free = hi > lo  # the local search moves only the coordinates the domain lets vary

    def point(z_free, z0):
        z = z0.copy()
        z[free] = np.clip(z_free, lo[free], hi[free])
        return z

    def negative(z_free, z0):
        nonlocal evaluated
        evaluated += 1
        qq, vv, uu = _point(domain, point(z_free, z0))
        Ak, _ = robot.jacobians(qq[0], vv[0], uu[0])
        return -pole_bound(Ak, W_T, m)[0]

    best_z = z_box[0]
    best = scores[0]
    order = np.argsort(-scores)
    if scores[order[0]] > 0:
        best_z, best = z_box[order[0]], scores[order[0]]
        bounds = list(zip(lo[free], hi[free]))
        for k in order[: min(starts, len(unstable))] if free.any() else []:
            z0 = z_box[k].copy()
            res = minimize(
                negative, z0[free], args=(z0,), method="Powell", bounds=bounds, options={"xtol": 1e-6, "maxfev": 400}
            )
            if -res.fun > best:
                best, best_z = -res.fun, point(res.x, z0)
    qq, vv, uu = _point(domain, best_z)
    Ak, _ = robot.jacobians(qq[0], vv[0], uu[0])
    bound, pole, direction = pole_bound(Ak, W_T, m)  # recomputed at the clipped point: what is reported is its own
    return PerformanceLimit(
        bound=bound,
        pole=pole,
        direction=direction,
        q=qq[0] if pole is not None else None,
        qdot=vv[0] if pole is not None else None,
        u=uu[0] if pole is not None else None,
        points=evaluated,
    )


def _point(domain, z):
    """``(q, qdot, u)`` of a box point (a task domain maps its acceleration to the torque)."""
    return domain.split(domain.points(z) if hasattr(domain, "points") else z)
