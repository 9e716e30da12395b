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
>>> P = generalized_plant(uncertain_plant(pldi, model="box"), W_S, W_T)
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
from dataclasses import dataclass, field, replace

import control
import numpy as np

from polyrob.controller import as_controller_ss  # noqa: F401 - its home is polyrob.controller
from polyrob.errors import ArgumentError
from polyrob.plant.lftplant import UncertainPlant, upper_lft
from polyrob.plant.loops import (  # noqa: F401  (re-exported: the pipeline imports them from here)
    ClosedLoop,
    closed_loop,
    lft,
    loop_functions,
    lower_lft_matrices,
    nominal_closed_loop,
)
from polyrob.plant.paper_controller import PAPER_CONTROLLER, paper_controller  # noqa: F401
from polyrob.plant.realize import ss_matrices, weight_ss  # noqa: F401

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
    "lower_lft_matrices",
    "as_controller_ss",
]


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
    unc: UncertainPlant, W_S=None, W_T=None, W_KS=None, *, W_n=None, W_f=None, regularize: float | None = None
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
    W_n : LTI system, array or number, optional
        Sensor-noise weight: a second exogenous input ``n`` (``m`` channels)
        enters the measurement, ``y_meas = r - (q + W_n n)``, so
        ``w = [r; n]`` and ``n_w = 2m`` (labels ``n[i]``).  ``W_S`` still
        weighs the true error ``r - q`` and ``W_T`` the true ``q``; the
        channel ``n -> z_KS`` is ``-W_KS K S W_n``: with ``W_KS = W_u`` the
        torque (or ``v``) the noise drives.  ``None`` (default): no noise
        input (the pipeline folds a constant ``W_n`` into ``W_KS`` instead,
        :func:`polyrob.plant.weights.limit_weight`).
    W_f : array or number, optional
        Coulomb-friction weight (``m x m`` or a scalar times the identity): a
        further exogenous input ``f`` (``|f_i| <= 1``, labels ``f[i]``, after
        ``r`` and ``n``) with the robot's input ``u + W_f f``; it reaches the
        robot's states and the uncertainty outputs as ``u`` does, not ``W_KS``
        (:func:`polyrob.plant.weights.coulomb_weight`, docs/synthesis.md).
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
    >>> P = generalized_plant(uncertain_plant(pldi, model="box"), control.tf([0.5, 0.5], [1, 0.005]), W_KS=1e-3)
    >>> P.z_labels, P.n_z, P.system.nstates
    (('W_S e', 'W_KS u'), 4, 6)
    >>> P.system.input_labels[10:]
    ['r[0]', 'r[1]', 'u[0]', 'u[1]']
    """
    if not isinstance(unc, UncertainPlant):
        raise ArgumentError(f"generalized_plant needs an UncertainPlant, got {type(unc).__name__}")
    m = unc.m
    WS, WT, WKS = weight_ss(W_S, m, "W_S"), weight_ss(W_T, m, "W_T"), weight_ss(W_KS, m, "W_KS")
    if regularize is not None:
        try:
            eps = float(regularize)
        except (TypeError, ValueError):
            raise ArgumentError(f"regularize must be a positive number, got {regularize!r}") from None
        if not (math.isfinite(eps) and eps > 0):
            raise ArgumentError(f"regularize must be a positive number, got {regularize!r}")
    else:
        eps = None
    if WS is None and WT is None and WKS is None and eps is None:
        raise ArgumentError("give at least one weight (W_S, W_T or W_KS): z would be empty")
    if W_f is not None:
        return _with_friction(generalized_plant(unc, W_S, W_T, W_KS, W_n=W_n, regularize=regularize), W_f)
    Wn = weight_ss(W_n, m, "W_n")
    if Wn is not None:
        return _with_noise(generalized_plant(unc, W_S, W_T, W_KS, regularize=regularize), Wn)

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
        Aw, Bw, Cw, Dw = ss_matrices(W)
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
        A,
        B,
        C,
        D,
        inputs=d_lab + [f"r[{i}]" for i in range(m)] + [f"u[{i}]" for i in range(m)],
        outputs=v_lab + z_names + [f"e[{i}]" for i in range(m)],
        states=x_lab + w_names,
        name="P",
        dt=0,
    )
    blk_rs = np.asarray(unc.block_structure, dtype=int).reshape(-1, 2)
    blk_rp = np.vstack([blk_rs, [[m, n_z]]]).astype(int)
    return GeneralizedPlant(
        system=system,
        uncertain=unc,
        W_S=WS,
        W_T=WT,
        W_KS=WKS,
        regularize=eps,
        n_delta=nd,
        n_w=m,
        n_z=n_z,
        n_u=m,
        n_y=m,
        z_labels=tuple(labels),
        block_structure_rs=blk_rs,
        block_structure_rp=blk_rp,
    )


def _with_noise(P: GeneralizedPlant, Wn: control.StateSpace) -> GeneralizedPlant:
    """``P`` with the sensor-noise input ``n``: ``w = [r; n]``, ``y_meas = r - q - W_n n``.

    Only the measurement row sees ``n``: the weights on the true error and
    position do not (they weigh what the robot does, not what it reads).
    """
    m, nd = P.n_u, P.n_delta
    A, B, C, D = ss_matrices(P.system)
    An, Bn, Cn, Dn = ss_matrices(Wn)
    N, k = A.shape[0], An.shape[0]
    rows_y = slice(C.shape[0] - m, C.shape[0])
    # inputs [d, r, n, u]; states [x_P, x_Wn]
    A2 = np.block([[A, np.zeros((N, k))], [np.zeros((k, N)), An]])
    B2 = np.zeros((N + k, B.shape[1] + m))
    B2[:N, : nd + m] = B[:, : nd + m]
    B2[:N, nd + 2 * m :] = B[:, nd + m :]
    B2[N:, nd + m : nd + 2 * m] = Bn
    C2 = np.hstack([C, np.zeros((C.shape[0], k))])
    C2[rows_y, N:] = -Cn
    D2 = np.zeros((D.shape[0], D.shape[1] + m))
    D2[:, : nd + m] = D[:, : nd + m]
    D2[:, nd + 2 * m :] = D[:, nd + m :]
    D2[rows_y, nd + m : nd + 2 * m] = -Dn
    ins = list(P.system.input_labels)
    inputs = ins[: nd + m] + [f"n[{i}]" for i in range(m)] + ins[nd + m :]
    states = list(P.system.state_labels) + [f"xn[{i}]" for i in range(k)]
    system = control.ss(
        A2, B2, C2, D2, inputs=inputs, outputs=list(P.system.output_labels), states=states, name="P", dt=0
    )
    blk_rp = P.block_structure_rp.copy()
    blk_rp[-1, 0] = 2 * m
    info = dict(P.info, W_n=Wn, w_labels=("r", "n"))
    return replace(P, system=system, n_w=2 * m, block_structure_rp=blk_rp, info=info)


def _with_friction(P: GeneralizedPlant, W_f) -> GeneralizedPlant:
    """``P`` with the Coulomb input ``f`` (before ``u``): the robot's input is ``u + W_f f``.

    Only the robot's state rows and the uncertainty outputs ``v`` (through
    ``D_vu``) see ``f``, exactly as they see ``u``; the weights on ``e`` and
    ``y`` see it through the robot, and ``W_KS`` (on the commanded ``u``) not at all.
    """
    m, nd, n = P.n_u, P.n_delta, P.uncertain.n_x
    Wf = np.asarray(W_f, float)
    Wf = Wf * np.eye(m) if Wf.ndim == 0 else Wf
    if Wf.shape != (m, m) or not np.all(np.isfinite(Wf)):
        raise ArgumentError(f"W_f must be a finite number or a {m}x{m} matrix, got shape {Wf.shape}")
    A, B, C, D = ss_matrices(P.system)
    u_cols = slice(B.shape[1] - m, B.shape[1])
    Bf = np.zeros((A.shape[0], m))
    Bf[:n] = B[:n, u_cols] @ Wf
    Df = np.zeros((D.shape[0], m))
    Df[:nd] = D[:nd, u_cols] @ Wf
    B2 = np.hstack([B[:, : u_cols.start], Bf, B[:, u_cols]])
    D2 = np.hstack([D[:, : u_cols.start], Df, D[:, u_cols]])
    ins = list(P.system.input_labels)
    inputs = ins[: u_cols.start] + [f"f[{i}]" for i in range(m)] + ins[u_cols.start :]
    system = control.ss(
        A,
        B2,
        C,
        D2,
        inputs=inputs,
        outputs=list(P.system.output_labels),
        states=list(P.system.state_labels),
        name="P",
        dt=0,
    )
    blk_rp = P.block_structure_rp.copy()
    blk_rp[-1, 0] = P.n_w + m
    info = dict(P.info, W_f=Wf, w_labels=tuple(P.info.get("w_labels", ("r",))) + ("f",))
    return replace(P, system=system, n_w=P.n_w + m, block_structure_rp=blk_rp, info=info)
