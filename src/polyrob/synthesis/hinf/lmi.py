"""LMI route of the H∞ synthesis (cvxpy + Clarabel).

The full-order LMI of Gahinet & Apkarian (1994) in the linearising change
of variables of Scherer, Gahinet & Chilali (1997), then the controller
reconstructed from ``X, Y``.  A second pass at a slightly larger γ pushes
``[Y I; I X]`` away from singular so that the reconstruction is well
conditioned; when that pass (or the interior-point solver) fails, what was
done instead is recorded in ``info["fallbacks"]``.
"""

from __future__ import annotations

import warnings

import numpy as np

from polyrob.errors import SynthesisError
from polyrob.synthesis.hinf.problem import SynthesisProblem

__all__ = ["lmi_controller"]


def lmi_controller(prob: SynthesisProblem, tol: float, solver: str | None = None):
    """Full-order H∞ LMI (Scherer-Gahinet-Chilali change of variables) + reconstruction."""
    import cvxpy as cp

    A, B, C, D = prob.A, prob.B, prob.C, prob.D
    nu, ny = prob.n_u, prob.n_y
    n = A.shape[0]
    nw, nz = B.shape[1] - nu, C.shape[0] - ny
    B1, B2 = B[:, :nw], B[:, nw:]
    C1, C2 = C[:nz], C[nz:]
    D11, D12, D21, D22 = D[:nz, :nw], D[:nz, nw:], D[nz:, :nw], D[nz:, nw:]
    X = cp.Variable((n, n), symmetric=True)
    Y = cp.Variable((n, n), symmetric=True)
    Ah = cp.Variable((n, n))
    Bh = cp.Variable((n, ny))
    Ch = cp.Variable((nu, n))
    Dh = cp.Variable((nu, ny))
    g = cp.Variable(nonneg=True)
    AA = cp.bmat([[A @ Y + B2 @ Ch, A + B2 @ Dh @ C2], [Ah, X @ A + Bh @ C2]])
    BB = cp.vstack([B1 + B2 @ Dh @ D21, X @ B1 + Bh @ D21])
    CC = cp.hstack([C1 @ Y + D12 @ Ch, C1 + D12 @ Dh @ C2])
    DD = D11 + D12 @ Dh @ D21
    L = cp.bmat(
        [
            [AA + AA.T, BB, CC.T],
            [BB.T, -g * np.eye(nw), DD.T],
            [CC, DD, -g * np.eye(nz)],
        ]
    )
    XY = cp.bmat([[Y, np.eye(n)], [np.eye(n), X]])
    kappa = 1e6
    delta = 1e-7
    N = L.shape[0]
    cons = [
        (L + L.T) / 2 << -delta * np.eye(N),
        (XY + XY.T) / 2 >> delta * np.eye(2 * n),
        X << kappa * np.eye(n),
        Y << kappa * np.eye(n),
    ]
    fallbacks = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prob1 = cp.Problem(cp.Minimize(g), cons)
        try:
            prob1.solve(solver=solver or "CLARABEL")
        except cp.error.SolverError as exc:
            # interior-point failure: a first-order solver, and say so
            fallbacks.append(f"LMI: {solver or 'CLARABEL'} failed ({exc}); solved with SCS instead")
            try:
                prob1.solve(solver="SCS", eps=1e-7, max_iters=50000)
            except cp.error.SolverError as exc2:
                raise SynthesisError(f"H∞ LMI synthesis failed: {exc2}") from None
        if prob1.status not in ("optimal", "optimal_inaccurate") or g.value is None:
            raise SynthesisError(f"H∞ LMI synthesis failed (solver status {prob1.status})")
        gstar = float(g.value)
        saved = [np.array(V.value) for V in (X, Y, Ah, Bh, Ch, Dh)]
        # second pass at a slightly larger γ: push [Y I; I X] away from
        # singular so that I - XY (and the reconstruction) is well conditioned
        eta = cp.Variable()
        gfix = gstar * (1 + max(tol, 1e-2))
        cons2 = [
            (L + L.T) / 2 << -delta * np.eye(N),
            (XY + XY.T) / 2 >> eta * np.eye(2 * n),
            X << kappa * np.eye(n),
            Y << kappa * np.eye(n),
            g == gfix,
            eta <= 1.0,
        ]
        prob2 = cp.Problem(cp.Maximize(eta), cons2)
        try:
            prob2.solve(solver=solver or "CLARABEL")
            status2 = prob2.status
        except cp.error.SolverError as exc:
            status2 = f"solver error: {exc}"
        if status2 in ("optimal", "optimal_inaccurate") and X.value is not None:
            saved = [np.array(V.value) for V in (X, Y, Ah, Bh, Ch, Dh)]
        else:
            gfix = gstar
            fallbacks.append(
                f"LMI: the conditioning pass at gamma = {gstar * (1 + max(tol, 1e-2)):.4g} failed "
                f"({status2}); controller reconstructed from the first pass"
            )
    Xv, Yv, Ahv, Bhv, Chv, Dhv = saved
    # U V^T = I - X Y, split by an SVD for balance
    Um, s, Vt = np.linalg.svd(np.eye(n) - Xv @ Yv)
    if s[-1] <= 1e-12 * max(1.0, s[0]):
        raise SynthesisError(
            "H∞ LMI synthesis: I - XY is singular, controller reconstruction impossible"
            + "".join(f" ({f})" for f in fallbacks)
        )
    U = Um * np.sqrt(s)[None, :]
    V = Vt.T * np.sqrt(s)[None, :]
    Dk = Dhv
    Ck = np.linalg.solve(V, (Chv - Dk @ C2 @ Yv).T).T
    Bk = np.linalg.solve(U, Bhv - Xv @ B2 @ Dk)
    inner = Ahv - Xv @ (A + B2 @ Dk @ C2) @ Yv - U @ Bk @ C2 @ Yv - Xv @ B2 @ Ck @ V.T
    Ak = np.linalg.solve(U, np.linalg.solve(V, inner.T).T)
    if np.any(D22):
        # the LMI assumed D22 = 0: close u = Kt (y - D22 u)
        R = np.eye(nu) + Dk @ D22
        Ri = np.linalg.inv(R)
        Ck2, Dk2 = Ri @ Ck, Ri @ Dk
        Ak = Ak - Bk @ D22 @ Ck2
        Bk = Bk - Bk @ D22 @ Dk2
        Ck, Dk = Ck2, Dk2
    return (Ak, Bk, Ck, Dk), {
        "gamma": gfix,
        "gamma_lmi_opt": gstar,
        "solver_status": prob1.status,
        "fallbacks": fallbacks,
    }
