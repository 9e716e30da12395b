"""The generalized plant ``P`` of the paper's eq. (10), its LFTs and loop functions.

:func:`generalized_plant` augments an :class:`~polyrob.plant.uncertainty.UncertainPlant`
with performance weights (mixed sensitivity, MATLAB's ``augw`` plus the
uncertainty channels) into the plant ``P`` partitioned as in eq. (10)::

    inputs  [d; w; u]:  d  uncertainty (n_delta),  w = r  reference (m),  u  control (m)
    outputs [v; z; y]:  v  uncertainty (n_delta),  z = [W_S e; W_T y; W_KS u],  y_meas = e = r - y

    P : [ ẋ ]   [ A   | B_d   B_w   B_u  ] [ x ]
        [ v ] = [ C_v | D_vd  D_vw  D_vu ] [ d ]
        [ z ]   [ C_z | D_zd  D_zw  D_zu ] [ w ]
        [ y ]   [ C_y | D_yd  D_yw  D_yu ] [ u ]

Inside ``P`` (``Δ`` closes ``d = Δ v`` from above, the controller ``u = K e``
from below)::

                      +-------+
               +------|   Δ   |<------+
               | d    +-------+     v |
               v                      |
          +---------------------------+--+
    u -+->|             G(Δ)             |--+-- y --> W_T --> z_T
       |  +------------------------------+  |
       |                                    | (-)
       +--> W_KS --> z_KS             r --> (+) -- e --> W_S --> z_S
                                                |
                                                +--> y_meas = e   (u = K y_meas)

``lft(P, K)`` is the paper's ``LLFT(P, K)``: the closed loop ``N`` from
``[d; w]`` to ``[v; z]``, analysed with :math:`\\mu` against
``diag(Δ_unc, Δ_perf)`` where ``Δ_perf`` is a full complex ``n_w x n_z``
block (it maps ``z`` back to ``w``), i.e. MATLAB ``blk`` row ``[n_w, n_z]``
(:attr:`GeneralizedPlant.block_structure_rp`).

The interconnection is assembled by hand from explicit state-space
matrices rather than with ``control.interconnect``: the partition and the
state order are then known exactly, nothing is reduced or reordered, and
the matrices are bit-for-bit those of the uncertain plant and the weights.

Examples
--------
>>> import polyrob
>>> from polyrob.plant.uncertainty import uncertain_plant
>>> from polyrob.plant.generalized import generalized_plant, lft, paper_controller
>>> from polyrob.plant.weights import paper_weights
>>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
>>> W_S, W_T = paper_weights()
>>> P = generalized_plant(uncertain_plant(pldi), W_S, W_T)
>>> P.n_delta, P.n_w, P.n_z, P.n_u, P.n_y
(10, 2, 4, 2, 2)
>>> P.block_structure_rp[-1].tolist()
[2, 4]
>>> N = lft(P, paper_controller())
>>> N.ninputs, N.noutputs
(12, 14)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import control
import numpy as np
import scipy.linalg as sla

from polyrob.errors import PolyrobError
from polyrob.plant.lftplant import UncertainPlant, upper_lft

__all__ = [
    "GeneralizedPlant",
    "ClosedLoop",
    "generalized_plant",
    "lft",
    "loop_functions",
    "closed_loop",
    "nominal_closed_loop",
    "paper_controller",
    "PAPER_CONTROLLER",
]

#: The paper's fixed-structure controller K*(s) (section 3), numerator and
#: denominator coefficients (descending powers of s) of each entry, transcribed
#: exactly as printed.
PAPER_CONTROLLER = {
    "num": [
        [[1.07e5, 1.392e5, 44157.0], [264150.0, 5.362e05, 15849.0]],
        [[3.421e4, 4.447e4, 14454.0], [1.172e5, 4.728e5, 16406.0]],
    ],
    "den": [
        [[0.02, 4.0, 200.0, 1.0], [0.08333, 13.33, 500.0, 1.0]],
        [[0.01422, 3.556, 222.2, 1.0], [0.02319, 6.494, 454.6, 1.0]],
    ],
}


def paper_controller() -> control.TransferFunction:
    """The paper's fixed-structure robust controller ``K*(s)`` (section 3).

    A 2x2 matrix of third-order transfer functions from ``e = r - q`` to ``u``,
    obtained there by fixed-structure ``musyn`` (μ upper bound 0.9999 against
    the paper's intervals and weights).  Stable, no integral action.

    Examples
    --------
    >>> from polyrob.plant.generalized import paper_controller
    >>> K = paper_controller()
    >>> K.ninputs, K.noutputs, K.den[1][1].tolist()
    (2, 2, [0.02319, 6.494, 454.6, 1.0])
    >>> round(float(K(0)[0, 0].real))
    44157
    """
    return control.tf(
        PAPER_CONTROLLER["num"], PAPER_CONTROLLER["den"],
        inputs=["e[0]", "e[1]"], outputs=["u[0]", "u[1]"], name="K*",
    )


# --------------------------------------------------------------------------- realisations


def _is_static(W) -> bool:
    return isinstance(W, (int, float, np.integer, np.floating)) or (
        isinstance(W, np.ndarray) and W.ndim <= 2
    )


def _siso_ss(num, den) -> control.StateSpace:
    num = np.trim_zeros(np.atleast_1d(np.asarray(num, dtype=float)), "f")
    den = np.trim_zeros(np.atleast_1d(np.asarray(den, dtype=float)), "f")
    if len(num) == 0:
        return control.ss([], [], [], [[0.0]], dt=0)
    if len(num) > len(den):
        raise PolyrobError("an improper transfer function has no state-space realisation")
    if len(den) == 1:
        return control.ss([], [], [], [[num[0] / den[0]]], dt=0)
    return control.ss(control.tf(num, den))


def _block_ss(entries, p, q) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sum of ``e_i G_ij e_j^T`` for SISO state-space ``entries[(i, j)]``: (A, B, C, D)."""
    As, Bs, Cs = [], [], []
    D = np.zeros((p, q))
    for (i, j), g in entries.items():
        D[i, j] = float(np.asarray(g.D)[0, 0])
        ns = g.nstates
        if ns == 0:
            continue
        As.append(np.asarray(g.A))
        b = np.zeros((ns, q))
        b[:, j] = np.asarray(g.B)[:, 0]
        c = np.zeros((p, ns))
        c[i, :] = np.asarray(g.C)[0, :]
        Bs.append(b)
        Cs.append(c)
    if As:
        return sla.block_diag(*As), np.vstack(Bs), np.hstack(Cs), D
    return np.zeros((0, 0)), np.zeros((0, q)), np.zeros((p, 0)), D


def _as_ss(sys, what: str) -> control.StateSpace:
    """Continuous-time state space of an LTI system, realised exactly.

    A MIMO ``TransferFunction`` is realised entry by entry (order = sum of the
    entries' degrees, zero entries skipped): exact and minimal for diagonal
    weights and for ``K*`` (whose entries have distinct poles), whereas a
    common-denominator realisation (``control.ss`` on a MIMO TF) loses ~1e-10
    relative accuracy at low frequency on ``K*``.  Pass a ``StateSpace`` to
    impose another realisation.
    """
    if isinstance(sys, control.StateSpace):
        out = sys
    elif isinstance(sys, control.TransferFunction):
        p, q = sys.noutputs, sys.ninputs
        try:
            entries = {(i, j): _siso_ss(sys.num[i][j], sys.den[i][j]) for i in range(p) for j in range(q)}
        except (ValueError, PolyrobError) as exc:
            raise PolyrobError(f"{what}: {exc}") from None
        A, B, C, D = _block_ss(entries, p, q)
        out = control.ss(A, B, C, D, dt=sys.dt)
    elif isinstance(sys, control.LTI):
        try:
            out = control.ss(sys)
        except Exception as exc:
            raise PolyrobError(f"{what}: cannot convert {type(sys).__name__} to state space ({exc})") from None
    else:
        raise PolyrobError(f"{what} must be a python-control LTI system or a number, got {type(sys).__name__}")
    if out.dt not in (0, None):
        raise PolyrobError(f"{what} is discrete-time (dt={out.dt}); the plant is continuous-time")
    return out


def _weight(W, m: int, name: str) -> control.StateSpace | None:
    """An ``m x m`` weight from a SISO weight (one copy per channel), an ``m x m`` one or a gain."""
    if W is None:
        return None
    if _is_static(W):
        G = np.asarray(W, dtype=float)
        if G.ndim == 0:
            G = float(G) * np.eye(m)
        if G.shape != (m, m):
            raise PolyrobError(f"{name} is a {G.shape} gain; expected a scalar or {m}x{m}")
        if not np.all(np.isfinite(G)):
            raise PolyrobError(f"{name} has non-finite entries")
        return control.ss(np.zeros((0, 0)), np.zeros((0, m)), np.zeros((m, 0)), G, dt=0)
    if not isinstance(W, control.LTI):
        raise PolyrobError(f"{name} must be a python-control LTI system, an array or a number, got {type(W).__name__}")
    p, q = W.noutputs, W.ninputs
    if (p, q) == (1, 1):
        # a SISO weight applies to every channel: m decoupled copies
        g = _as_ss(W, name)
        A = sla.block_diag(*([np.asarray(g.A)] * m)) if g.nstates else np.zeros((0, 0))
        B = sla.block_diag(*([np.asarray(g.B)] * m)) if g.nstates else np.zeros((0, m))
        C = sla.block_diag(*([np.asarray(g.C)] * m)) if g.nstates else np.zeros((m, 0))
        out = control.ss(A, B, C, float(np.asarray(g.D)[0, 0]) * np.eye(m), dt=0)
    elif (p, q) == (m, m):
        out = _as_ss(W, name)
    else:
        raise PolyrobError(
            f"{name} is {p}x{q}; expected SISO (applied to every channel) or {m}x{m} (the robot has m={m} joints)"
        )
    if out.nstates:
        poles = np.linalg.eigvals(np.asarray(out.A))
        if np.max(poles.real) >= 0:
            raise PolyrobError(
                f"{name} has a pole with Re >= 0 ({poles[np.argmax(poles.real)]:.4g}): weights sit outside the "
                "loop, so the generalized plant would not be stabilisable; use a stable weight (e.g. makeweight)"
            )
    return out


def _mats(sys: control.StateSpace):
    return tuple(np.asarray(X, dtype=float) for X in (sys.A, sys.B, sys.C, sys.D))


# --------------------------------------------------------------------------- generalized plant


@dataclass(frozen=True, eq=False)
class GeneralizedPlant:
    """The generalized plant ``P`` (eq. 10) and its partition.

    Attributes
    ----------
    system : control.StateSpace
        Inputs ``[d (n_delta), w = r (n_w), u (n_u)]``, outputs
        ``[v (n_delta), z (n_z), e (n_y)]``; states ``[x (2m), W_S, W_T, W_KS]``.
    uncertain : UncertainPlant
    W_S, W_T, W_KS : control.StateSpace or None
        The ``m x m`` weights as realised (``None``: channel omitted).
    regularize : float or None
        ``ε`` of the extra ``z_reg = ε u`` channel, if any.
    n_delta, n_w, n_z, n_u, n_y : int
    z_labels : tuple of str
        What each ``z`` block is: ``"W_S e"``, ``"W_T y"``, ``"W_KS u"``, ``"reg u"``.
    block_structure_rs : ndarray
        MATLAB ``blk`` for robust stability: the uncertainty blocks.
    block_structure_rp : ndarray
        For robust performance: the uncertainty blocks and ``[n_w, n_z]``.
    """

    system: control.StateSpace
    uncertain: UncertainPlant
    W_S: control.StateSpace | None
    W_T: control.StateSpace | None
    W_KS: control.StateSpace | None
    regularize: float | None
    n_delta: int
    n_w: int
    n_z: int
    n_u: int
    n_y: int
    z_labels: tuple[str, ...]
    block_structure_rs: np.ndarray
    block_structure_rp: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def n_x(self) -> int:
        return self.system.nstates

    @property
    def input_slices(self) -> dict[str, slice]:
        """``{"d": ..., "w": ..., "u": ...}`` column ranges of ``P``."""
        a, b = self.n_delta, self.n_delta + self.n_w
        return {"d": slice(0, a), "w": slice(a, b), "u": slice(b, b + self.n_u)}

    @property
    def output_slices(self) -> dict[str, slice]:
        """``{"v": ..., "z": ..., "y": ...}`` row ranges of ``P``."""
        a, b = self.n_delta, self.n_delta + self.n_z
        return {"v": slice(0, a), "z": slice(a, b), "y": slice(b, b + self.n_y)}

    @property
    def z_slices(self) -> dict[str, slice]:
        """Rows of ``z`` (within ``z``) of each weighted signal, keyed by :attr:`z_labels`."""
        m, out, start = self.n_u, {}, 0
        for lab in self.z_labels:
            out[lab] = slice(start, start + m)
            start += m
        return out

    def at(self, delta, *, strict: bool = True) -> control.StateSpace:
        """``P`` with its uncertainty closed at ``δ``: ``[w; u] -> [z; y]`` (upper LFT)."""
        unc = self.uncertain
        d = unc._check_delta(delta, strict)
        return upper_lft(self.system, unc.delta_matrix(d))


def generalized_plant(
    unc: UncertainPlant, W_S=None, W_T=None, W_KS=None, *, regularize: float | None = None
) -> GeneralizedPlant:
    """Augment the uncertain plant with weights: the paper's ``P`` (eq. 10).

    Parameters
    ----------
    unc : UncertainPlant
    W_S, W_T, W_KS : LTI system, array or number, optional
        Weights on ``e = r - y``, ``y`` and ``u``: SISO (applied to every
        channel), ``m x m`` (diagonal in the paper; any ``m x m`` is accepted)
        or a static gain.  Continuous-time, proper and stable.  ``None``
        omits the channel; at least one must be given.
    regularize : float, optional
        ``ε > 0`` appends ``z_reg = ε u`` so that ``D_zu`` has full column rank
        (needed by H∞/D-K synthesis when ``W_KS`` is omitted: ``G`` is
        strictly proper).  It also enlarges ``z`` and the performance block.

    Returns
    -------
    GeneralizedPlant

    Raises
    ------
    PolyrobError
        A weight of the wrong size, discrete-time, improper or unstable; no
        weight at all; a non-positive ``regularize``.

    Examples
    --------
    >>> import control, polyrob
    >>> from polyrob.plant.uncertainty import uncertain_plant
    >>> from polyrob.plant.generalized import generalized_plant
    >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    >>> P = generalized_plant(uncertain_plant(pldi), control.tf([0.5, 0.5], [1, 0.005]), W_KS=1e-3)
    >>> P.z_labels, P.n_z, P.system.nstates
    (('W_S e', 'W_KS u'), 4, 6)
    >>> P.system.input_labels[10:]
    ['r[0]', 'r[1]', 'u[0]', 'u[1]']
    """
    if not isinstance(unc, UncertainPlant):
        raise PolyrobError(f"generalized_plant needs an UncertainPlant, got {type(unc).__name__}")
    m = unc.m
    WS, WT, WKS = _weight(W_S, m, "W_S"), _weight(W_T, m, "W_T"), _weight(W_KS, m, "W_KS")
    if regularize is not None:
        try:
            eps = float(regularize)
        except (TypeError, ValueError):
            raise PolyrobError(f"regularize must be a positive number, got {regularize!r}") from None
        if not (math.isfinite(eps) and eps > 0):
            raise PolyrobError(f"regularize must be a positive number, got {regularize!r}")
    else:
        eps = None
    if WS is None and WT is None and WKS is None and eps is None:
        raise PolyrobError("give at least one weight (W_S, W_T or W_KS): z would be empty")

    n, nd = unc.n_x, unc.n_delta
    A_g, B_g, C_g = unc.A_mid, unc.B_mid, unc.C
    I_m, Z_m = np.eye(m), np.zeros((m, m))

    # every block row below is written as [coefficients on x | d | r | u] plus the
    # weight's own states; the signals feeding each weight are
    #   e = r - C x,   y = C x,   u = u
    feeds = {  # (x, d, r, u) coefficients of each weight's input signal
        "W_S e": (-C_g, np.zeros((m, nd)), I_m, Z_m),
        "W_T y": (C_g, np.zeros((m, nd)), Z_m, Z_m),
        "W_KS u": (np.zeros((m, n)), np.zeros((m, nd)), Z_m, I_m),
    }
    weights = [(lab, W) for lab, W in (("W_S e", WS), ("W_T y", WT), ("W_KS u", WKS)) if W is not None]
    nw_states = [W.nstates for _, W in weights]
    N = n + sum(nw_states)
    n_z = m * (len(weights) + (eps is not None))
    n_in = nd + m + m
    A = np.zeros((N, N))
    B = np.zeros((N, n_in))
    Cz = np.zeros((n_z, N))
    Dz = np.zeros((n_z, n_in))
    A[:n, :n] = A_g
    B[:n, :nd] = unc.B_d
    B[:n, nd + m :] = B_g
    start, row = n, 0
    labels = []
    for (lab, W), ns in zip(weights, nw_states):
        Aw, Bw, Cw, Dw = _mats(W)
        fx, fd, fr, fu = feeds[lab]
        feed_x = fx  # the weight's input in terms of x (of G) ...
        feed_in = np.hstack([fd, fr, fu])  # ... and of [d, r, u]
        sl = slice(start, start + ns)
        A[sl, sl] = Aw
        A[sl, :n] = Bw @ feed_x
        B[sl, :] = Bw @ feed_in
        rows = slice(row, row + m)
        Cz[rows, sl] = Cw
        Cz[rows, :n] = Dw @ feed_x
        Dz[rows, :] = Dw @ feed_in
        labels.append(lab)
        start += ns
        row += m
    if eps is not None:
        Dz[row : row + m, nd + m :] = eps * I_m
        labels.append("reg u")

    Cv = np.zeros((nd, N))
    Cv[:, :n] = unc.C_v
    Dv = np.zeros((nd, n_in))
    Dv[:, :nd] = unc.D_vd
    Dv[:, nd + m :] = unc.D_vu
    Ce = np.zeros((m, N))
    Ce[:, :n] = -C_g
    De = np.zeros((m, n_in))
    De[:, nd : nd + m] = I_m
    C = np.vstack([Cv, Cz, Ce])
    D = np.vstack([Dv, Dz, De])

    _, y_lab, x_lab, d_lab, v_lab = unc._labels()
    tags = {"W_S e": "z_S", "W_T y": "z_T", "W_KS u": "z_KS", "reg u": "z_reg"}
    z_names = [f"{tags[lab]}[{i}]" for lab in labels for i in range(m)]
    w_names = [f"xw[{i}]" for i in range(N - n)]
    system = control.ss(
        A, B, C, D,
        inputs=d_lab + [f"r[{i}]" for i in range(m)] + [f"u[{i}]" for i in range(m)],
        outputs=v_lab + z_names + [f"e[{i}]" for i in range(m)],
        states=x_lab + w_names, name="P", dt=0,
    )
    blk_rs = np.asarray(unc.block_structure, dtype=int).reshape(-1, 2)
    blk_rp = np.vstack([blk_rs, [[m, n_z]]]).astype(int)
    return GeneralizedPlant(
        system=system, uncertain=unc, W_S=WS, W_T=WT, W_KS=WKS, regularize=eps,
        n_delta=nd, n_w=m, n_z=n_z, n_u=m, n_y=m, z_labels=tuple(labels),
        block_structure_rs=blk_rs, block_structure_rp=blk_rp,
    )


# --------------------------------------------------------------------------- lower LFT


def _lft_mats(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y):
    """Matrices of ``Fl(P, K)``; raises ``np.linalg.LinAlgError`` if ill posed."""
    nw, nz = B.shape[1] - n_u, C.shape[0] - n_y
    B1, B2 = B[:, :nw], B[:, nw:]
    C1, C2 = C[:nz], C[nz:]
    D11, D12, D21, D22 = D[:nz, :nw], D[:nz, nw:], D[nz:, :nw], D[nz:, nw:]
    R = np.eye(n_y) - D22 @ Dk
    if np.linalg.cond(R) > 1e12:
        raise np.linalg.LinAlgError("I - D22 Dk is singular")
    Yx, Yw, Yk = (np.linalg.solve(R, X) for X in (C2, D21, D22 @ Ck))
    Ux, Uw, Uk = Dk @ Yx, Dk @ Yw, Ck + Dk @ Yk
    Acl = np.block([[A + B2 @ Ux, B2 @ Uk], [Bk @ Yx, Ak + Bk @ Yk]])
    Bcl = np.vstack([B1 + B2 @ Uw, Bk @ Yw])
    Ccl = np.hstack([C1 + D12 @ Ux, D12 @ Uk])
    Dcl = D11 + D12 @ Uw
    return Acl, Bcl, Ccl, Dcl


def _lower_lft(P: control.StateSpace, K: control.StateSpace, n_u: int, n_y: int) -> control.StateSpace:
    """``Fl(P, K)`` closing the last ``n_u`` inputs with ``u = K y`` on the last ``n_y`` outputs."""
    nw, nz = P.ninputs - n_u, P.noutputs - n_y
    try:
        Acl, Bcl, Ccl, Dcl = _lft_mats(*_mats(P), *_mats(K), n_u, n_y)
    except np.linalg.LinAlgError:
        raise PolyrobError("the lower LFT is ill posed: I - D_yu D_K is singular") from None
    states = list(P.state_labels) + [f"xK[{i}]" for i in range(K.nstates)]
    return control.ss(
        Acl, Bcl, Ccl, Dcl, inputs=P.input_labels[:nw], outputs=P.output_labels[:nz], states=states, dt=0,
    )


def _controller(K, n_u: int, n_y: int) -> control.StateSpace:
    Ks = _as_ss(K, "K") if not _is_static(K) else control.ss(
        np.zeros((0, 0)), np.zeros((0, n_y)), np.zeros((n_u, 0)), np.atleast_2d(np.asarray(K, float)), dt=0
    )
    if (Ks.noutputs, Ks.ninputs) != (n_u, n_y):
        raise PolyrobError(
            f"K maps {Ks.ninputs} inputs to {Ks.noutputs} outputs; expected {n_y} measurements -> {n_u} controls"
        )
    return Ks


def lft(P, K, *, n_u: int | None = None, n_y: int | None = None) -> control.StateSpace:
    """Lower LFT ``N = Fl(P, K)`` (the paper's ``LLFT(P, K)``), closing ``u = K y_meas``.

    Parameters
    ----------
    P : GeneralizedPlant or control.StateSpace
        For a bare ``StateSpace`` give ``n_u``/``n_y`` (the controls are the
        last ``n_u`` inputs, the measurements the last ``n_y`` outputs).
    K : LTI system or array
        ``n_u x n_y`` controller (a ``TransferFunction`` is realised entry by
        entry, see :func:`_as_ss`), continuous-time.

    Returns
    -------
    control.StateSpace
        For a :class:`GeneralizedPlant`: ``[d; w] -> [v; z]``, states
        ``[P's, K's]``, ready for ``mu_bounds(N, P.block_structure_rp)``.

    Raises
    ------
    PolyrobError
        Size mismatch, discrete-time ``K`` or an ill-posed loop.

    Examples
    --------
    >>> import control, numpy as np
    >>> from polyrob.plant.generalized import lft
    >>> P = control.ss([[0.0]], [[1.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])
    >>> N = lft(P, -2.0, n_u=1, n_y=1)   # x' = w + u, u = -2 x
    >>> N.A
    array([[-2.]])
    """
    if isinstance(P, GeneralizedPlant):
        n_u, n_y, sys = P.n_u, P.n_y, P.system
    elif isinstance(P, control.StateSpace):
        if n_u is None or n_y is None:
            raise PolyrobError("lft of a bare StateSpace needs n_u and n_y")
        sys = P
        if not (0 < n_u <= sys.ninputs and 0 < n_y <= sys.noutputs):
            raise PolyrobError(f"n_u={n_u}, n_y={n_y} do not fit a {sys.noutputs}x{sys.ninputs} plant")
    else:
        raise PolyrobError(f"lft needs a GeneralizedPlant or a StateSpace, got {type(P).__name__}")
    return _lower_lft(sys, _controller(K, n_u, n_y), n_u, n_y)


# --------------------------------------------------------------------------- loop functions


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """Loop functions of ``u = K (r - y)`` around one plant.

    Attributes
    ----------
    S, T, KS : control.StateSpace
        ``S = (I + G K)^{-1}`` (``r -> e``), ``T = G K (I + G K)^{-1}``
        (``r -> y``), ``K S`` (``r -> u``); each carries every closed-loop state.
    system : control.StateSpace
        ``r -> [e; y; u]``.
    poles : ndarray
        Closed-loop poles.
    stable : bool
        All poles in the open left half-plane.
    delta : ndarray or None
        The ``δ`` of the plant (``None`` for the nominal or a given plant).
    """

    S: control.StateSpace
    T: control.StateSpace
    KS: control.StateSpace
    system: control.StateSpace
    poles: np.ndarray
    stable: bool
    delta: np.ndarray | None = None


def loop_functions(G: control.StateSpace, K, *, delta=None) -> ClosedLoop:
    """``S``, ``T``, ``KS`` of the unity negative-feedback loop ``u = K (r - y)``.

    Examples
    --------
    >>> import control
    >>> from polyrob.plant.generalized import loop_functions
    >>> cl = loop_functions(control.ss(control.tf([1], [1, 0])), 2.0)   # G = 1/s, K = 2
    >>> abs(complex(cl.S(0))), round(abs(complex(cl.T(0))), 12), cl.stable   # S(0) = 0, T(0) = 1
    (0.0, 1.0, True)
    """
    G = _as_ss(G, "G")
    p, m = G.noutputs, G.ninputs
    Ks = _controller(K, m, p)
    A, B, C, D = _mats(G)
    n = A.shape[0]
    # loop plant: inputs [r, u], outputs [e, y, u, e_meas]
    Bl = np.hstack([np.zeros((n, p)), B])
    Cl = np.vstack([-C, C, np.zeros((m, n)), -C])
    Dl = np.block([
        [np.eye(p), -D],
        [np.zeros((p, p)), D],
        [np.zeros((m, p)), np.eye(m)],
        [np.eye(p), -D],
    ])
    L = control.ss(
        A, Bl, Cl, Dl,
        inputs=[f"r[{i}]" for i in range(p)] + [f"u[{i}]" for i in range(m)],
        outputs=[f"e[{i}]" for i in range(p)] + [f"y[{i}]" for i in range(p)] + [f"u[{i}]" for i in range(m)]
        + [f"em[{i}]" for i in range(p)],
        states=list(G.state_labels), dt=0,
    )
    cl = _lower_lft(L, Ks, m, p)
    poles = np.linalg.eigvals(np.asarray(cl.A)) if cl.nstates else np.zeros(0)
    stable = bool(np.all(poles.real < 0))
    return ClosedLoop(
        S=cl[:p, :], T=cl[p : 2 * p, :], KS=cl[2 * p :, :], system=cl, poles=poles, stable=stable,
        delta=None if delta is None else np.asarray(delta, float),
    )


def closed_loop(unc: UncertainPlant, K, delta, *, strict: bool = True) -> ClosedLoop:
    """Loop functions around ``G(δ)`` (for Monte Carlo over ``usample``/corners).

    Examples
    --------
    >>> import numpy as np, polyrob
    >>> from polyrob.plant.uncertainty import uncertain_plant
    >>> from polyrob.plant.generalized import closed_loop, paper_controller
    >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    >>> cl = closed_loop(uncertain_plant(pldi), paper_controller(), np.zeros(10))
    >>> cl.S.ninputs, cl.T.noutputs, cl.system.nstates
    (2, 2, 16)
    """
    return loop_functions(unc.plant_at(delta, strict=strict), K, delta=delta)


def nominal_closed_loop(unc: UncertainPlant, K) -> ClosedLoop:
    """Loop functions around the nominal ``G_n`` (:meth:`UncertainPlant.nominal_system`)."""
    return loop_functions(unc.nominal_system(), K)


# Public names for the synthesis stage (the private spellings above are kept
# until every caller has moved over).
lower_lft_matrices = _lft_mats
as_controller_ss = _controller
