"""The Lyapunov basis of the moving-robot certificate, and the re-check of its ``X`` on a finer grid.

:func:`default_basis` gives ``X(rho) = sum_j f_j(rho) X_j`` on the robot's
state ``rho = (q_i, qdot_j)``:

* ``tensor=False`` (separable): ``1, cos q_i, sin q_i, qdot_j``;
* ``tensor=True``: the products ``{1, cos q_i, sin q_i} x {1, qdot_j}``, so
  that the velocity part of ``X`` may differ from one position to another.
  On ``paper_2r`` it is what closes the gap to the frozen peak: the
  separable basis leaves 2.49 even with every rate 0 (frozen loops) against
  a frozen peak of 0.726, the tensor one proves 0.735 with the domain's
  rates (docs/certificates.md).

:func:`finer_recheck` re-checks the ``X(rho)`` a search returned, unchanged,
at the points of a finer grid (every point and rate vertex, the float64
check of :func:`polyrob.analysis.lpv.check.check_solution`): the level it
proves there.  It is still a grid, denser: no bound between its points.

Examples
--------
>>> import numpy as np, polyrob
>>> from polyrob.domains.torque_box import Domain
>>> from polyrob.analysis.lpv.robot import scheduling
>>> robot = polyrob.load_robot("paper_2r")
>>> model = scheduling(robot, Domain.from_robot(robot, "paper"), points=(5, 3))
>>> len(default_basis(model)), len(default_basis(model, tensor=True))
(5, 9)
"""

from __future__ import annotations

from functools import partial

import numpy as np

__all__ = ["default_basis", "basis_size", "finer_recheck", "failing_points", "even_functions", "constant_function"]


def _unit(p: int, i: int, dv: float) -> np.ndarray:
    g = np.zeros(p)
    g[i] = dv
    return g


# The basis functions are module-level functions bound by functools.partial, not closures: the moving
# robot's cells check sends the basis to worker processes, which pickle it (polyrob.analysis.lpv.cells).
def _one(r):
    return 1.0


def _zero_grad(r, p):
    return np.zeros(p)


def _cos(r, i, k):
    return np.cos(k * r[i])


def _cos_grad(r, p, i, k):
    return _unit(p, i, -k * np.sin(k * r[i]))


def _sin(r, i, k):
    return np.sin(k * r[i])


def _sin_grad(r, p, i, k):
    return _unit(p, i, k * np.cos(k * r[i]))


def _coordinate(r, i):
    return r[i]


def _coordinate_grad(r, p, i):
    return _unit(p, i, 1.0)


def _pair(r, a, b):
    return r[a] * r[b]


def _pair_grad(r, p, a, b):
    return _unit(p, a, r[b]) + _unit(p, b, r[a])


def _times(r, fa, fb):
    return fa(r) * fb(r)


def _times_grad(r, fa, ga, fb, gb):
    return np.asarray(ga(r)) * fb(r) + fa(r) * np.asarray(gb(r))


def constant_function(p: int):
    """The basis function ``1`` on ``p`` parameters, as ``(f, grad)`` (picklable)."""
    return partial(_one), partial(_zero_grad, p=p)


def _position_functions(model, harmonics: int = 1):
    p = len(model.names)
    out = [constant_function(p)]
    for i, kind in enumerate(model.kinds):
        if kind == "q":
            for k in range(1, int(harmonics) + 1):
                out.append((partial(_cos, i=i, k=k), partial(_cos_grad, p=p, i=i, k=k)))
                out.append((partial(_sin, i=i, k=k), partial(_sin_grad, p=p, i=i, k=k)))
    return out


def _velocity_functions(model, quadratic: bool):
    p = len(model.names)
    vel = [i for i, k in enumerate(model.kinds) if k == "qdot"]
    out = [(partial(_coordinate, i=i), partial(_coordinate_grad, p=p, i=i)) for i in vel]
    if quadratic:
        for a in vel:
            for b in vel:
                if b >= a:
                    out.append((partial(_pair, a=a, b=b), partial(_pair_grad, p=p, a=a, b=b)))
    return out


def _product(f, g):
    (fa, ga), (fb, gb) = f, g
    return partial(_times, fa=fa, fb=fb), partial(_times_grad, fa=fa, ga=ga, fb=fb, gb=gb)


def default_basis(model, *, quadratic: bool = False, tensor: bool = False, harmonics: int = 1):
    """Basis of ``X(rho)``: ``1``, ``cos q_i``, ``sin q_i``, ``qdot_j`` (``quadratic``: and their products).

    ``tensor=True``: every position function times every velocity function
    (``{1, cos q_i, sin q_i} x {1, qdot_j, ...}``); ``harmonics=K``: the
    position functions ``cos k q_i, sin k q_i`` for ``k <= K``.

    Returns
    -------
    list of (f, grad)
    """
    pos, vel = _position_functions(model, harmonics), _velocity_functions(model, quadratic)
    if not tensor:
        return pos + vel
    return pos + [_product(f, g) for g in vel for f in pos]


