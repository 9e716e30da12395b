"""Integral action, and the tracking error Coulomb friction causes in a loop.

Coulomb friction is not in the robot's model: it is a torque ``|d_j| <= F_c,j``
(:func:`polyrob.plant.weights.coulomb_weight`) entering where the torque
enters, the generalized plant's input ``f`` with ``|f_i| <= 1``
(:func:`polyrob.plant.generalized.generalized_plant` ``W_f``).  What it does
to the tracking error ``e = r - q``:

* **a constant friction torque** (a joint held by static friction): the
  closed loop settles with ``e_ss = -(S G)(0) W_f f``.  A controller that
  integrates every error channel (:func:`integral_rank` ``= m``: at a
  steady state its integrator states stand still, ``W^T B_K e = 0`` with
  ``W`` the left null space of ``A_K``, so ``e = 0``) leaves **no**
  steady-state error on every plant whose loop is stable: on every member a
  certificate keeps stable, whatever the model error.  Without it the
  nominal loop's DC gain (exact linear algebra) gives the error per joint,
  ``sum_k |DC_ik|`` for the worst signs of the box ``|f| <= 1``;
* **a friction torque of any frequency** (the breakaway of a stick-slip
  cycle): ``||S G W_f||_inf`` of the nominal loop, proved from above by
  :func:`polyrob.analysis.norms.hinf_norm_upper`: the largest error
  amplitude per unit amplitude of ``f`` (exact for sinusoids).

The figures are of the nominal plant (``Delta = 0``) unless said otherwise;
the words every command prints are
:func:`polyrob.analysis.certificate.friction_sentence`'s.

Examples
--------
>>> import control, numpy as np
>>> from polyrob.synthesis.pid_tuning import pid_controller
>>> G = control.ss([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]])  # a double integrator
>>> integral_rank(pid_controller(np.array([[100.0, 10.0, 20.0, 0.005]])))
1
>>> pd = control.ss([[-200.0]], [[1.0]], [[-20.0 * 200.0 ** 2]], [[100.0 + 20.0 * 200.0]])   # Kp + Kd s/(s/200 + 1)
>>> ch = coulomb_channel(G, pd, [2.0], source="stated")
>>> round(ch.steady_state[0], 6), ch.integral                    # Kp e = d: 2 / 100
(0.02, False)
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from polyrob.errors import ArgumentError

__all__ = ["integral_rank", "CoulombChannel", "coulomb_channel", "coulomb_levels"]


def integral_rank(K, *, rtol: float = 1e-12) -> int:
    """How many independent error directions the continuous controller ``K`` integrates exactly.

    ``rank(W^T B_K)`` with ``W`` the left null space of ``A_K`` (singular
    values below ``rtol * max(1, ||A_K||)``): ``m`` means every error channel
    is integrated, so a stable loop's steady state has ``e = 0``.  A static
    or discrete controller gives 0.
    """
    if not isinstance(K, control.StateSpace) or K.nstates == 0 or not K.isctime():
        return 0
    A, B = np.asarray(K.A, float), np.asarray(K.B, float)
    U, s, _ = np.linalg.svd(A.T)
    tol = rtol * max(1.0, float(s.max(initial=0.0)))
    W = U[:, s <= tol]  # columns w with w^T A = 0
    if W.shape[1] == 0:
        return 0
    return int(np.linalg.matrix_rank(W.T @ B, tol=1e-9 * max(1.0, float(np.abs(B).max()))))


@dataclass(frozen=True)
class CoulombChannel:
    """What Coulomb friction ``|d_j| <= F_c,j`` does to the tracking error of one loop (module text).

    Attributes
    ----------
    levels : tuple of float
        ``F_c`` per joint [N m].
    source : str
        Where the levels come from (the robot-uncertainty set, ``--coulomb``).
    weight : tuple of float
        ``W_f``'s diagonal [u's unit per unit ``f``].
    integral : bool
        The controller integrates every error channel (:func:`integral_rank`).
    stable : bool
        The nominal loop is stable (else no figure: ``nan``).
    steady_state : tuple of float
        Per joint, the largest ``|e_ss|`` [rad] a constant friction torque within the
        levels leaves on the nominal loop (0 with integral action, on every stable member).
    steady_state_per_nm : tuple of float
        The same per N m on every joint [rad per N m].
    peak : float
        ``||S G W_f||_inf`` of the nominal loop, proved from above [rad per unit ``f``].
    peak_per_nm : float
        The same with 1 N m on every joint [rad per N m].
    slowest_rate : float
        ``min |Re p|`` over the nominal loop's poles [1/s]: how fast the error a friction torque
        (or any constant offset) leaves decays at best; ``1 / slowest_rate`` is its time constant.
    approximation : str
        What the channel approximates (empty when exact).
    """

    levels: tuple
    source: str
    weight: tuple
    integral: bool
    stable: bool
    steady_state: tuple
    steady_state_per_nm: tuple
    peak: float
    peak_per_nm: float
    slowest_rate: float = float("nan")
    approximation: str = ""

    def to_dict(self) -> dict:
        def plain(v):
            if isinstance(v, tuple):
                return [plain(x) for x in v]
            return None if isinstance(v, float) and not np.isfinite(v) else v

        from polyrob.analysis.certificate import friction_sentence

        out = {k: plain(getattr(self, k)) for k in self.__dataclass_fields__}
        out["words"] = friction_sentence(self)
        return out


def _disturbance_loop(G, K, Wf) -> control.StateSpace:
    """``f -> e`` of ``u = K e``, ``e = -y``, ``y = G (u + W_f f)`` (the reference at rest)."""
    from polyrob.plant.loops import lower_lft
    from polyrob.plant.realize import ss_matrices

    A, B, C, D = ss_matrices(G)
    m = B.shape[1]
    D_e = np.hstack([-D @ Wf, -D])  # e = -y, read by the controller as it is
    L = control.ss(A, np.hstack([B @ Wf, B]), np.vstack([-C, -C]), np.vstack([D_e, D_e]))
    from polyrob.controller import as_controller_ss

    return lower_lft(L, as_controller_ss(K, m, m), m, m)


def _figures(G, K, Wf, integral: bool):
    from polyrob.analysis.norms import hinf_norm_upper
    from polyrob.analysis.stability import stability_verdict

    cl = _disturbance_loop(G, K, Wf)
    m = Wf.shape[0]
    stable = bool(stability_verdict(cl).stable)
    if not stable:
        return False, (float("nan"),) * m, float("nan"), float("nan")
    A, B, C, D = (np.asarray(X, float) for X in (cl.A, cl.B, cl.C, cl.D))
    dc = D - C @ np.linalg.solve(A, B) if A.size else D
    steady = (0.0,) * m if integral else tuple(float(v) for v in np.abs(dc).sum(axis=1))
    slowest = float(np.min(np.abs(np.linalg.eigvals(A).real))) if A.size else float("inf")
    return True, steady, float(hinf_norm_upper(cl)), slowest


def coulomb_channel(G, K, levels, *, source: str, inverse_inertia=None, model_error: float = 0.0) -> CoulombChannel:
    """The figures of :class:`CoulombChannel` for the continuous controller ``K`` around the plant ``G`` (``u -> q``).

    ``G``: the nominal plant (:meth:`~polyrob.plant.lftplant.UncertainPlant.nominal_system`);
    ``inverse_inertia`` and ``model_error`` as in :func:`polyrob.plant.weights.coulomb_weight`
    (given: ``u`` is the computed-torque layer's ``v``).
    """
    from polyrob.plant.weights import coulomb_weight

    G = control.ss(G)
    m = G.ninputs
    fc = np.asarray(levels, float).ravel()
    if fc.size == 1:
        fc = np.full(m, float(fc[0]))
    if fc.size != m:
        raise ArgumentError(f"--coulomb: give one level or one per joint ({m}), got {fc.size}")
    Wf = coulomb_weight(fc, inverse_inertia, model_error=model_error)
    W1 = coulomb_weight(np.ones(m), inverse_inertia, model_error=model_error)
    integral = integral_rank(K) == m
    stable, steady, peak, slowest = _figures(G, K, Wf, integral)
    _, steady1, peak1, _ = _figures(G, K, W1, integral)
    approx = ""
    if inverse_inertia is not None:
        approx = (
            "behind the computed-torque layer the torque d reaches the loop as M_hat^-1 d (first order in the "
            f"model error, times 1/(1 - {model_error:g})), M_hat^-1 bounded on sampled points of the domain"
        )
    return CoulombChannel(
        levels=tuple(float(v) for v in fc),
        source=source,
        weight=tuple(float(v) for v in np.diag(Wf)),
        integral=integral,
        stable=stable,
        steady_state=steady,
        steady_state_per_nm=steady1,
        peak=peak,
        peak_per_nm=peak1,
        slowest_rate=slowest,
        approximation=approx,
    )


def coulomb_levels(robot, given=None):
    """``(levels per joint, source)`` of the Coulomb friction to state, or ``(None, "")``.

    ``given`` (``--coulomb``: one value or one per joint) wins; otherwise the
    robot-uncertainty set's friction (its joints without friction at 0).
    """
    m = int(robot.m)
    if given is not None:
        g = np.asarray(given, float).ravel()
        g = np.full(m, float(g[0])) if g.size == 1 else g
        if g.size != m:
            raise ArgumentError(f"--coulomb: give one level or one per joint ({m}), got {g.size}")
        return g, "--coulomb"
    spec = getattr(robot, "uncertainty", None)
    friction = getattr(spec, "friction", ()) or ()
    if not any(getattr(f, "coulomb", 0.0) > 0 for f in friction):
        return None, ""
    names = list(getattr(robot, "joint_names", ()) or getattr(getattr(robot, "_base", None), "joint_names", ()))
    levels = np.zeros(m)
    for f in friction:
        if f.joint in names:
            levels[names.index(f.joint)] = f.coulomb
    return levels, "the robot-uncertainty set"
