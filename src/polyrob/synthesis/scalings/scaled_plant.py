"""The generalized plant of the K-step: the plant scaled by the fitted D (and G) filters.

``Fl(scaled_plant(P), K) = T`` of :meth:`~polyrob.synthesis.scalings.data.Scalings.transformed`;
see :mod:`polyrob.synthesis.scalings.dscale` for the method.
"""

from __future__ import annotations

import control
import numpy as np
import scipy.linalg as sla

from polyrob.errors import ArgumentError
from polyrob.synthesis.scalings.data import Scalings

__all__ = ["scaled_plant"]


def _diag_ss(items, n_ch):
    """Block-diagonal MIMO system from a list of per-channel SISO ``(A, B, C, D)``."""
    As, Bs, Cs, Ds = [], [], [], []
    for A, B, C, D in items:
        As.append(A)
        Bs.append(B)
        Cs.append(C)
        Ds.append(D)
    A = sla.block_diag(*As) if any(a.size for a in As) else np.zeros((0, 0))
    n = A.shape[0]
    B = np.zeros((n, n_ch))
    C = np.zeros((n_ch, n))
    D = np.zeros((n_ch, n_ch))
    r = 0
    for ch, (a, b, c, d) in enumerate(items):
        k = a.shape[0]
        B[r : r + k, ch] = b[:, 0]
        C[ch, r : r + k] = c[0, :]
        D[ch, ch] = d[0, 0]
        r += k
    return A, B, C, D


def _connect(systems, Q, R, H, E):
    """Interconnect ``systems`` (list of (A,B,C,D)): ``U = Q Y + R e``, ``out = H Y + E e``.

    The lower LFT of the static wiring ``[e; Y] -> [out; U] = [[E, H], [R, Q]]``
    with the block-diagonal stack of the systems.
    """
    A = sla.block_diag(*[s[0] for s in systems if s[0].size]) if any(s[0].size for s in systems) else np.zeros((0, 0))
    Bs = sla.block_diag(*[s[1] if s[1].size else np.zeros((s[0].shape[0], s[3].shape[1])) for s in systems])
    Cs = sla.block_diag(*[s[2] if s[2].size else np.zeros((s[3].shape[0], s[0].shape[0])) for s in systems])
    Ds = sla.block_diag(*[s[3] for s in systems])
    Bs = Bs.reshape(A.shape[0], Ds.shape[1])
    Cs = Cs.reshape(Ds.shape[0], A.shape[0])
    # the wiring's own solve, not plant.loops.lower_lft_matrices: that one refuses a loop whose
    # I - D22 Dk has condition above 1e12 (an ill-posed physical loop), and the filter stacks of
    # high-order D/G scalings reach such conditions while the interconnection is still exact
    L = np.eye(Q.shape[0]) - Q @ Ds
    Li = np.linalg.solve(L, np.hstack([Q @ Cs, R]))
    LQ, LR = Li[:, : A.shape[0]], Li[:, A.shape[0] :]
    Acl = A + Bs @ LQ
    Bcl = Bs @ LR
    Ccl = H @ (Cs + Ds @ LQ)
    Dcl = H @ Ds @ LR + E
    return Acl, Bcl, Ccl, Dcl


