"""The norm-bounded blocks of the ``inner-links`` model: the relative inertia error ``G = I - M_hat^-1 M`` and the state residual.

Split from :mod:`~polyrob.plant.models.inner_links` (its module text says
how the blocks are used): the weighted forms of ``G`` over the task's
samples, the bounds of the blocks' norms over the set, and the inertia
ratio the model reports.

Both blocks are a matrix linear in the set's scalars, ``sum_j u_j R_j``
(``|u_j| <= 1``), plus the payload's part at each point of its physical
set.  Its norm is the largest eigenvalue of its Hermitian dilation
``H(X) = [[0, X], [X^T, 0]]``, linear in ``X``; ``u H(R) <= |H(R)|`` in the
Loewner order, so ``||sum_j u_j R_j + R_p|| <= lambda_max(H(R_p) + sum_j
|H(R_j)|)`` for every ``u`` of the box: at most the triangle inequality's
``sum_j ||R_j|| + ||R_p||``, and less where the ``R_j`` act on different
directions.

Examples
--------
>>> import numpy as np
>>> R = np.array([np.diag([1.0, 0.0]), np.diag([0.0, 1.0])])[:, None]  # two scalars on different axes, one sample
>>> float(residual_norm_bounds(R, np.zeros((0, 1, 2, 2)), np.zeros((1, 0)))[0])  # the triangle inequality says 2
1.0
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The inertia block's shape keeps this fraction of its largest eigenvalue in every direction (:func:`shape_of`).
RIDGE = 0.02
#: Rounds of :func:`shape_of`'s programme, each with the samples and payload points it violated most added.
SHAPE_ROUNDS = 3

__all__ = [
    "RIDGE",
    "SHAPE_ROUNDS",
    "InertiaBlock",
    "inertia_block",
    "well_posed_margin",
    "shape_of",
    "exactly_weighted",
    "spectrum_bounds",
    "g_norm_bound",
    "residual_norm_bounds",
    "inertia_range",
    "inertia_ratio",
]


def exactly_weighted(robot, q, G, W) -> tuple[np.ndarray, np.ndarray]:
    """``W_q G W_q^-1`` with ``W_q = M_hat(q)^{1/2}`` at each sample (symmetric: ``-M_hat^-1/2 dM M_hat^-1/2``), and
    ``kappa = ||W W_q^-1|| ||W_q W^-1||``, what the fixed weighting ``W`` of the block costs at that sample."""
    out, kappa = np.empty_like(G), np.empty(len(q))
    for s, qq in enumerate(q):
        M = robot.model_robot.mass_matrix(qq)
        values, vectors = np.linalg.eigh(0.5 * (M + M.T))
        W_q = (vectors * np.sqrt(values)) @ vectors.T
        W_q_inv = (vectors / np.sqrt(values)) @ vectors.T
        out[:, s] = W_q @ G[:, s] @ W_q_inv
        T = W @ W_q_inv
        kappa[s] = np.linalg.norm(T, 2) * np.linalg.norm(np.linalg.inv(T), 2)
    return out, kappa


def _sym_skew(R):
    sym = 0.5 * (R + np.swapaxes(R, -1, -2))
    return sym, np.linalg.norm(R - sym, 2, axis=(-2, -1))


def spectrum_bounds(box_rest, payload_rest, pay) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(bottom, top, skew)`` per sample: the eigenvalues of the block's symmetric part lie in ``[bottom, top]``.

    Box scalars: ``A = sum_j |sym R_j|`` bounds their symmetric part in the
    Loewner order (``-|S| <= u S <= |S|`` for ``|u| <= 1``), their skew
    parts add their norms (``skew``); the payload at each point ``p`` of its
    sampled physical set (:func:`payload_points`) adds ``S_p``, so the
    symmetric part lies between ``S_p - A`` and ``S_p + A``.  Arrays of the
    samples (one entry when there is no payload).
    """
    sym, skew = _sym_skew(box_rest)
    values, vectors = np.linalg.eigh(sym)
    A = np.einsum("...ab,...b,...cb->...ac", vectors, np.abs(values), vectors).sum(axis=0)  # (S, m, m)
    skew = skew.sum(axis=0)
    if len(payload_rest):
        pay = np.asarray(pay, float)[_distinct(pay)[0]]  # the extremes over the points: the distinct ones suffice
        S_p, skew_p = _sym_skew(np.einsum("pi,isab->psab", pay, payload_rest))
        top = np.linalg.eigvalsh(S_p + A).max(axis=-1)
        bottom = np.linalg.eigvalsh(S_p - A).min(axis=-1)
        skew = skew + skew_p.max(axis=0)
    else:
        top = np.linalg.eigvalsh(A).max(axis=-1)[None]
        bottom = -top
    return bottom, top, skew


