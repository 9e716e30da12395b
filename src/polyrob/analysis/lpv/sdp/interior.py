"""A primal-dual interior-point method for block-diagonal SDPs whose Schur complement the caller builds.

The problem, in the dual form of SDPT3 (Toh, Todd & Tütüncü 1999),

.. math::

   \\max_y\\; b^T y \\quad \\text{s.t.} \\quad Z_l = C_l - \\mathcal A_l^*(y) \\succeq 0,

with its primal ``min sum <C_l, X_l>`` s.t. ``sum A_l(X_l) = b``,
``X_l >= 0``.  Infeasible start, Nesterov-Todd scaling, Mehrotra's
predictor-corrector; per iteration one dense Cholesky factorisation of the
Schur complement ``H = sum_l A_l (W_l . W_l) A_l^*``, which the *family*
forms from its own structure (:class:`~polyrob.analysis.lpv.sdp.family.BoundedRealFamily`).

Blocks come in groups of equal side, stored as ``(count, s, s)`` arrays, so
the scaling, the step lengths and the residuals are batched numpy.  The
result is a candidate only: :mod:`polyrob.analysis.lpv.check` proves a level
with it or not, whatever this solver reports.

Examples
--------
>>> import numpy as np
>>> from polyrob.analysis.lpv.check import grid_data
>>> from polyrob.analysis.lpv.sdp.family import BoundedRealFamily
>>> data = grid_data([np.array([[-1.0]])], [np.array([[1.0]])], [np.array([[1.0]])], [np.array([[0.0]])])
>>> res = solve(BoundedRealFamily(data, eps=0.0))
>>> res.status, round(-res.dual_objective, 6)          # 1/(s + 1): gamma = 1
('solved', 1.0)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from polyrob.errors import SolverError

__all__ = ["InteriorPointResult", "solve"]


@dataclass(frozen=True)
class InteriorPointResult:
    """The last iterate of :func:`solve`.

    Attributes
    ----------
    y : ndarray
        The dual variables (the caller's unknowns).
    status : str
        ``"solved"``, ``"max_iterations"``, ``"stalled"``, ``"numerical_error"`` (a primal block lost
        definiteness to rounding, or the Schur complement is singular) or ``"infeasible"`` (the objectives diverge).  Every ``y`` returned
        is the last iterate: strictly inside the dual cones once the dual residual is zero.
    iterations : int
    dual_objective, primal_objective : float
    dual_residual : float
        ``max_l ||C_l - Z_l - A_l^*(y)||_F`` relative to ``1 + max ||C_l||_F``.
    """

    y: np.ndarray
    status: str
    iterations: int
    dual_objective: float
    primal_objective: float
    dual_residual: float


def _inner(U: list, V: list) -> float:
    return float(sum(np.einsum("lab,lab->", u, v) for u, v in zip(U, V)))


def _sym(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + np.transpose(M, (0, 2, 1)))


def _nt_scaling(X: np.ndarray, Z: np.ndarray):
    """``G`` with ``G G^T = W``, ``W Z W = X``, and ``lambda`` with ``G^-1 X G^-T = G^T Z G = diag(lambda)``."""
    Lx = np.linalg.cholesky(X)
    lam2, U = np.linalg.eigh(np.transpose(Lx, (0, 2, 1)) @ Z @ Lx)
    lam2 = np.maximum(lam2, np.finfo(float).tiny)
    G = Lx @ U * lam2[:, None, :] ** -0.25
    Ginv = (lam2[:, :, None] ** 0.25) * np.transpose(U, (0, 2, 1)) @ np.linalg.inv(Lx)
    return G, Ginv, np.sqrt(lam2)


def _cholesky(H: np.ndarray):
    """Cholesky factor of ``H``, regularised up to ``1e-8`` of its largest diagonal entry; ``None`` if that fails."""
    scale = float(np.abs(np.diag(H)).max() or 1.0)
    for reg in (0.0, 1e-14, 1e-11, 1e-8):
        try:
            return sla.cho_factor(H + reg * scale * np.eye(H.shape[0]), lower=True)
        except (np.linalg.LinAlgError, ValueError):  # not positive definite, or not finite
            continue
    return None


def _max_step(lam: np.ndarray, Ds: np.ndarray) -> float:
    """Largest ``alpha`` with ``diag(lam) + alpha Ds >= 0`` over a group (``inf`` when every direction is PSD)."""
    r = 1.0 / np.sqrt(lam)
    ev = np.linalg.eigvalsh(_sym(r[:, :, None] * Ds * r[:, None, :]))
    low = float(ev.min()) if ev.size else 0.0
    return np.inf if low >= 0 else -1.0 / low


def solve(family, *, tol: float = 1e-8, max_iterations: int = 100, step: float = 0.98, progress=None):
    """Maximise ``b^T y`` subject to the family's blocks ``C_l - A_l^*(y) >= 0``.

    Parameters
    ----------
    family : object
        ``C`` (list of ``(count, s, s)`` arrays), ``b``, ``n_variables``,
        ``adjoint(y) -> list``, ``forward(list) -> vector``, ``schur(W: list) -> H``.
    tol : float
        Relative duality gap and infeasibilities at which it stops.
    max_iterations : int
    step : float
        Fraction of the step to the boundary of the cones.
    progress : callable, optional
        ``progress(iteration, dual_objective, gap)`` after each iteration.

    Returns
    -------
    InteriorPointResult

    Raises
    ------
    SolverError
        The Schur complement is singular at the starting point (later, the last iterate is returned).
    """
    C, b = family.C, np.asarray(family.b, float)
    norm_c = 1.0 + max(float(np.sqrt(np.einsum("lab,lab->l", c, c).max())) for c in C if c.shape[0])
    nu = sum(c.shape[0] * c.shape[1] for c in C)
    # the starting point of SDPT3 in spirit: per group, multiples of the identity as large as its data
    X, Z = [], []
    for c in C:
        size = max(10.0, np.sqrt(c.shape[1]))
        scale = float(np.sqrt(np.einsum("lab,lab->l", c, c).max())) if c.shape[0] else 0.0
        X.append(np.broadcast_to(np.eye(c.shape[1]) * size, c.shape).copy())
        Z.append(np.broadcast_to(np.eye(c.shape[1]) * max(size, scale), c.shape).copy())
    y = np.zeros(family.n_variables)
    status, it = "max_iterations", 0
    stall = 0
    for it in range(1, max_iterations + 1):
        AY = family.adjoint(y)
        Rd = [c - z - a for c, z, a in zip(C, Z, AY)]
        rp = b - family.forward(X)
        mu = _inner(X, Z) / nu
        pobj, dobj = _inner(C, X), float(b @ y)
        gap = abs(pobj - dobj) / (1.0 + abs(pobj) + abs(dobj))
        dres = max(float(np.sqrt(np.einsum("lab,lab->l", r, r).max())) for r in Rd) / norm_c
        pres = float(np.linalg.norm(rp)) / (1.0 + float(np.linalg.norm(b)))
        if progress is not None:
            progress(it, dobj, gap)
        if gap < tol and dres < tol and pres < tol:
            status = "solved"
            break
        if pobj < -1e12 * (1.0 + abs(dobj)) or abs(dobj) > 1e12:
            status = "infeasible"
            break
        if stall >= 4:  # four steps too short to matter: the last point is what there is
            status = "stalled"
            break
        try:
            scal = [_nt_scaling(x, z) for x, z in zip(X, Z)]
        except np.linalg.LinAlgError:  # a block lost definiteness to rounding near the optimum: keep the last y
            status = "numerical_error"
            break
        try:
            with np.errstate(over="raise", invalid="raise"):
                W = [g @ np.transpose(g, (0, 2, 1)) for g, _, _ in scal]
                H = family.schur(W)
        except FloatingPointError:
            status = "numerical_error"
            break
        factor = _cholesky(H)
        if factor is None:  # singular even regularised: near the optimum the last y is what there is
            if it == 1:
                raise SolverError("interior point: the Schur complement is singular at the starting point")
            status = "numerical_error"
            break
        WRdW = [w @ r @ w for w, r in zip(W, Rd)]

        def direction(R_scaled):
            # dx~ + dz~ = lambda <> R (lambda o D = R), then back to the unscaled blocks
            Rc = []
            for (g, _, lam), r in zip(scal, R_scaled):
                D = 2.0 * r / (lam[:, :, None] + lam[:, None, :])
                Rc.append(g @ D @ np.transpose(g, (0, 2, 1)))
            dy = sla.cho_solve(factor, rp - family.forward([rc - wrw for rc, wrw in zip(Rc, WRdW)]))
            dZ = [r - a for r, a in zip(Rd, family.adjoint(dy))]
            dX = [rc - w @ dz @ w for rc, w, dz in zip(Rc, W, dZ)]
            return [_sym(d) for d in dX], dy, [_sym(d) for d in dZ]

        def scaled(dX, dZ):
            sx = [gi @ d @ np.transpose(gi, (0, 2, 1)) for (_, gi, _), d in zip(scal, dX)]
            sz = [np.transpose(g, (0, 2, 1)) @ d @ g for (g, _, _), d in zip(scal, dZ)]
            return sx, sz

        def steps(dX, dZ):
            sx, sz = scaled(dX, dZ)
            ap = min([_max_step(lam, d) for (_, _, lam), d in zip(scal, sx)] + [np.inf])
            ad = min([_max_step(lam, d) for (_, _, lam), d in zip(scal, sz)] + [np.inf])
            return min(1.0, step * ap), min(1.0, step * ad), sx, sz

        try:  # overflow or NaN in a step (a scaling near singular): the last finite iterate is what there is
            with np.errstate(over="raise", invalid="raise", divide="raise"):
                lam_sq = [np.einsum("li,ij->lij", lam**2, np.eye(lam.shape[1])) for _, _, lam in scal]
                dXa, _, dZa = direction([-m for m in lam_sq])
                ap, ad, sx, sz = steps(dXa, dZa)
                mu_aff = _inner([x + ap * d for x, d in zip(X, dXa)], [z + ad * d for z, d in zip(Z, dZa)]) / nu
                sigma = min(1.0, max(0.0, mu_aff / mu)) ** 3
                R = []
                for m, a, c in zip(lam_sq, sx, sz):
                    eye = np.broadcast_to(np.eye(m.shape[1]), m.shape)
                    R.append(sigma * mu * eye - m - _sym(a @ c))
                dX, dy, dZ = direction(R)
                ap, ad, _, _ = steps(dX, dZ)
        except (FloatingPointError, ValueError, np.linalg.LinAlgError):
            status = "numerical_error"
            break
        stall = stall + 1 if max(ap, ad) < 1e-4 else 0
        X = [x + ap * d for x, d in zip(X, dX)]
        Z = [z + ad * d for z, d in zip(Z, dZ)]
        y = y + ad * dy
    AY = family.adjoint(y)
    Rd = [c - z - a for c, z, a in zip(C, Z, AY)]
    dres = max(float(np.sqrt(np.einsum("lab,lab->l", r, r).max())) for r in Rd) / norm_c
    return InteriorPointResult(y=y, status=status, iterations=it, dual_objective=float(b @ y),
                               primal_objective=_inner(C, X), dual_residual=dres)  # fmt: skip
