"""Membership in a computed-torque factor LFT: is a Jacobian pair ``(A, B)`` a member of the ``inner-gain``/``inner-links`` set?

Split from :mod:`~polyrob.plant.models.inner_factors` (whose module text
states the LFT): a member has the model's kinematic rows, and its factor
``K_raw = [B_low^-1 A_low, I - B_low^-1]`` less the centre and ``sum_k
theta_k K_k,c`` is a residual within every block's ball for some
``theta`` of the box.  That residual's largest scaled norm is convex in
``theta``, so membership is a convex minimisation over a few scalars
(:func:`convex_box_minimum`).  The coverage checks of both models call
:func:`inner_factors_contains`.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from polyrob.plant.lftplant import UncertainPlant

__all__ = [
    "reached_entries",
    "scaled_residuals",
    "scaled_residual_norm",
    "convex_box_minimum",
    "inner_factors_contains",
    "ZOOM_ROUNDS",
    "ZOOM_SCALARS",
]


def reached_entries(unc: UncertainPlant) -> np.ndarray:
    """The entries of the factor that a residual block (or an entry's real scalar) carries."""
    reached = np.zeros(unc.info["K_centres"].shape[1:], bool)
    for b in unc.info["residual_blocks"]:
        reached[np.ix_(b["rows"], b["cols"])] = True
    entries = np.asarray(unc.info.get("residual_entries", np.zeros((0, 2), int)), int).reshape(-1, 2)
    reached[entries[:, 0], entries[:, 1]] = True
    return reached


def _weighted_residual(unc: UncertainPlant, E: np.ndarray) -> np.ndarray:
    """``W E diag(I, W^-1)``: the residual in the coordinates its bounds are stated in (``E`` without a weighting)."""
    W = unc.info.get("residual_weighting")
    if W is None:
        return E
    m = W.shape[0]
    E = W @ E
    E[:, 2 * m :] = np.linalg.solve(W.T, E[:, 2 * m :].T).T
    return E


def scaled_residuals(unc: UncertainPlant, E: np.ndarray, moving: bool | None = None) -> list[np.ndarray]:
    """``E`` (``m x 3m``, a residual of the factor) as the square blocks of ``unc.full_blocks``, scaled by their weights.

    ``unc.matrices_at(delta, residual=scaled_residuals(unc, E))`` is the
    member with residual ``E``; it is in the set when each block's norm is
    at most one.  ``moving`` (a model with motion blocks,
    :mod:`polyrob.plant.moving_links`): only the blocks whose ``moving`` flag
    is that, the part of the residual they carry.
    """
    E = _weighted_residual(unc, E)
    out = []
    for b, size in zip(unc.info["residual_blocks"], unc.full_blocks):
        if moving is not None and bool(b.get("moving", False)) is not moving:
            continue
        S = np.zeros((size, size))
        part, W_l, W_r = E[np.ix_(b["rows"], b["cols"])], np.asarray(b["W_l"]), np.asarray(b["W_r"])
        # diagonal weights (entry radii), or the matrices of a shaped block (W_l^-1 E W_r^-1)
        part = np.linalg.solve(W_l, part) if W_l.ndim == 2 else part / W_l[:, None]
        part = np.linalg.solve(W_r.T, part.T).T if W_r.ndim == 2 else part / W_r[None, :]
        S[: len(b["rows"]), : len(b["cols"])] = part
        out.append(S)
    return out


def scaled_residual_norm(unc: UncertainPlant, K_raw, theta, rtol: float, reached) -> float:
    """The largest scaled norm of the residual ``K_raw - sum theta_k K_k,c`` over its blocks (convex in ``theta``).

    An entry that no residual block reaches (``~reached``) must
    match: its mismatch relative to ``rtol`` counts instead when it is larger.
    """
    E = K_raw - unc.info.get("K_offset", 0.0) - np.tensordot(theta, unc.info["K_centres"], axes=1)
    mismatch = np.abs(E[~reached]).max(initial=0.0) / (rtol * (1.0 + np.abs(K_raw).max()))
    norms = [float(np.linalg.norm(S, 2)) for S in scaled_residuals(unc, E)]
    entries = np.asarray(unc.info.get("residual_entries", np.zeros((0, 2), int)), int).reshape(-1, 2)
    if len(entries):  # each entry within its real scalar's radius
        weighted = _weighted_residual(unc, E)
        norms.append(float(np.max(np.abs(weighted[entries[:, 0], entries[:, 1]]) / unc.info["residual_entry_radii"])))
    return max([mismatch, *norms])


#: Rounds of the zoomed grid of :func:`convex_box_minimum` (its span halves each round: 2^-12 of the box).
ZOOM_ROUNDS = 12
#: The zoom runs for up to this many scalars (a grid of 9^3 points a round; more scalars get 3 points an axis).
ZOOM_SCALARS = 3


def convex_box_minimum(f, start, r, points: int = 9, max_grid: int = 729) -> float:
    """The minimum of a convex, non-smooth ``f`` over the box ``|theta_k| <= r_k`` (a few scalars).

    Nelder-Mead alone stalls at the kinks of a largest singular value (ur5
    with a payload: 5 % of its own true robots' Jacobians refused), so it
    polishes the best point of a ``points^P`` grid as well as ``start``,
    and when that still stays above 1 zooms the grid on its best point
    (:data:`ZOOM_ROUNDS`, up to :data:`ZOOM_SCALARS` scalars); the grid has at most ``max_grid`` points (fewer
    per axis for many scalars: 9^6 would be half a million residual norms
    per Jacobian).  An upper bound of the minimum: a value above 1 may be a
    member the search missed, never the reverse.
    """
    points = max(2, min(points, int(round(max_grid ** (1.0 / max(len(r), 1))))))
    axes = [np.linspace(-rk, rk, points) for rk in r]
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(r), -1).T
    values = np.array([f(t) for t in grid])
    bounds = list(zip(-r, r))
    best = float(values.min())
    for x0 in (start, grid[int(np.argmin(values))]):
        if best <= 1.0:
            break
        best = min(best, float(minimize(f, x0, method="Nelder-Mead", bounds=bounds).fun))
    if best > 1.0 and len(r) == 2:
        best = min(best, _nested_minimum(f, r))
    # Nelder-Mead also stalls on a kink's ridge (planar_2r with a 0-2 kg payload: 6 of 1000 fresh members
    # refused, their minimum 0.46-0.89): zoom the grid on its best point, halving its span each round
    centre, half = grid[int(np.argmin(values))], np.asarray(r, float).copy()
    for _ in range(ZOOM_ROUNDS if best > 1.0 and len(r) <= ZOOM_SCALARS else 0):
        half = half / 2
        axes = [np.linspace(max(c - h, -rk), min(c + h, rk), points) for c, h, rk in zip(centre, half, r)]
        grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(r), -1).T
        values = np.array([f(t) for t in grid])
        centre = grid[int(np.argmin(values))]
        best = min(best, float(values.min()))
        if best <= 1.0:
            break
    return best