def _dilation(X) -> np.ndarray:
    """The Hermitian dilation ``[[0, X], [X^T, 0]]`` of ``X`` (last two axes): linear in ``X``, its largest eigenvalue ``||X||_2``."""
    r, c = X.shape[-2:]
    out = np.zeros(X.shape[:-2] + (r + c, r + c))
    out[..., :r, r:] = X
    out[..., r:, :r] = np.swapaxes(X, -1, -2)
    return out


def _distinct(pay) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)``: a row of ``pay`` for each distinct point, and each row's among them (``pay[first][inverse] == pay``).

    A payload whose mass range starts at 0 has one point at that end for
    all its centres of mass (half of :func:`payload_points`); the largest
    eigenvalues over the points are taken on the distinct ones, the same
    values at half the work.
    """
    pay = np.asarray(pay, float)
    if pay.ndim != 2 or not len(pay):
        return np.arange(len(pay)), np.arange(len(pay))
    _, first, inverse = np.unique(pay, axis=0, return_index=True, return_inverse=True)
    return first, np.asarray(inverse).reshape(-1)


@dataclass(frozen=True)
class InertiaBlock:
    """The acceleration columns' block ``offset + g_norm S^1/2 Delta S^1/2`` (weighted), ``||Delta|| <= 1``.

    Attributes
    ----------
    g_norm : float
        Its size (times the caller's margin).
    offset : numpy.ndarray or float
        Its centre ``G0`` (``m x m``; a float ``g0`` for ``g0 I``).
    shape : numpy.ndarray or None
        ``S`` (largest eigenvalue 1), or ``None`` for a ball.
    kind : str
        ``"shaped"`` or ``"ball"``.
    margin : float
        :func:`well_posed_margin` (``> 0``: ``I - G`` is invertible for every member).
    ball : float
        The ball's radius relative to the room its centre leaves (``g_norm / (1 - g0)``), for reports.
    """

    g_norm: float
    offset: object
    shape: object
    kind: str
    margin: float
    ball: float


def inertia_block(G_exact, G_fixed, on_payload, pay, kappa, ranges, centres, margin_factor: float) -> InertiaBlock:
    """The inertia block of the ``inner-links`` model: shaped like the set (:func:`shape_of`) when well posed, else a ball.

    ``G_exact`` (each sample's symmetric form, ``kappa`` what the fixed
    weighting costs there) and ``G_fixed`` (the fixed weighting's) are the
    acceleration columns per scalar, ``(N, S, m, m)``; ``on_payload`` marks
    the payload's scalars, ``pay`` the points of its physical set.  The
    ball is the smaller, relative to its room, of the two bounds
    :func:`g_norm_bound` gives (its module text); the shaped block is the
    fixed weighting's in the shape's coordinates.  Both hold over the
    set and the samples; the shaped one is carried when ``I - G`` stays
    invertible for every member (on ur5's per-link set it holds the same
    errors in a ball of 0.45 in one direction and about 0.1 in the others).
    """
    box, payload = G_fixed[~on_payload], G_fixed[on_payload]
    ones = np.ones(G_fixed.shape[1])
    balls = [g_norm_bound(G_exact[~on_payload], G_exact[on_payload], pay, kappa), g_norm_bound(box, payload, pay, ones)]
    ball, g0 = min(balls, key=lambda b: b[0] / (1.0 - b[1]))
    fitted, margin = shape_of(box, payload, pay), -np.inf
    if fitted is not None:
        shape, centre = fitted
        g_norm, t = g_norm_bound(box, payload, pay, ones, shape=shape, centre=centre)
        offset = centre + t * shape
        g_norm *= margin_factor
        margin = well_posed_margin(ranges, centres, g_norm, offset, shape)
    ball *= margin_factor
    if margin > 0.0:
        return InertiaBlock(g_norm, offset, shape, "shaped", margin, ball / (1.0 - g0))
    return InertiaBlock(ball, g0, None, "ball", well_posed_margin(ranges, centres, ball, g0), ball / (1.0 - g0))


def well_posed_margin(ranges, centres, g_norm: float, offset=0.0, shape=None, points: int = 9) -> float:
    """``min sigma_min(H^-1 (I - G0 - sum t_k G_k,c) H^-1) - g_norm`` over a grid of the directions' box (``> 0``: well posed there).

    ``H = S^1/2`` of the block's ``shape`` (``I`` for a ball), ``G0`` its
    ``offset`` (a float for ``g0 I``): ``I - G0 - sum t_k G_k,c - g_norm H
    Delta H`` is then invertible for every ``||Delta|| <= 1`` (small gain).
    In the weighted coordinates of the block; ``centres`` ``(P, m, 3m)``, the
    directions' acceleration columns the last ``m``; the grid has
    ``points`` values per direction (at most 4 directions on the grid, the
    rest at their ends).
    """
    m = centres.shape[1]
    G = np.array([K[:, -m:] for K in centres]).reshape(len(centres), m, m)
    G0 = np.asarray(offset, float) * np.eye(m) if np.ndim(offset) == 0 else np.asarray(offset, float)
    H_inv = np.eye(m)
    if shape is not None:
        values, vectors = np.linalg.eigh(np.asarray(shape, float))
        H_inv = (vectors / np.sqrt(values)) @ vectors.T
    axes = [np.linspace(-r, r, points if k < 4 else 2) for k, r in enumerate(ranges)]
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(ranges), -1).T
    eye = np.eye(m) - G0
    worst = min(
        float(np.linalg.svd(H_inv @ (eye - np.tensordot(t, G, axes=1)) @ H_inv, compute_uv=False)[-1]) for t in grid
    )
    return worst - g_norm


def g_norm_bound(box_rest, payload_rest, pay, kappa, shape=None, centre=None) -> tuple[float, float]:
    """``(g_norm, g0)``: ``||sum_j u_j R_j - g0 I||_2 <= g_norm`` (acceleration columns) over the set and the samples.

    The norm is the largest eigenvalue of the Hermitian dilation ``H``, which
    is linear in the matrix: ``H(sum_j u_j R_j + R_p - g0 I) <= H(R_p - g0 I)
    + sum_j |H(R_j)|`` in the Loewner order for every ``|u_j| <= 1`` (box
    scalars) and every point ``p`` of the payload's sampled physical set.  A
    block that is not symmetric (the fixed weighting away from the task's
    centre) keeps the signs its symmetric and skew parts share; adding the
    skew parts' norms to the symmetric part's spectrum instead refused
    panda's default set and z1's (docs/uncertainty.md).  ``kappa`` per sample is
    what a fixed weighting costs there.

    ``g0``, the block's centre (a heavy off-axis payload raises the inertia
    more than a light one lowers it), minimises ``g_norm / (1 - g0)``, the
    block's size against the room its centre leaves, searched on the
    payload points that attain the largest eigenvalue at some sample.  The
    bound returned holds at every point and sample: each eigenvalue moves
    by at most ``|g0 - g_c|`` from its value at the spectrum's centre
    ``g_c`` (``||H(I)|| = 1``), and every pair that bound does not settle
    is evaluated at ``g0``.

    ``shape`` ``S`` and ``centre`` ``C`` (``m x m``; :func:`shape_of`): the
    same in the block's shaped coordinates, ``||S^-1/2 (sum_j u_j R_j + R_p
    - C) S^-1/2 - g0 I||_2 <= g_norm``, i.e. the block ``C + g0 S + g_norm
    S^1/2 Delta S^1/2`` with ``||Delta|| <= 1``; ``g0`` then minimises
    ``g_norm ||S^1/2 (I - C - g0 S)^-1 S^1/2||``, the small-gain figure of
    the loop ``(I - G)^-1`` the block sits in (``1 / (1 - g0)`` when ``S =
    I``, ``C = 0``).
    """
    from scipy.optimize import minimize_scalar

    m = box_rest.shape[-1]
    eye = np.eye(m)
    shaped = shape is not None or centre is not None
    if shaped:
        S = eye if shape is None else np.asarray(shape, float)
        C = np.zeros((m, m)) if centre is None else np.asarray(centre, float)
        values, vectors = np.linalg.eigh(S)
        T, root = (vectors / np.sqrt(values)) @ vectors.T, (vectors * np.sqrt(values)) @ vectors.T
        box_rest = T @ box_rest @ T
        # the centre is one more payload term, -T C T at every point (its coefficient 1)
        constant = np.broadcast_to(-(T @ C @ T), (1, box_rest.shape[1], m, m))
        payload_rest = np.concatenate([T @ payload_rest @ T, constant]) if len(payload_rest) else constant
        pay = np.hstack([pay, np.ones((len(pay), 1))])

    def room(t):  # the small-gain figure of the loop (I - G)^-1 around the centre t
        if not shaped:
            return 1.0 / (1.0 - t) if t < 1.0 else np.inf
        M = eye - C - t * S
        if np.linalg.cond(M) > 1e12:
            return np.inf
        return float(np.linalg.norm(root @ np.linalg.solve(M, root), 2))

    A = _absolute_sum(box_rest)  # (S, 2m, 2m)
    R = np.einsum("pi,isab->psab", pay, payload_rest) if len(payload_rest) else np.zeros((1,) + box_rest.shape[1:])

    first, inverse = _distinct(pay) if len(payload_rest) else (np.zeros(1, int), np.zeros(1, int))

    def largest(g, rows, chunk=32):  # (rows, S): the dilation's largest eigenvalue at each payload point and sample
        distinct, back = np.unique(inverse[rows], return_inverse=True)  # each distinct point once
        out = np.empty((len(distinct), A.shape[0]))
        for start in range(0, A.shape[0], chunk):  # a payload's 1300 points times 512 samples: a gigabyte at once
            part = slice(start, start + chunk)
            out[:, part] = np.linalg.eigvalsh(_dilation(R[first[distinct], part] - g * eye) + A[part]).max(axis=-1)
        return out[np.asarray(back).reshape(-1)]

    bottom, top, _ = spectrum_bounds(box_rest, payload_rest, pay[::16])  # a start: any centre gives a bound
    g_c = 0.5 * (float(top.max()) + float(bottom.min()))
    span = max(float(top.max() - bottom.min()), 1e-6)
    at_centre = largest(g_c, np.arange(len(R)))  # (P, S)
    active = np.unique(np.argmax(at_centre, axis=0))
    upper = g_c + 0.5 * span if shaped else min(g_c + 0.5 * span, 1.0 - 1e-3)
    found = minimize_scalar(
        lambda t: float((kappa * largest(t, active).max(axis=0)).max()) * room(t),
        bounds=(g_c - 0.5 * span, upper),
        method="bounded",
        options={"xatol": 1e-3},
    )
    g = float(found.x)
    at_g = at_centre + abs(g - g_c)  # every pair's eigenvalue at g, bounded
    at_g[active] = largest(g, active)
    unsettled = np.argwhere(kappa * at_g > (kappa * at_g[active]).max())
    for start in range(0, len(unsettled), 16384):
        p, s = unsettled[start : start + 16384].T
        at_g[p, s] = np.linalg.eigvalsh(_dilation(R[p, s] - g * eye) + A[s]).max(axis=-1)
    bounds = [(float((kappa * at_centre.max(axis=0)).max()), g_c), (float((kappa * at_g.max(axis=0)).max()), g)]
    return min((b for b in bounds if np.isfinite(room(b[1]))), key=lambda b: b[0] * room(b[1]))


def shape_of(box_rest, payload_rest, pay, ridge: float = RIDGE, rounds: int = SHAPE_ROUNDS):
    """``(S, C)``: a shape and a centre for the inertia block from its parts (``(J, S, m, m)``), or ``None``.

    The set's inertia errors are far from round: on ur5 with ±10 % per link
    the Loewner sum of the box scalars has one eigenvalue of 0.45 (the
    upper arm's parallel-axis term) and five of 0.1-0.13, so a ball of
    radius 0.45 holds errors in every direction that only one direction
    has.  ``S`` and ``C`` solve the semidefinite programme ``min trace S``
    subject to ``diag(S, S) >= H(X_p(x) - C) + A(x)`` (``H`` the Hermitian
    dilation, ``A(x) = sum_j |H(R_j(x))|`` the box scalars' sum, ``X_p(x)``
    the payload at point ``p``: the condition ``||S^-1/2 (X - C) S^-1/2||
    <= 1`` for every member at ``x``), on a few samples and payload points,
    then again with the samples and points it violates most added
    (``rounds`` times; cvxpy, Clarabel).  ``ridge`` times its largest
    eigenvalue is added and the largest eigenvalue normalised to 1.  Any
    shape and centre give a valid bound (:func:`g_norm_bound` finds the
    size that holds at every point and sample); ``None`` when the
    programme has no solution.
    """
    import warnings

    import cvxpy as cp

    m = box_rest.shape[-1]
    n_samples = (box_rest if len(box_rest) else payload_rest).shape[1]
    A = _absolute_sum(box_rest) if len(box_rest) else np.zeros((n_samples, 2 * m, 2 * m))
    X = np.einsum("pi,isab->psab", pay, payload_rest) if len(payload_rest) else np.zeros((1, n_samples, m, m))
    first, inverse = _distinct(pay) if len(payload_rest) else (np.zeros(1, int), np.zeros(1, int))
    pairs = {
        (p, s) for p in range(0, len(X), max(1, len(X) // 16)) for s in range(0, n_samples, max(1, n_samples // 4))
    }
    S_var, C_var = cp.Variable((m, m), symmetric=True), cp.Variable((m, m), symmetric=True)
    block = cp.bmat([[S_var, np.zeros((m, m))], [np.zeros((m, m)), S_var]])
    fitted = None
    for _ in range(rounds):
        constraints = []
        for p, s in sorted(pairs):
            D = X[p, s]
            constraints.append(
                block - cp.bmat([[np.zeros((m, m)), D - C_var], [(D - C_var).T, np.zeros((m, m))]]) - A[s] >> 0
            )
        problem = cp.Problem(cp.Minimize(cp.trace(S_var)), constraints)
        try:
            with warnings.catch_warnings():  # an inaccurate optimum is still a shape: the bound does not rest on it
                warnings.simplefilter("ignore", UserWarning)
                problem.solve(solver=cp.CLARABEL)
        except cp.error.SolverError:
            break
        if problem.status not in ("optimal", "optimal_inaccurate") or S_var.value is None:
            break
        S, C = 0.5 * (S_var.value + S_var.value.T), 0.5 * (C_var.value + C_var.value.T)
        values, vectors = np.linalg.eigh(S)
        values = np.maximum(values, ridge * max(float(values.max()), 1e-300))
        fitted = ((vectors * values) @ vectors.T, C)
        # the pairs it violates most: the dilation's largest eigenvalue in the shape's coordinates
        T = (vectors / np.sqrt(values)) @ vectors.T
        T2 = np.kron(np.eye(2), T)
        worst = np.empty((len(first), n_samples))  # at the distinct points, then at every point
        for start in range(0, n_samples, 32):
            part = slice(start, start + 32)
            worst[:, part] = np.linalg.eigvalsh(T2 @ (_dilation(X[first, part] - C) + A[part]) @ T2).max(axis=-1)
        worst = worst[inverse]
        new = {
            tuple(ij) for ij in np.argwhere(worst > 1.0 + 1e-6)[np.argsort(-worst[worst > 1.0 + 1e-6])][:24].tolist()
        }
        if not new - pairs:
            break
        pairs |= new
    if fitted is None:
        return None
    S, C = fitted
    top = float(np.linalg.eigvalsh(S).max())
    S = S / top + ridge * np.eye(m)
    return S / float(np.linalg.eigvalsh(S).max()), C


def _absolute_sum(X) -> np.ndarray:
    """``sum_j |H(X_j)|`` over the first axis of ``X`` ``(J, S, r, c)``: ``(S, r + c, r + c)``."""
    values, vectors = np.linalg.eigh(_dilation(X))
    return np.einsum("...ab,...b,...cb->...ac", vectors, np.abs(values), vectors).sum(axis=0)


def residual_norm_bounds(box_rest, payload_rest, pay, chunk: int = 16) -> np.ndarray:
    """``(S,)``: ``||sum_j u_j R_j + sum_i p_i P_i||_2`` bounded at each sample, over the box ``|u_j| <= 1`` and the points ``p`` of ``pay``.

    ``box_rest`` ``(J, S, r, c)``, ``payload_rest`` ``(I, S, r, c)``, ``pay``
    ``(points, I)``: the module text's dilation bound, the payload's points
    ``chunk`` samples at a time (a payload's set has about 1300 points).
    """
    A = _absolute_sum(box_rest)
    if not len(payload_rest):
        return np.linalg.eigvalsh(A).max(axis=-1)
    pay = np.asarray(pay, float)[_distinct(pay)[0]]  # the largest over the points: the distinct ones suffice
    out = np.empty(box_rest.shape[1])
    for start in range(0, len(out), chunk):
        part = slice(start, start + chunk)
        sums = np.einsum("pi,isab->psab", pay, payload_rest[:, part])
        out[part] = np.linalg.eigvalsh(_dilation(sums) + A[part]).max(axis=-1).max(axis=0)
    return out


def inertia_range(G_exact_box, G_exact_payload, pay) -> tuple[float, float]:
    """``(lo, hi)``: the true robots' inertia between ``lo`` and ``hi`` times the model's (eigenvalues of
    ``M_hat^-1 M = I - G`` over the set and the task's samples; ``G_exact`` in each sample's ``M_hat^1/2``
    coordinates, where it is symmetric)."""
    bottom, top, _ = spectrum_bounds(G_exact_box, G_exact_payload, pay)
    return 1.0 - float(top.max()), 1.0 - float(bottom.min())


def inertia_ratio(robot, scalars, q, moved_robot) -> float:
    """``rho``: the largest ``|eig(M_hat^-1 dM)|`` over the box's vertices along each scalar, summed (a bound, for reports).

    ``moved_robot(robot, scalar, sign)``: the loop's model robot moved by the scalar's half range.
    """
    dM = []
    model = robot.model_robot
    for s in scalars:
        if s.joint >= 0:
            continue
        moved = moved_robot(
            robot, s, 1.0 if float(model.model.inertias[s.body].mass) + s.half_range * s.params[0] > 0 else -1.0
        )
        dM.append(moved)
    worst = 0.0
    for qq in q[:8]:
        M_hat = model.mass_matrix(qq)
        L = np.linalg.cholesky(M_hat)
        total = 0.0
        for moved in dM:
            D = moved.mass_matrix(qq) - M_hat
            total += float(np.max(np.abs(np.linalg.eigvalsh(np.linalg.solve(L, np.linalg.solve(L, D).T)))))
        worst = max(worst, total)
    return worst
