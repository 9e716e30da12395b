"""Input checks and the evaluation of a gridded LPV system, its basis and its rate box.

Examples
--------
>>> import numpy as np
>>> sysf = lambda r: (np.array([[-1.0 - r[0]]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)))
>>> affine = [(lambda r: 1.0, lambda r: [0.0]), (lambda r: r[0], lambda r: [1.0])]
>>> ev = evaluate(sysf, [np.linspace(0.0, 1.0, 3)], [(-1.0, 1.0)], affine)
>>> ev.data.A.shape, ev.data.nus.tolist()
((3, 1, 1), [[-1.0], [1.0]])
>>> evaluate(sysf, [np.linspace(0.0, 1.0, 3)], [(-1.0, 1.0)], affine[:1]).data.nus.tolist()  # X free of r
[[-1.0]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.analysis.lpv.check import GridData, rate_vertices
from polyrob.errors import ArgumentError

__all__ = ["Evaluated", "evaluate", "check_grid", "check_rate_bounds"]


@dataclass(frozen=True, eq=False)
class Evaluated:
    """The grid evaluated: the data, the box of the parameters and what was constant.

    Attributes
    ----------
    data : GridData
    lo, hi : ndarray
        The parameter box ``[min grid, max grid]``.
    constant_x : bool
        No basis was given: one constant ``X``.
    """

    data: GridData
    lo: np.ndarray
    hi: np.ndarray
    constant_x: bool


def check_grid(grid) -> list[np.ndarray]:
    """The grid as a list of sorted, unique, finite 1-D float arrays.

    Parameters
    ----------
    grid : sequence of array_like

    Returns
    -------
    list of ndarray

    Raises
    ------
    ArgumentError
        Empty, not 1-D, or not finite (NaN, inf).
    """
    if isinstance(grid, np.ndarray) and grid.ndim == 1:
        raise ArgumentError("grid must be a sequence of p 1-D arrays (one per parameter), e.g. [np.linspace(0, 1, 5)]")
    try:
        axes = [np.asarray(g, dtype=float) for g in grid]
    except (TypeError, ValueError) as exc:
        raise ArgumentError(f"grid must be a sequence of 1-D float arrays: {exc}") from exc
    if not axes:
        raise ArgumentError("grid has no parameter")
    for i, g in enumerate(axes):
        if g.ndim != 1 or g.size == 0:
            raise ArgumentError(f"grid[{i}] must be a non-empty 1-D array (got shape {g.shape})")
        if not np.all(np.isfinite(g)):
            raise ArgumentError(f"grid[{i}] has a non-finite value (NaN or inf)")
    return [np.unique(g) for g in axes]


def check_rate_bounds(rate_bounds, p: int) -> list[tuple[float, float]]:
    """The rate bounds as ``p`` pairs ``(lo, hi)``, ``lo <= hi``, no NaN (``±inf`` allowed).

    Parameters
    ----------
    rate_bounds : sequence of (lo, hi)
    p : int
        Number of parameters.

    Returns
    -------
    list of (float, float)
    """
    try:
        rb = [(float(lo), float(hi)) for lo, hi in rate_bounds]
    except (TypeError, ValueError) as exc:
        raise ArgumentError(f"rate_bounds must be a sequence of p pairs (lo, hi): {exc}") from exc
    if len(rb) != p:
        raise ArgumentError(f"rate_bounds has {len(rb)} pairs for {p} parameters")
    for i, (lo, hi) in enumerate(rb):
        if np.isnan(lo) or np.isnan(hi):
            raise ArgumentError(f"rate_bounds[{i}] has a NaN")
        if lo > hi:
            raise ArgumentError(f"rate_bounds[{i}] = ({lo}, {hi}): lo > hi")
    return rb


def _matrices(system, rho: np.ndarray, shapes):
    try:
        out = system(rho.copy())
        A, B, C, D = (np.atleast_2d(np.asarray(x, dtype=float)) for x in out)
    except (TypeError, ValueError) as exc:
        raise ArgumentError(f"system(rho) must return four arrays (A, B, C, D): {exc}") from exc
    n = A.shape[0]
    if A.shape != (n, n) or n == 0 or B.shape[0] != n or C.shape[1] != n or D.shape != (C.shape[0], B.shape[1]):
        raise ArgumentError(
            f"system(rho) at rho = {rho.tolist()}: inconsistent shapes {A.shape, B.shape, C.shape, D.shape}"
        )
    if shapes is not None and (A.shape, B.shape, C.shape) != shapes:
        raise ArgumentError(f"system(rho) at rho = {rho.tolist()} changes shape across the grid")
    for name, x in zip("ABCD", (A, B, C, D)):
        if not np.all(np.isfinite(x)):
            raise ArgumentError(f"system(rho) at rho = {rho.tolist()}: {name} is not finite")
    return A, B, C, D


def _basis_values(basis, points: np.ndarray):
    p = points.shape[1]
    try:
        pairs = [(f, g) for f, g in basis]
    except (TypeError, ValueError) as exc:
        raise ArgumentError(f"basis must be a sequence of pairs (f, grad): {exc}") from exc
    if not pairs:
        raise ArgumentError("basis is empty (include the constant function)")
    F = np.empty((len(points), len(pairs)))
    G = np.empty((len(points), len(pairs), p))
    for a, rho in enumerate(points):
        for j, (f, g) in enumerate(pairs):
            try:
                F[a, j] = float(f(rho.copy()))
                grad = np.asarray(g(rho.copy()), dtype=float).reshape(-1)
            except (TypeError, ValueError) as exc:
                raise ArgumentError(f"basis[{j}] at rho = {rho.tolist()}: {exc}") from exc
            if grad.shape != (p,):
                raise ArgumentError(f"basis[{j}] gradient at rho = {rho.tolist()} has shape {grad.shape}, not ({p},)")
            G[a, j] = grad
    if not (np.all(np.isfinite(F)) and np.all(np.isfinite(G))):
        raise ArgumentError("a basis function or gradient is not finite at a grid point")
    return F, G


def _collapse_unused(bounds, G) -> list[tuple[float, float]]:
    """``bounds`` with one value for each parameter no basis function depends on (zero gradient at every point).

    Its rate multiplies ``dX/drho_i = 0`` in the LMIs, so both ends of its
    interval give the same LMI: enumerating them would only repeat it (the
    task's jerk doubled the LMIs per acceleration for an ``X`` free of them).
    """
    unused = ~np.any(G != 0, axis=(0, 1))
    return [(lo, lo) if unused[i] and np.isfinite(lo) else (lo, hi) for i, (lo, hi) in enumerate(bounds)]


def _rates_per_point(rates_at, points, rb, G) -> np.ndarray:
    """``(N, V, p)`` rate vertices from ``rates_at(rho)``, each box inside ``rb`` (shorter lists padded)."""
    p = points.shape[1]
    per = []
    for a, rho in enumerate(points):
        try:
            here = check_rate_bounds(rates_at(rho.copy()), p)
        except ArgumentError as exc:
            raise ArgumentError(f"rates_at(rho) at rho = {rho.tolist()}: {exc}") from exc
        for i, ((lo, hi), (blo, bhi)) in enumerate(zip(here, rb)):
            if lo < blo or hi > bhi:
                raise ArgumentError(
                    f"rates_at(rho) at rho = {rho.tolist()}: [{lo}, {hi}] for rho_{i + 1} is outside rate_bounds [{blo}, {bhi}]"
                )
            if not (np.isfinite(lo) and np.isfinite(hi)) and np.any(G[a, :, i] != 0):
                raise ArgumentError(f"rates_at: the rate of rho_{i + 1} is unbounded, but the basis depends on it")
        per.append(rate_vertices(_collapse_unused(here, G)))
    V = max(len(v) for v in per)
    return np.array([np.vstack([v] + [v[-1:]] * (V - len(v))) for v in per])


def evaluate(system, grid, rate_bounds=None, basis=None, rates_at=None, extra=None) -> Evaluated:
    """Evaluate the system, basis and rate box on the tensor grid (after checking every input).

    Parameters
    ----------
    system : callable
        ``rho -> (A, B, C, D)``.
    grid : sequence of array_like
        One 1-D array of values per parameter.
    rate_bounds : sequence of (lo, hi) or None
    basis : sequence of (f, grad) or None
    rates_at : callable, optional
        ``rho -> p pairs (lo, hi)``: the rate box at each grid point, inside
        ``rate_bounds`` (e.g. ``d q/dt = qdot`` exactly when ``qdot`` is a
        parameter too).
    extra : array_like, optional
        ``(N_extra, p)`` points inside the grid's box, evaluated after the
        grid's (e.g. where a re-check found the ``X`` of the grid failing).

    Returns
    -------
    Evaluated

    Raises
    ------
    ArgumentError
        Any malformed input (NaN in the grid, wrong shapes, ``lo > hi``, a
        basis without rate bounds, a basis depending on a parameter whose rate
        is unbounded).
    """
    if not callable(system):
        raise ArgumentError("system must be a callable rho -> (A, B, C, D)")
    axes = check_grid(grid)
    p = len(axes)
    points = np.array(np.meshgrid(*axes, indexing="ij")).reshape(p, -1).T
    if extra is not None and len(extra):
        more = np.atleast_2d(np.asarray(extra, dtype=float))
        lo, hi = np.array([g[0] for g in axes]), np.array([g[-1] for g in axes])
        if more.shape[1] != p or not np.all(np.isfinite(more)) or np.any(more < lo) or np.any(more > hi):
            raise ArgumentError(f"extra points must be finite, {p} coordinates each, inside the grid's box")
        points = np.vstack([points, more])
    mats, shapes = [], None
    for rho in points:
        m = _matrices(system, rho, shapes)
        shapes = (m[0].shape, m[1].shape, m[2].shape)
        mats.append(m)
    A, B, C, D = (np.array([m[i] for m in mats]) for i in range(4))
    lo, hi = np.array([g[0] for g in axes]), np.array([g[-1] for g in axes])
    if basis is None:
        if rate_bounds is not None:
            check_rate_bounds(rate_bounds, p)
        data = GridData(A, B, C, D, np.ones((len(points), 1)), np.zeros((len(points), 1, p)), np.zeros((1, p)), points)
        return Evaluated(data, lo, hi, True)
    if rate_bounds is None:
        raise ArgumentError("a parameter-dependent X (basis) needs rate_bounds; without them X must be constant")
    rb = check_rate_bounds(rate_bounds, p)
    F, G = _basis_values(basis, points)
    for i, (rlo, rhi) in enumerate(rb):
        if not (np.isfinite(rlo) and np.isfinite(rhi)) and np.any(G[:, :, i] != 0):
            raise ArgumentError(f"the rate of rho_{i + 1} is unbounded, but the basis depends on it (nonzero gradient)")
    nus = rate_vertices(_collapse_unused(rb, G)) if rates_at is None else _rates_per_point(rates_at, points, rb, G)
    return Evaluated(GridData(A, B, C, D, F, G, nus, points), lo, hi, False)