def _nested_minimum(f, r, xatol: float = 1e-9) -> float:
    """The minimum of a convex ``f`` of two scalars over the box ``|theta_k| <= r_k``, one scalar inside the other.

    ``g(t0) = min_t1 f(t0, t1)`` is convex too, so a bounded scalar search of
    ``g`` whose every value is a bounded scalar search in ``t1`` finds the
    minimum however narrow and oblique its valley: kinova's default task (a
    common link factor and a payload mass, whose inertia effects nearly
    coincide) had a member whose valley, below 1 over a thousandth of the
    factor's range, the grid and its zoom missed (1.36 where the minimum is 0.29).
    """

    def inner(t0):
        found = minimize_scalar(lambda t1: f(np.array([t0, t1])), bounds=(-r[1], r[1]), method="bounded",
                                options={"xatol": xatol * r[1]})  # fmt: skip
        return float(found.fun)

    found = minimize_scalar(inner, bounds=(-r[0], r[0]), method="bounded", options={"xatol": xatol * r[0]})
    return float(found.fun)


def inner_factors_contains(unc: UncertainPlant, A, B, *, rtol: float = 1e-9) -> np.ndarray:
    """Whether Jacobians lie in the set of :func:`inner_factors_plant`.

    A member has ``K_raw = [B_low^-1 A_low, I - B_low^-1] = sum theta_k
    K_k,c + E`` for a ``theta`` in the box and a residual ``E`` the block
    covers: the scaled norm of ``E`` is convex in ``theta``, so its minimum
    over the box (a bounded search for one scalar; from the least-squares
    fit of ``K_raw`` by the centres, a local search for more)
    must be at most 1.  Entries no block reaches must match exactly: when
    they pin all scalars but at most one direction, the minimum is taken on
    that segment of the box (:func:`_pinned_line`).
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    if A.ndim == 2:
        A, B = A[None], B[None]
    m = unc.m
    r = np.asarray(unc.info["theta_range"], float)
    centres = unc.info["K_centres"].reshape(len(r), -1).T
    reached = reached_entries(unc)
    out = np.ones(len(A), bool)
    for i in range(len(A)):
        if not (np.allclose(A[i, :m], unc.A_mid[:m], atol=rtol) and np.allclose(B[i, :m], 0.0, atol=rtol)):
            out[i] = False
            continue
        inverse = np.linalg.inv(B[i, m:])
        K_raw = np.hstack([inverse @ A[i, m:], np.eye(m) - inverse])

        def f(theta, K_raw=K_raw):
            return scaled_residual_norm(unc, K_raw, np.atleast_1d(np.asarray(theta, float)), rtol, reached)

        shifted = (K_raw - unc.info.get("K_offset", 0.0)).ravel()
        pinned = _pinned_line(centres[~reached.ravel()], shifted[~reached.ravel()], r)
        if pinned is not None and pinned != "outside" and _line_minimum(f, *pinned) <= 1.0 + 1e-7:
            out[i] = True
            continue
        # the pinned segment can miss (kinova's inner-gain model: 0.16 of fresh points, 1.0 before it was
        # solved for): the box search below decides then, as it did; a member needs f <= 1 at a point either way
        start = np.clip(np.linalg.lstsq(centres, shifted, rcond=None)[0], -r, r)
        best = f(start)
        if best > 1.0 and len(r) == 1:
            best = min(best, minimize_scalar(f, bounds=(-r[0], r[0]), method="bounded").fun)
        elif best > 1.0:
            best = min(best, convex_box_minimum(f, start, r))
        out[i] = best <= 1.0 + 1e-7
    return out


def _pinned_line(C, e, r):
    """The scalars an exact entry pins: ``(theta0, direction, z_lo, z_hi)`` with ``theta = theta0 + z direction``.

    Entries no residual block reaches must match exactly, ``C theta = e``;
    a search over the whole box (a grid, Nelder-Mead) never lands on that
    affine set (ur5's ``G[5, 5]`` with a link factor and a payload mass: 15 %
    of fresh members refused), so it is solved for.  ``None`` when no scalar
    moves those entries or more than one direction stays free (the box
    search then decides); ``"outside"`` when the solution leaves the box.
    """
    moved = np.abs(C).max(axis=1, initial=0.0) > 0
    if not moved.any():
        return None
    C, e = C[moved], e[moved]
    _, S, Vt = np.linalg.svd(C)
    rank = int(np.sum(S > 1e-12 * S.max()))
    free = Vt[rank:]
    if len(free) > 1:
        return None
    theta0 = np.linalg.lstsq(C, e, rcond=None)[0]
    slack = r * (1 + 1e-9) + 1e-15
    if not len(free):
        return "outside" if np.any(np.abs(theta0) > slack) else (theta0, np.zeros_like(theta0), 0.0, 0.0)
    d = free[0]
    lo, hi = -np.inf, np.inf
    for t0, dk, sk in zip(theta0, d, slack):
        if abs(dk) < 1e-15:
            if abs(t0) > sk:
                return "outside"
            continue
        a, b = sorted(((-sk - t0) / dk, (sk - t0) / dk))
        lo, hi = max(lo, a), min(hi, b)
    return "outside" if lo > hi else (theta0, d, lo, hi)


def _line_minimum(f, theta0, d, lo, hi) -> float:
    """The minimum of the convex ``f`` on the segment ``theta0 + z d``, ``lo <= z <= hi`` (grid, then bounded search)."""
    if hi - lo <= 0.0:
        return float(f(theta0 + lo * d))
    zs = np.linspace(lo, hi, 17)
    values = [float(f(theta0 + z * d)) for z in zs]
    k = int(np.argmin(values))
    a, b = zs[max(k - 1, 0)], zs[min(k + 1, len(zs) - 1)]
    polished = minimize_scalar(lambda z: f(theta0 + z * d), bounds=(a, b), method="bounded", options={"xatol": 1e-12})
    return min(values[k], float(polished.fun))
