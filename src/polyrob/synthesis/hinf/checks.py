"""Checks before an H∞ synthesis: PBH stabilisability/detectability, and state balancing.

:func:`check_stabilizable` names the mode (and the states it lives on) that
no controller can move or see; :func:`balance_state` is the diagonal state
scaling (SLICOT TB01ID) both the check and the synthesis plant use.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from polyrob.errors import SynthesisError

__all__ = ["check_stabilizable", "balance_state", "describe_mode", "format_complex"]


def describe_mode(vec: np.ndarray, labels) -> str:
    w = np.abs(vec)
    if w.max() == 0:
        return ""
    idx = [int(i) for i in np.argsort(-w)[:3] if w[i] >= 0.1 * w.max()]
    names = [labels[i] if labels is not None and i < len(labels) else f"x[{i}]" for i in idx]
    return ", ".join(names)


def check_stabilizable(A, B2, C2, state_labels=None, *, tol: float = 1e-8) -> None:
    """PBH tests: raise :class:`SynthesisError` if ``(A, B2)`` is not stabilisable
    or ``(A, C2)`` not detectable, naming the offending mode.

    A mode ``λ`` with ``Re λ >= 0`` is uncontrollable iff its left
    eigenvector ``w`` satisfies ``w^H B2 = 0`` (Popov-Belevitch-Hautus).  The
    test is made on a diagonally balanced copy of ``A`` and needs both the
    eigenvector projection and the smallest singular value of
    ``[A - λI, B2]`` to vanish: D-scaled plants mix modes at 1e-5 and 1e3
    rad/s, and a singular-value test alone, relative to ``||A||``, mistakes
    slow but controllable modes for uncontrollable ones.

    Examples
    --------
    >>> import numpy as np
    >>> from polyrob.synthesis.hinf.checks import check_stabilizable
    >>> A = np.diag([1.0, -1.0]); B2 = np.array([[0.0], [1.0]]); C2 = np.array([[1.0, 1.0]])
    >>> check_stabilizable(A, B2, C2, ["unstable", "stable"])
    Traceback (most recent call last):
    ...
    polyrob.errors.SynthesisError: (A, B2) is not stabilisable: the mode at s = 1 (on states unstable) cannot be moved by the control inputs u ...
    """
    A = np.asarray(A, float)
    n = A.shape[0]
    if n == 0:
        return
    B2 = np.asarray(B2, float).reshape(n, -1)
    C2 = np.asarray(C2, float).reshape(-1, n)
    # diagonal balancing (powers of two, exact): entries of comparable size
    Ab, t, _ = balance_state(A, B2, C2)
    Bb, Cb = t[:, None] * B2, C2 / t[None, :]
    lam, Wl, Vr = sla.eig(Ab, left=True, right=True)
    scale = max(1.0, np.linalg.norm(Ab, 2))
    nB, nC = max(np.linalg.norm(Bb, 2), 1e-300), max(np.linalg.norm(Cb, 2), 1e-300)
    for k, mu in enumerate(lam):
        if mu.real < -1e-8 * max(1.0, abs(mu)):
            continue
        w, v = Wl[:, k], Vr[:, k]
        proj_b = np.linalg.norm(w.conj() @ Bb) / (np.linalg.norm(w) * nB)
        if proj_b <= tol:
            s = np.linalg.svd(np.hstack([Ab - mu * np.eye(n), Bb]), compute_uv=False)
            if s[-1] <= 1e3 * tol * scale:
                where = describe_mode(w / t, state_labels)
                raise SynthesisError(
                    f"(A, B2) is not stabilisable: the mode at s = {format_complex(mu)} (on states {where}) "
                    "cannot be moved by the control inputs u (PBH test); no controller can stabilise this "
                    "plant - check the actuated joints and that the weights are stable"
                )
        proj_c = np.linalg.norm(Cb @ v) / (np.linalg.norm(v) * nC)
        if proj_c <= tol:
            s = np.linalg.svd(np.vstack([Ab - mu * np.eye(n), Cb]), compute_uv=False)
            if s[-1] <= 1e3 * tol * scale:
                where = describe_mode(v * t, state_labels)
                raise SynthesisError(
                    f"(A, C2) is not detectable: the mode at s = {format_complex(mu)} (on states {where}) "
                    "is not seen by the measurements y (PBH test); no controller can stabilise this plant"
                )


def balance_state(A, B, C):
    """Diagonal state scaling balancing ``[A B; C 0]`` (SLICOT TB01ID).

    Returns ``(T A T^-1, t, scaled)`` with ``T = diag(t)`` (``x_s = T x``);
    ``scaled`` is ``False`` when nothing was balanced (no states, inputs or
    outputs).  D-scaled plants mix modes at 1e-5 and 1e3 rad/s: without it
    their entries span ten decades.
    """
    import slycot

    A = np.asarray(A, float)
    n = A.shape[0]
    B = np.asarray(B, float).reshape(n, -1)
    C = np.asarray(C, float).reshape(-1, n)
    if n == 0 or B.shape[1] == 0 or C.shape[0] == 0:
        return A.copy(), np.ones(n), False
    _, As, _, _, scale = slycot.tb01id(n, B.shape[1], C.shape[0], 0.0, A.copy(), B.copy(), C.copy(), job="A")
    # TB01ID: A_s = S^-1 A S, B_s = S^-1 B, C_s = C S, i.e. x_s = S^-1 x
    return np.asarray(As, float), 1.0 / np.asarray(scale, float), True


def format_complex(x) -> str:
    x = complex(x)
    return f"{x.real:.4g}" if abs(x.imag) < 1e-12 else f"{x:.4g}"
