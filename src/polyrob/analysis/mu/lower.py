"""Lower bound of the structured singular value: a perturbation that makes ``I - M Δ`` singular.

The bound :math:`\\ell` comes with its certificate, a :math:`\\Delta` in the
structure with :math:`\\bar\\sigma(\\Delta) = 1/\\ell` and
:math:`\\det(I - M\\Delta) = 0`: the power iteration of Packard, Fan & Doyle
(complex blocks) and Young & Doyle (mixed), vertex candidates for a few real
scalars, then a local search (SLSQP) on the singularity condition.  No
library computes it (python-control, slycot and dkpy stop at the upper
bound), hence this module.  Used by :func:`polyrob.analysis.mu.bounds.mussv`.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.optimize import minimize

from polyrob.analysis.mu.blocks import BlockStructure, perron_upper


def _q_from(a: np.ndarray, w: np.ndarray, meta) -> np.ndarray:
    """Structured Q (norm <= 1) aligning ``a`` with ``w`` block by block.

    This is the Packard-Doyle power-iteration update: it maximises
    ``Re(w^H Q a)`` over the unit ball of each complex block.  For real blocks
    (Young-Doyle) the projection of the complex alignment on the reals is used
    as a heuristic; the local search below makes it exact.
    """
    n = a.size
    Q = np.zeros((n, n), dtype=complex)
    for kind, rep, sl in meta:
        ai, wi = a[sl], w[sl]
        na, nw = np.linalg.norm(ai), np.linalg.norm(wi)
        if na < 1e-300 or nw < 1e-300:
            continue
        if kind == "full" and not rep:
            Q[sl, sl] = np.outer(wi, ai.conj()) / (na * nw)
        else:
            c = np.vdot(ai, wi) / (na * nw)
            q = c.real if kind == "real" else (c / abs(c) if abs(c) > 1e-300 else 1.0)
            Q[sl, sl] = q * np.eye(sl.stop - sl.start)
    return Q


def _power_iteration(Ms, meta, b, w, maxiter=60, tol=1e-9):
    """Packard-Doyle / Young-Doyle power iteration; returns the last Q, b, w."""
    beta_old = 0.0
    Q = np.zeros_like(Ms)
    for _ in range(maxiter):
        a = Ms @ b
        na = np.linalg.norm(a)
        if na < 1e-300:
            break
        a /= na
        z = _q_from(a, w, meta).conj().T @ w
        w = Ms.conj().T @ z
        nw = np.linalg.norm(w)
        if nw < 1e-300:
            break
        w /= nw
        Q = _q_from(a, w, meta)
        b = Q @ a
        nb = np.linalg.norm(b)
        if nb < 1e-300:
            break
        b /= nb
        beta = na * nb
        if abs(beta - beta_old) <= tol * max(beta, 1e-300):
            break
        beta_old = beta
    return Q, b, w


def _blocks_norm(delta_sq: np.ndarray, st: BlockStructure) -> float:
    return max((np.linalg.norm(delta_sq[sl, sl], 2) for sl in st.padded_slices), default=0.0)


def _candidate(Ms, st, Q):
    """Turn a structured Q into a verified (lower, padded delta) or None."""
    lam, X = np.linalg.eig(Ms @ Q)
    nq = _blocks_norm(Q, st)
    if nq == 0.0 or not np.any(np.abs(lam) > 0):
        return None
    if st.has_real:
        # only real eigenvalues are admissible: a complex phase cannot be
        # absorbed by real blocks.
        ok = np.abs(lam.imag) <= 1e-9 * np.abs(lam) + 1e-300
        if not np.any(ok & (np.abs(lam) > 0)):
            return None
        k = int(np.argmax(np.where(ok, np.abs(lam), -1.0)))
        lk = lam[k].real
    else:
        k = int(np.argmax(np.abs(lam)))
        lk = lam[k]
    return abs(lk) / nq, Q / lk, X[:, k]


def _vertex_candidates(Ms, st, max_real=10):
    """Exhaustive sign patterns of the real scalars (exact for real M, real blocks)."""
    idx = [sl for b, sl in zip(st.blocks, st.padded_slices) if b.kind == "real"]
    if len(idx) > max_real or len(idx) != len(st.blocks):
        return []
    n = Ms.shape[0]
    signs = np.array(np.meshgrid(*[[-1.0, 1.0]] * len(idx), indexing="ij")).reshape(len(idx), -1).T
    qdiag = np.zeros((signs.shape[0], n))
    for j, sl in enumerate(idx):
        qdiag[:, sl] = signs[:, [j]]
    lam = np.linalg.eigvals(Ms[None, :, :] * qdiag[:, None, :])
    score = np.where(np.abs(lam.imag) <= 1e-9 * np.abs(lam), np.abs(lam), -1.0).max(axis=1)
    best = int(np.argmax(score))
    if score[best] <= 0:
        return []
    c = _candidate(Ms, st, np.diag(qdiag[best]).astype(complex))
    return [c] if c is not None else []


def _refine(Ms, st, delta0, x0):
    """Local search for a smaller destabilising Delta (SLSQP).

    With ``y = Delta x`` and ``x = M y`` the condition ``det(I - M Delta) = 0``
    becomes per-block constraints on ``y``: ``|y_i| <= s |x_i|`` for full and
    complex scalar blocks, plus ``Im(conj(x_i) y_i) = 0`` for real scalars and
    ``y_i = delta_i x_i`` for repeated ones.  Minimising ``s`` maximises the
    lower bound ``1/s``; the result is re-verified by the caller.
    """
    n = Ms.shape[0]
    T = np.block([[Ms.real, -Ms.imag], [Ms.imag, Ms.real]])
    y0 = delta0 @ x0
    ny = np.linalg.norm(y0)
    if ny == 0:
        return None
    y0 = y0 / ny
    rep = [(b, sl) for b, sl in zip(st.blocks, st.padded_slices) if b.repeated]
    nd = sum(1 if b.kind == "real" else 2 for b, _ in rep)
    nv = 2 * n + nd + 1
    dvals = []
    for b, sl in rep:
        d = delta0[sl.start, sl.start]
        dvals += [d.real] if b.kind == "real" else [d.real, d.imag]
    p0 = np.concatenate([y0.real, y0.imag, dvals, [_blocks_norm(delta0, st)]])
    cr, ci = y0.real, y0.imag
    Tr, Ti = T[:n], T[n:]
    I2n = np.eye(2 * n)
    blocks = list(zip(st.blocks, st.padded_slices))
    real1 = np.array([sl.start for b, sl in blocks if b.kind == "real" and not b.repeated], dtype=int)
    nonrep = [sl for b, sl in blocks if not b.repeated]
    reps, k = [], 2 * n
    for b, sl in blocks:
        if b.repeated:
            reps.append((sl, b.kind == "real", k))
            k += 1 if b.kind == "real" else 2

    def split(p):
        xx = T @ p[: 2 * n]
        return p[:n], p[n : 2 * n], xx[:n], xx[n:]

    # Analytic Jacobians: SLSQP with finite differences was ~10x slower.
    def eq(p):
        yr, yi, xr, xi = split(p)
        out = [[cr @ yr + ci @ yi - 1.0, cr @ yi - ci @ yr], xr[real1] * yi[real1] - xi[real1] * yr[real1]]
        for sl, is_real, k in reps:
            dr, di = p[k], (0.0 if is_real else p[k + 1])
            out += [yr[sl] - (dr * xr[sl] - di * xi[sl]), yi[sl] - (dr * xi[sl] + di * xr[sl])]
        return np.concatenate(out)

    def eq_jac(p):
        yr, yi, xr, xi = split(p)
        rows = [np.r_[cr, ci, np.zeros(nv - 2 * n)], np.r_[-ci, cr, np.zeros(nv - 2 * n)]]
        J = np.zeros((len(real1), nv))
        J[:, : 2 * n] = yi[real1, None] * Tr[real1] - yr[real1, None] * Ti[real1]
        J[np.arange(len(real1)), n + real1] += xr[real1]
        J[np.arange(len(real1)), real1] -= xi[real1]
        out = [np.array(rows), J]
        for sl, is_real, k in reps:
            dr, di = p[k], (0.0 if is_real else p[k + 1])
            m = sl.stop - sl.start
            J1, J2 = np.zeros((m, nv)), np.zeros((m, nv))
            J1[:, : 2 * n] = I2n[sl] - dr * Tr[sl] + di * Ti[sl]
            J2[:, : 2 * n] = I2n[n + sl.start : n + sl.stop] - dr * Ti[sl] - di * Tr[sl]
            J1[:, k], J2[:, k] = -xr[sl], -xi[sl]
            if not is_real:
                J1[:, k + 1], J2[:, k + 1] = xi[sl], -xr[sl]
            out += [J1, J2]
        return np.vstack(out)

    def ineq(p):
        yr, yi, xr, xi = split(p)
        s2 = p[-1] ** 2
        out = [s2 * (xr[sl] @ xr[sl] + xi[sl] @ xi[sl]) - (yr[sl] @ yr[sl] + yi[sl] @ yi[sl]) for sl in nonrep]
        out += [s2 - p[k] ** 2 - (0.0 if is_real else p[k + 1] ** 2) for _, is_real, k in reps]
        return np.array(out)

    def ineq_jac(p):
        yr, yi, xr, xi = split(p)
        s = p[-1]
        J = np.zeros((len(nonrep) + len(reps), nv))
        for r, sl in enumerate(nonrep):
            J[r, : 2 * n] = 2 * s**2 * (xr[sl] @ Tr[sl] + xi[sl] @ Ti[sl])
            J[r, sl] -= 2 * yr[sl]
            J[r, n + sl.start : n + sl.stop] -= 2 * yi[sl]
            J[r, -1] = 2 * s * (xr[sl] @ xr[sl] + xi[sl] @ xi[sl])
        for r, (_, is_real, k) in enumerate(reps, start=len(nonrep)):
            J[r, k] = -2 * p[k]
            if not is_real:
                J[r, k + 1] = -2 * p[k + 1]
            J[r, -1] = 2 * s
        return J

    e_s = np.eye(nv)[-1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = minimize(
            lambda p: p[-1],
            p0,
            jac=lambda p: e_s,
            method="SLSQP",
            constraints=[{"type": "eq", "fun": eq, "jac": eq_jac}, {"type": "ineq", "fun": ineq, "jac": ineq_jac}],
            bounds=[(None, None)] * (nv - 1) + [(0.0, None)],
            options={"maxiter": 200, "ftol": 1e-12},
        )
    p = res.x
    yr, yi, xr, xi = split(p)
    y, x = yr + 1j * yi, xr + 1j * xi
    delta = np.zeros((n, n), dtype=complex)
    k = 2 * n
    for b, sl in zip(st.blocks, st.padded_slices):
        xi_, yi_ = x[sl], y[sl]
        if b.repeated:
            d = p[k] + (0.0 if b.kind == "real" else 1j * p[k + 1])
            k += 1 if b.kind == "real" else 2
            delta[sl, sl] = d * np.eye(b.size)
        elif np.linalg.norm(xi_) > 1e-300:
            if b.kind == "real":
                delta[sl, sl] = (yi_[0] / xi_[0]).real
            else:
                delta[sl, sl] = np.outer(yi_, xi_.conj()) / np.vdot(xi_, xi_).real
    # Q := delta normalised; _candidate re-verifies and rescales exactly.
    nd_ = _blocks_norm(delta, st)
    return _candidate(Ms, st, delta / nd_) if nd_ > 0 else None


def lower_bound(Ms, st, *, starts=4, refine=True, seed=0, init=None, real_starts=8, target=np.inf, D=None):
    """Lower bound of ``mu(Ms)`` with its verified perturbation.

    Parameters
    ----------
    Ms : (n, n) complex ndarray
        Padded square matrix (:meth:`BlockStructure.pad`).
    st : BlockStructure
    starts, seed : int
        Power-iteration starts (singular vectors + random) and their seed.
    refine : bool
        Polish with the local search (SLSQP).
    init : tuple, optional
        Power-iteration state of a neighbouring frequency (warm start).
    real_starts : int
        Extra random seeds of the local search for real blocks.
    target : float
        A known upper bound: the search stops once it is reached.
    D : ndarray, optional
        Upper-bound scaling used to balance the power iteration.

    Returns
    -------
    lower : float
    delta : ndarray
        Padded perturbation with ``det(I - Ms delta) = 0`` (verified), or zeros.
    state : tuple or None
        Power-iteration state for the next frequency.

    Notes
    -----
    ``D`` (upper-bound scaling, commuting with Delta) balances the matrix for
    the power iteration: ``rho(D M D^-1 Q) = rho(M Q)`` so its Q's are valid
    for M, and the scaled matrix's singular vectors are far better starts
    (unscaled, they can sit on disjoint blocks and stall the iteration at a
    spurious fixed point).  ``target`` (a known upper bound) stops the local
    search once reached.
    """
    n = Ms.shape[0]
    meta = [
        ("real" if b.kind == "real" else "full" if (b.kind == "full" or b.size == 1) else "complex", b.repeated, sl)
        for b, sl in zip(st.blocks, st.padded_slices)
    ]
    if not np.any(Ms):
        return 0.0, np.zeros((n, n), complex), None
    rng = np.random.default_rng(seed)
    if D is None:
        D = perron_upper(Ms, st)[1]
    try:
        Mp = D @ Ms @ np.linalg.inv(D)
    except np.linalg.LinAlgError:
        Mp = Ms
    if not np.all(np.isfinite(Mp)):
        Mp = Ms
    try:
        U, _, Vh = np.linalg.svd(Mp)
    except np.linalg.LinAlgError:  # scalings over hundreds of decades (panda's per-link loop): LAPACK gives up
        Mp = Ms
        try:
            U, _, Vh = np.linalg.svd(Mp)
        except np.linalg.LinAlgError:  # no start for the search: 0, the bound that always holds
            return 0.0, np.zeros((n, n), complex), None
    inits = [init] if init is not None else []
    inits.append((Vh[0].conj(), U[:, 0]))
    for _ in range(starts - 1):
        inits.append(tuple(rng.standard_normal(n) + 1j * rng.standard_normal(n) for _ in range(2)))
    cands, state = [], None
    for b0, w0 in inits:
        Q, b, w = _power_iteration(Mp, meta, b0, w0)
        state = state or (b, w)
        c = _candidate(Ms, st, Q)
        if c is not None:
            cands.append(c)
        elif refine and np.any(Q):
            # no admissible eigenvalue yet (real blocks): seed the local
            # search with the dominant, possibly complex, eigenpair.
            lam, X = np.linalg.eig(Ms @ Q)
            k = int(np.argmax(np.abs(lam)))
            if abs(lam[k]) > 0:
                cands.append((0.0, Q / lam[k], X[:, k]))
    if st.has_real:
        cands += _vertex_candidates(Ms, st)
    good = [c for c in cands if c[0] > 0 and _singular(Ms, c[1])]
    best = max(good, key=lambda c: c[0]) if good else (0.0, np.zeros((n, n), complex))
    if refine and best[0] < target * (1 - 1e-7):
        seeds = sorted(cands, key=lambda c: -c[0])[:2]
        if st.has_real:
            # Real blocks make the lower bound a non-convex search with many
            # local optima (the power iteration often stalls); random
            # perturbations as extra seeds of the local search pay off.
            for _ in range(real_starts):
                Q = st.pad_delta(st.random_delta(rng, uniform=True))
                lam, X = np.linalg.eig(Ms @ Q)
                k = int(np.argmax(np.abs(lam)))
                if abs(lam[k]) > 0:
                    seeds.append((0.0, Q / lam[k], X[:, k]))
        for c in seeds:
            r = _refine(Ms, st, c[1], c[2])
            if r is not None and r[0] > best[0] and _singular(Ms, r[1]):
                best = r
                if best[0] >= target * (1 - 1e-7):  # matches the upper bound
                    break
    return best[0], best[1], state


def _singular(Ms, delta_sq, tol=1e-7):
    """Verify det(I - M Delta) = 0 via the smallest singular value.

    A candidate whose product overflows (a badly scaled ``M``) is not verified:
    the lower bound must rest on a singular matrix that was checked.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        A = np.eye(Ms.shape[0]) - Ms @ delta_sq
    if not np.all(np.isfinite(A)):
        return False
    try:
        s = np.linalg.svd(A, compute_uv=False)
    except np.linalg.LinAlgError:
        return False
    return s[-1] <= tol * max(1.0, s[0])