def even_functions(basis, lo, hi, samples: int = 8):
    """The functions of ``basis`` that are even in ``rho`` (``f(-rho) = f(rho)`` at random points of the box)."""
    pts = np.random.default_rng(1).uniform(lo, hi, size=(samples, len(lo)))
    return [(f, g) for f, g in basis if all(abs(f(r) - f(-r)) <= 1e-12 * (1 + abs(f(r))) for r in pts)]


def basis_size(model, *, quadratic: bool = False, tensor: bool = False, harmonics: int = 1) -> int:
    """The number of basis functions of :func:`default_basis` (without building them)."""
    n_pos = 1 + 2 * int(harmonics) * sum(k == "q" for k in model.kinds)
    n_vel = sum(k == "qdot" for k in model.kinds)
    if quadratic:
        n_vel += n_vel * (n_vel + 1) // 2
    return n_pos * (1 + n_vel) if tensor else n_pos + n_vel


def finer_recheck(system, model, result, rates, basis, *, points=(9, 5), c: float = 1.0) -> dict:
    """The level the returned ``X(rho)`` proves on a finer grid of the same box (sampled: still a grid).

    Parameters
    ----------
    system : callable
        The (conditioned, time-scaled) system the search was run on.
    model : MovingRobotModel
    result : LpvNormResult
        Its ``X`` (the coefficients in ``basis``, in ``system``'s coordinates).
    rates : sequence of (float, float)
        The rate bounds in physical time (divided by ``c`` here).
    basis : sequence of (f, grad) or None
        ``None``: the constant ``X`` of an arbitrarily fast search.
    points : (int, int)
        Points per position and per velocity parameter of the finer grid.
    c : float
        The time scale of ``system``.

    Returns
    -------
    dict
        ``points`` (the finer grid's size), ``gamma`` (``inf`` when ``X`` fails
        there: then ``reason``), ``holds_at_gamma`` (the search's level holds
        there too).
    """
    from polyrob.analysis.lpv.check import check_solution, proved_gamma

    if not result.proved or not result.X:
        return {"points": 0, "gamma": float("inf"), "holds_at_gamma": False, "reason": "nothing proved to re-check"}
    data, Xs = _recheck_data(system, model, result, rates, basis, points, c)
    at_level = check_solution(data, Xs, result.gamma)
    gamma, chk = proved_gamma(data, Xs, result.gamma)
    out = {"points": int(data.A.shape[0]), "gamma": float(gamma), "holds_at_gamma": bool(at_level.holds)}
    if not np.isfinite(gamma):
        out["reason"] = chk.reason
    return out


def _recheck_data(system, model, result, rates, basis, points, c):
    """The finer grid's data on power-of-two balanced states (exact: ``x = S x~``) and ``X_j`` there."""
    from polyrob.analysis.lpv.check import GridData
    from polyrob.analysis.lpv.data import evaluate
    from polyrob.analysis.lpv.norm import state_scaling
    from polyrob.analysis.lpv.robot import kinematic_rates

    axes = [
        np.linspace(a[0], a[-1], int(points[0] if kind == "q" else points[1])) if a.size > 1 else a
        for a, kind in zip(model.axes, model.kinds)
    ]
    if basis is None:
        ev = evaluate(system, axes)
    else:
        scaled = [(lo / c, hi / c) for lo, hi in rates]
        ev = evaluate(system, axes, scaled, basis, kinematic_rates(model, rates, c))
    d = ev.data  # checked, like lpvnorm's own check, on power-of-two balanced states (exact: x = S x~)
    sc = state_scaling(d.A)
    data = GridData(
        d.A / sc[None, :, None] * sc[None, None, :], d.B / sc[None, :, None], d.C * sc[None, None, :], d.D,
        d.F, d.G, d.nus, d.points,
    )  # fmt: skip
    return data, np.asarray(result.X, dtype=float) * sc[None, :, None] * sc[None, None, :]


def failing_points(system, model, result, rates, basis, *, points, c: float, level: float, most: int) -> np.ndarray:
    """The finer grid's points where the returned ``X`` is not proved at ``level``, worst first (at most ``most``).

    The same check as :func:`finer_recheck` (every rate vertex, the float
    rounding allowed for), point by point: the points to add to a search
    whose ``X`` fails between its grid points (constraint generation).

    Returns
    -------
    ndarray
        ``(N, p)`` parameter points.
    """
    from polyrob.analysis.lpv.check import brl_matrices

    if not result.proved or not result.X:
        return np.zeros((0, len(model.axes)))
    data, Xs = _recheck_data(system, model, result, rates, basis, points, c)
    M, err, _, _ = brl_matrices(data, Xs, level)
    worst = (np.linalg.eigvalsh(M)[..., -1] + err).max(axis=1)
    order = [i for i in np.argsort(-worst)[: int(most)] if worst[i] >= 0]
    return data.points[order]
