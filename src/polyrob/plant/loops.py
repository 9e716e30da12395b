"""Closing loops: the lower LFT ``Fl(P, K)`` and the loop functions ``S``, ``T``, ``KS``.

Of systems, the lower LFT is python-control's ``StateSpace.lft`` (states
``[P's, K's]``), called by :func:`lower_lft` with polyrob's well-posedness
threshold and the plant's signal names; :func:`lft` (a generalized plant or
a bare plant, any controller), the loop functions and
:func:`polyrob.validate.discretize.discrete_lft` all go through it.

:func:`lower_lft_matrices` is the same realisation for raw double matrices:
the synthesis closes the loop there thousands of times (every step of a γ
bisection, of a D-K iteration, of the fixed-structure optimiser), where
wrapping the matrices into two ``StateSpace`` objects and a rank test would
cost 3-4 times as much (measured: 1.9 ms against 0.5 ms at 30 + 12 states).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import control
import numpy as np

from polyrob.analysis.stability import stability_verdict
from polyrob.controller import as_controller_ss
from polyrob.errors import ArgumentError
from polyrob.plant.realize import as_state_space, ss_matrices

if TYPE_CHECKING:
    from polyrob.plant.lftplant import UncertainPlant

__all__ = [
    "lower_lft_matrices",
    "lower_lft",
    "lft",
    "ClosedLoop",
    "loop_functions",
    "closed_loop",
    "nominal_closed_loop",
]

#: ``I - D_yu D_K`` beyond this condition number is an ill-posed loop.
ILL_POSED_CONDITION = 1e12


# --------------------------------------------------------------------------- lower LFT


def _well_posed(D22, Dk, n_y):
    """``I - D22 Dk``; raises ``np.linalg.LinAlgError`` when the loop is ill posed."""
    R = np.eye(n_y) - D22 @ Dk
    if np.linalg.cond(R) > ILL_POSED_CONDITION:
        raise np.linalg.LinAlgError("I - D22 Dk is singular")
    return R


def lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y):
    """Matrices of ``Fl(P, K)`` (states ``[P's, K's]``); raises ``np.linalg.LinAlgError`` if ill posed.

    The raw-matrix form of :func:`lower_lft` for the synthesis' inner loops
    (see the module's note on why it is not python-control's there).
    """
    nw, nz = B.shape[1] - n_u, C.shape[0] - n_y
    B1, B2 = B[:, :nw], B[:, nw:]
    C1, C2 = C[:nz], C[nz:]
    D11, D12, D21, D22 = D[:nz, :nw], D[:nz, nw:], D[nz:, :nw], D[nz:, nw:]
    R = _well_posed(D22, Dk, n_y)
    Yx, Yw, Yk = (np.linalg.solve(R, X) for X in (C2, D21, D22 @ Ck))
    Ux, Uw, Uk = Dk @ Yx, Dk @ Yw, Ck + Dk @ Yk
    Acl = np.block([[A + B2 @ Ux, B2 @ Uk], [Bk @ Yx, Ak + Bk @ Yk]])
    Bcl = np.vstack([B1 + B2 @ Uw, Bk @ Yw])
    Ccl = np.hstack([C1 + D12 @ Ux, D12 @ Uk])
    Dcl = D11 + D12 @ Uw
    return Acl, Bcl, Ccl, Dcl


def lower_lft(P: control.StateSpace, K: control.StateSpace, n_u: int, n_y: int) -> control.StateSpace:
    """``Fl(P, K)`` closing the last ``n_u`` inputs with ``u = K y`` on the last ``n_y`` outputs.

    python-control's ``StateSpace.lft`` (states ``[P's, K's]``, the time base
    of ``P``), refused as ill posed when ``cond(I - D_yu D_K) > 1e12``; the
    closed loop keeps ``P``'s signal and state names.
    """
    nw, nz = P.ninputs - n_u, P.noutputs - n_y
    try:
        _well_posed(np.asarray(P.D, float)[nz:, nw:], np.asarray(K.D, float), n_y)
    except np.linalg.LinAlgError:
        raise ArgumentError("the lower LFT is ill posed: I - D_yu D_K is singular") from None
    if K.dt != P.dt:  # the caller has checked the sample times agree (to rounding)
        K = control.ss(K.A, K.B, K.C, K.D, dt=P.dt)
    try:
        N = P.lft(K, nu=n_u, ny=n_y)
        mats = (N.A, N.B, N.C, N.D)
    except ValueError:
        # python-control tests the rank of [[I, -D22], [-D_K, I]], whose tolerance grows with
        # |D_K|: a fixed-structure controller with a large feedthrough fails it although
        # I - D22 D_K (the matrix the loop equations solve, checked above) is well conditioned
        mats = lower_lft_matrices(*(np.asarray(X, float) for X in (P.A, P.B, P.C, P.D, K.A, K.B, K.C, K.D)), n_u, n_y)
    states = list(P.state_labels) + [f"xK[{i}]" for i in range(K.nstates)]
    return control.ss(
        *mats,
        inputs=P.input_labels[:nw],
        outputs=P.output_labels[:nz],
        states=states,
        dt=P.dt,
    )


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
    if hasattr(P, "system") and hasattr(P, "n_u") and hasattr(P, "n_y"):  # a GeneralizedPlant
        n_u, n_y, sys = P.n_u, P.n_y, P.system
    elif isinstance(P, control.StateSpace):
        if n_u is None or n_y is None:
            raise ArgumentError("lft of a bare StateSpace needs n_u and n_y")
        sys = P
        if not (0 < n_u <= sys.ninputs and 0 < n_y <= sys.noutputs):
            raise ArgumentError(f"n_u={n_u}, n_y={n_y} do not fit a {sys.noutputs}x{sys.ninputs} plant")
    else:
        raise ArgumentError(f"lft needs a GeneralizedPlant or a StateSpace, got {type(P).__name__}")
    return lower_lft(sys, as_controller_ss(K, n_u, n_y), n_u, n_y)


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
        Proved stable by :func:`~polyrob.analysis.stability.stability_verdict`
        (all poles in the open left half-plane, beyond their error bound).
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
    G = as_state_space(G, "G")
    p, m = G.noutputs, G.ninputs
    Ks = as_controller_ss(K, m, p)
    A, B, C, D = ss_matrices(G)
    n = A.shape[0]
    # loop plant: inputs [r, u], outputs [e, y, u, e_meas]
    Bl = np.hstack([np.zeros((n, p)), B])
    Cl = np.vstack([-C, C, np.zeros((m, n)), -C])
    Dl = np.block(
        [
            [np.eye(p), -D],
            [np.zeros((p, p)), D],
            [np.zeros((m, p)), np.eye(m)],
            [np.eye(p), -D],
        ]
    )
    L = control.ss(
        A,
        Bl,
        Cl,
        Dl,
        inputs=[f"r[{i}]" for i in range(p)] + [f"u[{i}]" for i in range(m)],
        outputs=[f"e[{i}]" for i in range(p)]
        + [f"y[{i}]" for i in range(p)]
        + [f"u[{i}]" for i in range(m)]
        + [f"em[{i}]" for i in range(p)],
        states=list(G.state_labels),
        dt=0,
    )
    cl = lower_lft(L, Ks, m, p)
    poles = np.linalg.eigvals(np.asarray(cl.A)) if cl.nstates else np.zeros(0)
    stable = stability_verdict(cl).stable
    return ClosedLoop(
        S=cl[:p, :],
        T=cl[p : 2 * p, :],
        KS=cl[2 * p :, :],
        system=cl,
        poles=poles,
        stable=stable,
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
    >>> cl = closed_loop(uncertain_plant(pldi, model="box"), paper_controller(), np.zeros(10))
    >>> cl.S.ninputs, cl.T.noutputs, cl.system.nstates
    (2, 2, 16)
    """
    return loop_functions(unc.plant_at(delta, strict=strict), K, delta=delta)


def nominal_closed_loop(unc: UncertainPlant, K) -> ClosedLoop:
    """Loop functions around the nominal ``G_n`` (:meth:`UncertainPlant.nominal_system`)."""
    return loop_functions(unc.nominal_system(), K)