def scaled_plant(P: control.StateSpace, scalings: Scalings, n_u: int, n_y: int) -> control.StateSpace:
    """Generalized plant of the K-step: ``Fl(P_s, K) = T`` of :meth:`Scalings.transformed`.

    ``P`` has inputs ``[x (M columns); u]`` and outputs ``[y (M rows); y_meas]``.
    The result has inputs ``[x̃; u]`` and outputs ``[ỹ; y_meas]`` with
    ``x = D^{-1} x̃ - F y``, ``ỹ = D (y + F x)`` and ``y = (P's M rows)/β``.
    With no G scaling this is ``diag(D, I) P diag(D^{-1}, I)/β`` on the M channels.
    Each scalar filter is realised in balanced form; ``D^{-1}`` is realised
    from the inverted factors, not by inverting a realisation.
    """
    st = scalings.structure
    A, B, C, D = (np.array(X, float) for X in (P.A, P.B, P.C, P.D))
    nr, nc = st.m_shape
    if (C.shape[0] - n_y, B.shape[1] - n_u) != (nr, nc):
        raise ArgumentError(
            f"plant has {C.shape[0] - n_y}x{B.shape[1] - n_u} M channels but the structure needs {nr}x{nc}"
        )
    beta = float(scalings.beta)
    C = C.copy()
    D = D.copy()
    C[:nr] /= beta
    D[:nr] /= beta
    one = (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[1.0]]))
    dl, dri = [one] * nr, [one] * nc
    real_rows, real_cols, Fs = [], [], []
    for b, sc, rsl, csl in zip(st.blocks, scalings.blocks, st.col_slices, st.row_slices):
        if sc.d is not None and (sc.d.order > 0 or abs(sc.d.gain - 1.0) > 0):
            fwd, inv = sc.d.ss(), sc.d.ss(inverse=True)
            for r in range(rsl.start, rsl.stop):
                dl[r] = fwd
            for c in range(csl.start, csl.stop):
                dri[c] = inv
        if b.kind == "real" and sc.F is not None and sc.F.order > 0:
            for j in range(b.rows):
                real_rows.append(rsl.start + j)
                real_cols.append(csl.start + j)
                Fs.append(sc.F.ss())
    Sdl = _diag_ss(dl, nr)
    Sdr = _diag_ss(dri, nc)
    nu_all = B.shape[1]
    ny_all = C.shape[0]
    if not Fs:
        # x = D^-1 x̃ ; ỹ = D y
        systems = [Sdr, (A, B, C, D), Sdl]
        # stacked inputs: [Sdr in (nc); P in (nc + n_u); Sdl in (nr)]
        # stacked outputs: [Sdr out (nc); P out (nr + n_y); Sdl out (nr)]
        nU = nc + nu_all + nr
        nY = nc + ny_all + nr
        Q = np.zeros((nU, nY))
        R = np.zeros((nU, nc + n_u))
        Q[nc : nc + nc, :nc] = np.eye(nc)  # P's x <- Sdr out
        Q[nc + nu_all :, nc : nc + nr] = np.eye(nr)  # Sdl in <- P's y
        R[:nc, :nc] = np.eye(nc)  # Sdr in <- x̃
        R[nc + nc : nc + nu_all, nc:] = np.eye(n_u)  # P's u <- u
        Hm = np.zeros((nr + n_y, nY))
        Hm[:nr, nc + ny_all :] = np.eye(nr)  # ỹ <- Sdl out
        Hm[nr:, nc + nr : nc + ny_all] = np.eye(n_y)  # y_meas
        E = np.zeros((nr + n_y, nc + n_u))
    else:
        nf = len(Fs)
        Er = np.zeros((nf, nr))
        Ec = np.zeros((nf, nc))
        Er[np.arange(nf), real_rows] = 1.0
        Ec[np.arange(nf), real_cols] = 1.0
        SF1 = _diag_ss(Fs, nf)  # f1 = F y_real   (feeds x = x' - Ec^T f1)
        SF2 = _diag_ss(Fs, nf)  # f2 = F x_real   (ỹ = D (y + Er^T f2))
        systems = [Sdr, (A, B, C, D), SF1, SF2, Sdl]
        # inputs: Sdr(nc) | P(nc+n_u) | SF1(nf) | SF2(nf) | Sdl(nr)
        iS, iP, i1, i2, iL = 0, nc, nc + nu_all, nc + nu_all + nf, nc + nu_all + 2 * nf
        nU = iL + nr
        # outputs: Sdr(nc) | P(nr+n_y) | SF1(nf) | SF2(nf) | Sdl(nr)
        oS, oP, o1, o2, oL = 0, nc, nc + ny_all, nc + ny_all + nf, nc + ny_all + 2 * nf
        nY = oL + nr
        Q = np.zeros((nU, nY))
        R = np.zeros((nU, nc + n_u))
        R[iS : iS + nc, :nc] = np.eye(nc)
        # P's x = x' - Ec^T f1
        Q[iP : iP + nc, oS : oS + nc] = np.eye(nc)
        Q[iP : iP + nc, o1 : o1 + nf] = -Ec.T
        R[iP + nc : iP + nu_all, nc:] = np.eye(n_u)
        # SF1 in = y_real = Er y
        Q[i1 : i1 + nf, oP : oP + nr] = Er
        # SF2 in = x_real = Ec x = Ec (x' - Ec^T f1)
        Q[i2 : i2 + nf, oS : oS + nc] = Ec
        Q[i2 : i2 + nf, o1 : o1 + nf] = -Ec @ Ec.T
        # Sdl in = y + Er^T f2
        Q[iL : iL + nr, oP : oP + nr] = np.eye(nr)
        Q[iL : iL + nr, o2 : o2 + nf] = Er.T
        Hm = np.zeros((nr + n_y, nY))
        Hm[:nr, oL : oL + nr] = np.eye(nr)
        Hm[nr:, oP + nr : oP + ny_all] = np.eye(n_y)
        E = np.zeros((nr + n_y, nc + n_u))
    As, Bs, Cs, Ds = _connect(systems, Q, R, Hm, E)
    return control.ss(As, Bs, Cs, Ds, dt=0)
