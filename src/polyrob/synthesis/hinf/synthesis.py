"""H∞ output-feedback synthesis that does not give up on robot plants.

:func:`hinfsyn` computes a (sub)optimal H∞ controller ``K`` for a generalized
plant ``P`` partitioned as ``[z; y] = P [w; u]`` (controls last among the
inputs, measurements last among the outputs), like MATLAB's ``hinfsyn``.

Why not ``control.hinfsyn``: it wraps SLICOT SB10AD, needs ``D12`` of full
column rank, ``D21`` of full row rank and no rank loss of the Rosenbrock
pencils on the imaginary axis, and exposes neither its starting γ nor its
tolerance.  The mixed-sensitivity plant of a robot violates these
conditions (strictly proper double integrators: ``D12 = 0``, poles at
``s = 0``), and with dynamic D-scales its data spans ten decades.  Here:

1. **Checks first** (PBH): a mode of ``A`` with ``Re λ >= 0`` that ``u``
   cannot move or ``y`` cannot see raises :class:`~polyrob.errors.SynthesisError`
   naming the mode and the states it lives on.
2. **Scaling**: a diagonal state similarity (Osborne balancing of
   ``[A B; C 0]``) and unit-norm control/measurement channels.  Neither
   changes the problem.
3. **Documented regularisation**, each step recorded in
   :attr:`HinfResult.regularization`: a control penalty ``z_reg = ε u`` when
   ``D12`` lacks full column rank, measurement noise ``ε w_n`` when ``D21``
   lacks full row rank, and, only if SLICOT still reports a rank loss on the
   imaginary axis (poles of double integrators at ``s = 0``), a shift of the
   *axis*: synthesis for ``P(s - ε)`` (``A + εI``) and ``K(s) = K_ε(s + ε)``,
   which guarantees closed-loop poles left of ``-ε`` and
   ``‖Fl(P, K)‖∞ <= γ`` (moving only the offending poles to ``-ε`` gives no
   such guarantee: the central controller cancels them).  γ then depends on
   ε: the reported :attr:`HinfResult.gamma` is always an upper bound of the
   H∞ norm of the closed loop with the *user's* plant
   (:func:`~polyrob.analysis.norms.hinf_norm`: AB13DD confirmed by a
   Hamiltonian test, never a grid value).  When a controller does not
   verify (see 4), ε is raised tenfold (twice at most) and the failed
   attempts are listed in :attr:`HinfResult.fallbacks`.
4. **Own γ bisection** around SLICOT SB10FD (central controller at a given
   γ) with an explicit closed-loop eigenvalue check at every step, then a
   check of the returned controller by the Hamiltonian test
   ``‖Fl(P_s, K)‖∞ < γ (1 + 1%)`` (:mod:`polyrob.synthesis.hinf.riccati`):
   near the optimal γ the Riccati equations are ill conditioned and SB10FD
   can return a stabilising controller that misses γ by orders of
   magnitude; γ is then backed off (1%, 3%, 10%, 30%, 100%) until the
   controller verifies.
5. **LMI fallback** (``method="lmi"``, or automatic when the Riccati route
   fails): the full-order LMI of Gahinet & Apkarian (1994) in the
   linearising change of variables of Scherer, Gahinet & Chilali (1997),
   solved with cvxpy, then the controller reconstructed from ``X, Y``.

References
----------
* K. Glover, J. C. Doyle, "State-space formulae for all stabilizing
  controllers that satisfy an H∞ norm bound", Syst. Control Lett. 11, 1988.
* P. Gahinet, P. Apkarian, "A linear matrix inequality approach to H∞
  control", Int. J. Robust Nonlinear Control 4, 1994.
* C. Scherer, P. Gahinet, M. Chilali, "Multiobjective output-feedback
  control via LMI optimization", IEEE TAC 42(7), 1997.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import control
import numpy as np

from polyrob._threads import single_blas_thread
from polyrob.analysis.norms import hinf_norm, hinf_norm_estimate, state_matrices
from polyrob.analysis.stability import stability_screen
from polyrob.errors import ArgumentError, SynthesisError
from polyrob.plant.generalized import lower_lft_matrices
from polyrob.synthesis.hinf.checks import check_stabilizable
from polyrob.synthesis.hinf.lmi import lmi_controller
from polyrob.synthesis.hinf.problem import SynthesisProblem
from polyrob.synthesis.hinf.riccati import riccati_controller

__all__ = ["HinfResult", "hinfsyn", "hinf_norm", "hinf_norm_estimate", "check_stabilizable"]

Method = Literal["auto", "riccati", "lmi"]


# ===================================================================== result
@dataclass(frozen=True, eq=False)
class HinfResult:
    """An H∞ controller and what it took to compute it.

    Attributes
    ----------
    K : control.StateSpace
        Controller ``u = K y`` (``n_u x n_y``), as many states as the plant.
    gamma : float
        H∞ norm of ``Fl(P, K)`` for the plant that was passed in (no
        regularisation, no shift): the number to quote.
    gamma_bound : float
        The level γ at which the controller formulas were solved, for the
        (scaled, regularised) synthesis plant.
    closed_loop : control.StateSpace
        ``Fl(P, K)``: ``w -> z``.
    method : str
        ``"riccati"`` (SB10FD with γ bisection) or ``"lmi"``.
    regularization : tuple of str
        Every modification of the problem, in words (empty if none).
    fallbacks : tuple of str
        Every attempt that failed before this controller was found (a
        Riccati route that did not verify, a larger ε, the LMI route taken
        instead, a skipped LMI conditioning pass), in words.
    info : dict
        ``gamma_lower`` (largest γ found infeasible), ``calls``, ``epsilon``,
        ``shift``, solver notes.
    """

    K: control.StateSpace
    gamma: float
    gamma_bound: float
    closed_loop: control.StateSpace
    method: str
    regularization: tuple = ()
    info: dict = field(default_factory=dict)
    fallbacks: tuple = ()


def _ss(A, B, C, D) -> control.StateSpace:
    A, B, C, D = (np.atleast_2d(np.asarray(X, float)) for X in (A, B, C, D))
    n = A.shape[0] if A.size else 0
    if n == 0:
        A = np.zeros((0, 0))
        B = np.zeros((0, D.shape[1]))
        C = np.zeros((D.shape[0], 0))
    return control.ss(A, B, C, D, dt=0)


# ===================================================================== hinfsyn
def _parse_plant(P, n_y, n_u):
    from polyrob.plant.generalized import GeneralizedPlant

    labels = None
    if isinstance(P, GeneralizedPlant):
        n_y = P.n_y if n_y is None else n_y
        n_u = P.n_u if n_u is None else n_u
        labels = list(P.system.state_labels)
        P = P.system
    if not isinstance(P, control.StateSpace):
        if isinstance(P, control.LTI):
            P = control.ss(P)
        else:
            raise ArgumentError(f"hinfsyn needs a StateSpace or GeneralizedPlant, got {type(P).__name__}")
    if P.dt not in (0, None):
        raise ArgumentError("hinfsyn: the plant must be continuous-time")
    if n_y is None or n_u is None:
        raise ArgumentError("hinfsyn of a bare StateSpace needs n_y and n_u")
    n_y, n_u = int(n_y), int(n_u)
    if not (0 < n_u < P.ninputs and 0 < n_y < P.noutputs):
        raise ArgumentError(f"n_u={n_u}, n_y={n_y} do not fit a {P.noutputs}x{P.ninputs} plant (need exogenous w and z)")
    if labels is None:
        labels = list(getattr(P, "state_labels", None) or []) or None
    A, B, C, D = state_matrices(P)
    if not all(np.all(np.isfinite(X)) for X in (A, B, C, D)):
        raise ArgumentError("hinfsyn: the plant has NaN or Inf entries")
    return A, B, C, D, n_y, n_u, labels


def hinfsyn(
    P,
    n_y: int | None = None,
    n_u: int | None = None,
    *,
    gamma_range: tuple[float, float] | None = None,
    tol: float = 1e-3,
    method: Method = "auto",
    epsilon: float = 1e-4,
    rank_tol: float = 1e-7,
    shifts: tuple[float, ...] = (1e-3, 1e-2, 1e-1),
    solver: str | None = None,
    lmi_max_states: int = 40,
) -> HinfResult:
    """H∞ (sub)optimal output-feedback controller with explicit regularisation.

    Parameters
    ----------
    P : control.StateSpace or GeneralizedPlant
        Inputs ``[w; u]``, outputs ``[z; y]`` (controls/measurements last).
    n_y, n_u : int
        Number of measurements and controls (taken from a
        :class:`~polyrob.plant.GeneralizedPlant` when omitted).
    gamma_range : (float, float), optional
        Bracket ``(γ_min, γ_max)`` for the bisection; default: found
        automatically by decades from γ = 1.
    tol : float
        Relative tolerance of the γ bisection.
    method : {"auto", "riccati", "lmi"}
        ``"riccati"``: SB10FD + bisection; ``"lmi"``: cvxpy LMI; ``"auto"``:
        Riccati, then LMI if it fails.
    epsilon : float
        ε of the control penalty / measurement noise regularisation, in the
        scaled units (unit-norm control columns and measurement rows).
    rank_tol : float
        Relative smallest singular value of ``D12``/``D21`` below which they
        are regularised.
    shifts : tuple of float
        Axis shifts tried, in turn, when SLICOT reports a rank loss on the
        imaginary axis, as fractions of the slowest stable mode of ``A``
        (see :meth:`SynthesisProblem.shift_axis`).
    solver : str, optional
        cvxpy solver for the LMI route (default CLARABEL).
    lmi_max_states : int
        ``method="auto"`` falls back on the LMI only up to this many plant
        states (its memory grows like ``n^4``: a 150-state D-scaled plant
        exhausted the memory of a 2-core machine).

    Returns
    -------
    HinfResult

    Raises
    ------
    SynthesisError
        Unstabilisable/undetectable plant (the mode is named), or no
        stabilising controller found by either route.
    PolyrobError
        Bad sizes or inputs.

    Examples
    --------
    A double integrator ``1/s^2`` with a strictly proper mixed-sensitivity
    plant (``D12 = 0``, poles at ``s = 0``), on which ``control.hinfsyn`` fails:

    >>> import control, numpy as np
    >>> from polyrob.synthesis.hinf.synthesis import hinfsyn
    >>> G = control.ss(control.tf([1], [1, 0, 0]))
    >>> WS = control.ss(control.tf([0.5, 0.5], [1, 0.005]))
    >>> P = control.augw(G, w1=WS)                 # z = W_S e, y = e = r - G u
    >>> res = hinfsyn(P, 1, 1)
    >>> res.method, bool(np.all(np.linalg.eigvals(res.closed_loop.A).real < 0))
    ('riccati', True)
    >>> res.regularization[0][:30]
    'D12 lacks full column rank (si'
    """
    A, B, C, D, n_y, n_u, labels = _parse_plant(P, n_y, n_u)
    if method not in ("auto", "riccati", "lmi"):
        raise ArgumentError(f"method must be 'auto', 'riccati' or 'lmi', got {method!r}")
    if not (0 < tol < 1):
        raise ArgumentError(f"tol must be in (0, 1), got {tol!r}")
    nw, nz = B.shape[1] - n_u, C.shape[0] - n_y
    check_stabilizable(A, B[:, nw:], C[nz:], labels)
    with single_blas_thread():
        return _hinfsyn(
            A, B, C, D, n_y, n_u, gamma_range, tol, method, epsilon, rank_tol, shifts, solver, lmi_max_states
        )


def _hinfsyn(A, B, C, D, n_y, n_u, gamma_range, tol, method, epsilon, rank_tol, shifts, solver, lmi_max_states=40):
    def fresh(eps):
        pr = SynthesisProblem(A, B, C, D, n_u, n_y)
        pr.balance()
        pr.scale_io()
        pr.regularize_d12(eps, rank_tol)
        pr.regularize_d21(eps, rank_tol)
        return pr

    def finish(prob, mats, meth, extra):
        Ak, Bk, Ck, Dk = prob.controller_to_user(*mats)
        try:
            Acl, Bcl, Ccl, Dcl = lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, n_u, n_y)
        except np.linalg.LinAlgError:
            return None
        if not stability_screen(Acl):
            return None
        K = _ss(Ak, Bk, Ck, Dk)
        cl = _ss(Acl, Bcl, Ccl, Dcl)
        info = dict(prob.info)
        info.update(extra)
        info["state_scaling_range"] = float(prob.T.max() / prob.T.min()) if prob.T.size else 1.0
        return HinfResult(
            K=K,
            gamma=hinf_norm(cl),
            gamma_bound=float(extra.get("gamma", np.nan)),
            closed_loop=cl,
            method=meth,
            regularization=tuple(prob.notes),
            info=info,
            fallbacks=tuple(failures) + tuple(extra.get("fallbacks", ())),
        )

    codes = {
        1: "rank loss of [A-jwI B2; C1 D12] on the jw axis",
        2: "rank loss of [A-jwI B1; C2 D21] on the jw axis",
        3: "D12 rank deficient",
        4: "D21 rank deficient",
        5: "SVD failure",
        6: "no admissible gamma",
        7: "X-Riccati failed",
        8: "Y-Riccati failed",
        9: "ill-posed loop",
        10: "controller numerically inaccurate",
    }
    failures = []
    if method in ("auto", "riccati"):
        # a larger regularisation eps is tried when the controller does not
        # verify: it conditions the Riccati equations better
        for eps in (epsilon, 10 * epsilon, 100 * epsilon):
            prob = fresh(eps)
            mats, info = riccati_controller(prob, gamma_range, tol)
            if mats is None and info.get("rank_fail"):
                # rank loss on the imaginary axis: move the axis (see SynthesisProblem.shift_axis),
                # by a fraction of the slowest stable mode so no stable mode crosses it
                lam = np.linalg.eigvals(A) if A.size else np.zeros(0)
                stable = -lam.real[lam.real < -1e-7 * np.maximum(1.0, np.abs(lam))]
                ref = float(stable.min()) if stable.size else 1.0
                for f in shifts:
                    prob = fresh(eps)
                    prob.shift_axis(f * ref)
                    mats, info = riccati_controller(prob, gamma_range, tol)
                    if mats is not None:
                        break
            if mats is not None:
                res = finish(prob, mats, "riccati", info)
                if res is not None:
                    return res
                failures.append("Riccati controller does not stabilise the original plant")
                break
            failures.append(f"Riccati (eps={eps:.0e}): " + codes.get(info.get("last_info", -1), "failed"))
            if info.get("last_info") != 10 or not prob.notes:
                break  # not a conditioning problem, or nothing was regularised
    n = A.shape[0]
    if method == "auto" and n > lmi_max_states:
        # the LMI has ~n^2 unknowns and a (2n + n_w + n_z)-square constraint:
        # beyond a few dozen states the interior-point solver runs out of memory
        failures.append(f"LMI fallback skipped ({n} states > lmi_max_states={lmi_max_states})")
    elif method in ("auto", "lmi"):
        prob = fresh(epsilon)
        try:
            mats, info = lmi_controller(prob, tol, solver)
        except SynthesisError as exc:
            failures.append(str(exc))
        else:
            res = finish(prob, mats, "lmi", info)
            if res is not None:
                return res
            failures.append("LMI controller does not stabilise the plant")
    raise SynthesisError("H∞ synthesis failed: " + "; ".join(failures))
