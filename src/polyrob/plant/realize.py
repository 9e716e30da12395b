"""State-space realisations of weights and controllers, exact and entry by entry.

Used by the generalized plant (:mod:`polyrob.plant.generalized`) and the
loop functions (:mod:`polyrob.plant.loops`).
"""

from __future__ import annotations

import control
import numpy as np
import scipy.linalg as sla

from polyrob.errors import ArgumentError, PolyrobError

__all__ = ["is_static", "as_state_space", "weight_ss", "ss_matrices"]


def is_static(W) -> bool:
    return isinstance(W, (int, float, np.integer, np.floating)) or (isinstance(W, np.ndarray) and W.ndim <= 2)


def _siso_ss(num, den) -> control.StateSpace:
    num = np.trim_zeros(np.atleast_1d(np.asarray(num, dtype=float)), "f")
    den = np.trim_zeros(np.atleast_1d(np.asarray(den, dtype=float)), "f")
    if len(num) == 0:
        return control.ss([], [], [], [[0.0]], dt=0)
    if len(num) > len(den):
        raise ArgumentError("an improper transfer function has no state-space realisation")
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


def as_state_space(sys, what: str) -> control.StateSpace:
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
            raise ArgumentError(f"{what}: {exc}") from None
        A, B, C, D = _block_ss(entries, p, q)
        out = control.ss(A, B, C, D, dt=sys.dt)
    elif isinstance(sys, control.LTI):
        try:
            out = control.ss(sys)
        except (ValueError, TypeError, NotImplementedError, control.ControlMIMONotImplemented) as exc:
            raise ArgumentError(f"{what}: cannot convert {type(sys).__name__} to state space ({exc})") from None
    else:
        raise ArgumentError(f"{what} must be a python-control LTI system or a number, got {type(sys).__name__}")
    if out.dt not in (0, None):
        raise ArgumentError(f"{what} is discrete-time (dt={out.dt}); the plant is continuous-time")
    return out


def weight_ss(W, m: int, name: str) -> control.StateSpace | None:
    """An ``m x m`` weight from a SISO weight (one copy per channel), an ``m x m`` one or a gain."""
    if W is None:
        return None
    if is_static(W):
        G = np.asarray(W, dtype=float)
        if G.ndim == 0:
            G = float(G) * np.eye(m)
        if G.shape != (m, m):
            raise ArgumentError(f"{name} is a {G.shape} gain; expected a scalar or {m}x{m}")
        if not np.all(np.isfinite(G)):
            raise ArgumentError(f"{name} has non-finite entries")
        return control.ss(np.zeros((0, 0)), np.zeros((0, m)), np.zeros((m, 0)), G, dt=0)
    if not isinstance(W, control.LTI):
        raise ArgumentError(f"{name} must be a python-control LTI system, an array or a number, got {type(W).__name__}")
    p, q = W.noutputs, W.ninputs
    if (p, q) == (1, 1):
        # a SISO weight applies to every channel: m decoupled copies
        g = as_state_space(W, name)
        A = sla.block_diag(*([np.asarray(g.A)] * m)) if g.nstates else np.zeros((0, 0))
        B = sla.block_diag(*([np.asarray(g.B)] * m)) if g.nstates else np.zeros((0, m))
        C = sla.block_diag(*([np.asarray(g.C)] * m)) if g.nstates else np.zeros((m, 0))
        out = control.ss(A, B, C, float(np.asarray(g.D)[0, 0]) * np.eye(m), dt=0)
    elif (p, q) == (m, m):
        out = as_state_space(W, name)
    else:
        raise ArgumentError(
            f"{name} is {p}x{q}; expected SISO (applied to every channel) or {m}x{m} (the robot has m={m} joints)"
        )
    if out.nstates:
        poles = np.linalg.eigvals(np.asarray(out.A))
        if np.max(poles.real) >= 0:
            raise ArgumentError(
                f"{name} has a pole with Re >= 0 ({poles[np.argmax(poles.real)]:.4g}): weights sit outside the "
                "loop, so the generalized plant would not be stabilisable; use a stable weight (e.g. makeweight)"
            )
    return out


def ss_matrices(sys: control.StateSpace):
    return tuple(np.asarray(X, dtype=float) for X in (sys.A, sys.B, sys.C, sys.D))
