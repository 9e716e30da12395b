"""``inner-gain`` with reflected rotor inertia: computed torque on ``M = R + s L``, an exact LFT in one scalar.

With a computed-torque inner layer ``u = M_hat(q) v + h_hat(q, qdot)`` whose
model has the true rotor (armature) inertia ``R`` but link masses and
inertias ``L`` off by one factor (the true robot has ``M = R + s L`` and
``h = s h_L + D qdot``, the model ``M_hat = R + L``), the outer input ``v``
and the acceleration ``a`` of the true robot satisfy exactly::

    a = v + sigma (G(q) a + phi(q, qdot)),    sigma = 1 - s,
    G = M_hat^-1 L = I - M_hat^-1 R,          phi = M_hat^-1 h_L

so the inner loop's Jacobians are ``[A_low B_low] = (I - sigma G)^-1 [sigma
J, I]`` with ``J = d(G a + phi)/dx`` at the domain point.  Without armature
``G = I`` and this is the one-gain model of :mod:`~polyrob.plant.models.inner_gain`;
with it ``B_low`` is no multiple of ``I`` (talos' arm: ``G`` has
eigenvalues from about 0 on the wrist to 0.9 on the shoulder) and the loop
is the LFT::

    a = v + w,   w = sigma z,   z = K [x; v + w],   K = [J  G]

one real scalar ``sigma`` in ``[-p, p]`` repeated on ``m`` channels, with
``D_vd = p K_c``'s ``G`` part (``G`` is fed back through ``sigma``).  ``K``
moves over the domain: ``K = K_c + E`` with each entry of ``E`` within the
half-width of its range, carried by one full complex block (as ``axes``
carries its residual), placed inside the ``sigma`` loop.  Every true robot
is then a member exactly (``sigma`` its factor, ``E`` its ``K`` less the
centre).  ``K`` does not depend on ``s``: a task domain fixes ``a``, so the
ranges come from one true robot (``s = 1 - p``) as ``K = [B_low^-1 A_low,
I - B_low^-1] / p``, bounded by the PLDI's own search on that map
(:class:`FactorLoop`).  A torque box, where ``a`` depends on ``s``, is
refused.

Why by hand: MATLAB's ``uss`` would hold this LFT, but the factor ``K`` and
its ranges over a robot's task are polyrob's own.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
from scipy.optimize import minimize_scalar

from polyrob.errors import NotApplicable
from polyrob.model.inner import InnerLoopRobot
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models.axes import entry_layout, residual_block

__all__ = ["FactorLoop", "inner_armature_plant", "inner_armature_contains", "factor_range"]


@dataclass(frozen=True, eq=False)
class FactorLoop(InnerLoopRobot):
    """The inner loop of the true robot ``s = 1 - sigma``, whose Jacobians are reported as the factor ``K``.

    ``jacobians_batch`` returns ``A`` with lower rows ``J = B_low^-1 A_low /
    sigma`` and ``B`` with lower rows ``G = (I - B_low^-1) / sigma``, so
    that :func:`polyrob.bound_pldi` bounds ``K = [J G]`` with the search it
    uses for any Jacobian.
    """

    sigma: float = 0.1

    def jacobians_batch(self, q, qdot, v):
        A, B = super().jacobians_batch(q, qdot, v)
        m = self.m
        inverse = np.linalg.inv(B[:, m:])
        A[:, m:] = inverse @ A[:, m:] / self.sigma
        B[:, m:] = (np.eye(m) - inverse) / self.sigma
        return A, B


def factor_loop(robot) -> FactorLoop:
    """The :class:`FactorLoop` of a computed-torque loop: its true robot at ``s = 1 - p``."""
    true = robot.with_true(None, None, 1.0 - robot.model_error)
    values = {f.name: getattr(true, f.name) for f in fields(InnerLoopRobot) if f.init}
    return FactorLoop(**values, sigma=float(robot.model_error))


def factor_range(pldi, robot):
    """``(K_c, rho, lay)``: the centre (``m x 3m``), the half-widths of the varying entries and their layout.

    Bounded with the PLDI's sample count, one local search per direction and
    one verification round (the effort of
    :func:`polyrob.plant.models.inner_gain.jacobian_range`).
    """
    from polyrob.bounds.pldi import bound_pldi

    loop = factor_loop(robot)
    domain = replace(pldi.domain, robot=loop)
    samples = int((pldi.info or {}).get("samples", 256))
    one = bound_pldi(
        loop,
        domain,
        samples=samples,
        screen=0,
        starts_per_direction=1,
        verify_rounds=1,
        coverage=0,
        workers=1,
        progress=False,
    )
    m = pldi.m
    K = np.hstack([np.asarray(one.A0, float)[m:], np.asarray(one.B0, float)[m:]])
    lay = entry_layout(one)
    lo, hi = np.asarray(one.lower, float), np.asarray(one.upper, float)
    K[lay[:, 0], lay[:, 1]] = 0.5 * (lo + hi)
    return K, 0.5 * (hi - lo), lay


def inner_armature_plant(pldi, robot) -> UncertainPlant:
    """The exact LFT of the module text for a computed-torque loop with reflected rotor inertia.

    Raises
    ------
    NotApplicable
        Not a task domain (the accelerations must be the domain's, not the
        input's), or a true robot whose ``I - sigma G`` is singular.
    """
    from polyrob.domains.task import TaskDomain

    if not isinstance(pldi.domain, TaskDomain):
        raise NotApplicable(
            "inner-gain with reflected rotor inertia: needs a task domain (its accelerations fix G a), not a torque box"
        )
    m, p = pldi.m, float(robot.model_error)
    n = 2 * m
    K_c, rho, lay = factor_range(pldi, robot)
    if np.max(np.abs(np.linalg.eigvals(K_c[:, n:]))) * p >= 1.0:
        raise NotApplicable("inner-gain with reflected rotor inertia: I - sigma G is singular for some factor")
    Bf, Cf, gains = residual_block(lay, rho, m)
    k = 0 if Bf is None else Bf.shape[1]
    # channels: the residual block first, then sigma repeated m times (d_sigma = w enters the accelerations)
    B_d = np.zeros((n, k + m))
    B_d[m:, k:] = np.eye(m)
    C_v = np.zeros((k + m, n))
    D_vu = np.zeros((k + m, m))
    D_vd = np.zeros((k + m, k + m))
    C_v[k:], D_vu[k:], D_vd[k:, k:] = p * K_c[:, :n], p * K_c[:, n:], p * K_c[:, n:]
    if k:
        C_v[:k], D_vu[:k], D_vd[:k, k:] = Cf[:, :n], Cf[:, n:], Cf[:, n:]
        D_vd[k:, :k] = p * Bf
    blk = ([[k, k]] if k else []) + [[-m, 0]]
    A_mid = np.zeros((n, n))
    A_mid[:m, m:] = np.eye(m)
    B_mid = np.zeros((n, m))
    B_mid[m:] = np.eye(m)
    return UncertainPlant(
        robot_name=pldi.robot_name,
        nominal_kind="pldi",
        A_nom=np.asarray(pldi.A0, float),
        B_nom=np.asarray(pldi.B0, float),
        C=np.hstack([np.eye(m), np.zeros((m, m))]),
        A_mid=A_mid,
        B_mid=B_mid,
        B_d=B_d,
        C_v=C_v,
        D_vu=D_vu,
        D_vd=D_vd,
        parameter_names=("sigma",),
        parameter_lower=np.array([-p]),
        parameter_upper=np.array([p]),
        channel_names=tuple([f"res#{i}" for i in range(k)] + [f"sigma#{i}" for i in range(m)]),
        channel_parameter=np.array([-1] * k + [0] * m, int),
        channel_index=None,
        channel_lower=None,
        channel_upper=None,
        nominal_delta=np.zeros(1),
        offset=np.zeros(1),
        block_structure=np.array(blk, int).reshape(-1, 2),
        info={
            "enclosure": "sampled",
            "enclosure_inputs": {"PLDI": pldi.enclosure, "K": "sampled"},
            "armature": True,
            "eps_range": (1.0 / (1.0 + p) - 1.0, 1.0 / (1.0 - p) - 1.0),
            "sigma_range": (-p, p),
            "K_centre": K_c,
            "K_layout": lay,
            "K_radius": rho,
            "residual_gain": float(p * np.linalg.norm(rho)),  # sigma E's entries at the largest |sigma|
            "n_directions": 1,
            **gains,
        },
        model="inner-gain",
    )


def inner_armature_contains(unc: UncertainPlant, A, B, *, rtol: float = 1e-9) -> np.ndarray:
    """Whether Jacobians lie in the set of :func:`inner_armature_plant` (a sufficient test).

    A member has ``K = [B_low^-1 A_low, I - B_low^-1] / sigma`` for its
    ``sigma`` in ``[-p, p]``; with ``t = 1/sigma`` the residual ``t K_raw -
    K_c`` is affine in ``t``, so its scaled norm is convex in ``t`` and is
    minimised on each half-line ``|t| >= 1/p``: the Jacobians are in the set
    when that minimum is at most 1 and the entries outside the residual's
    rows and columns match the centre.  ``sigma = 0`` (the model itself) is
    ``A_low = 0, B_low = I``.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    if A.ndim == 2:
        A, B = A[None], B[None]
    info, m = unc.info, unc.m
    p = -float(info["sigma_range"][0])
    K_c = info["K_centre"]
    rows, cols = info["residual_rows"], info["residual_cols"]
    inside = np.zeros((m, 3 * m), bool)  # the entries the residual block carries
    inside[np.ix_(rows, cols)] = True
    out = np.ones(len(A), bool)
    for i in range(len(A)):
        if not (np.allclose(A[i, :m], unc.A_mid[:m], atol=rtol) and np.allclose(B[i, :m], 0.0, atol=rtol)):
            out[i] = False
            continue
        if np.allclose(A[i, m:], 0.0, atol=rtol) and np.allclose(B[i, m:], np.eye(m), atol=rtol):
            continue  # sigma = 0: the model robot itself
        inverse = np.linalg.inv(B[i, m:])
        K_raw = np.hstack([inverse @ A[i, m:], np.eye(m) - inverse])

        def excess(t, K_raw=K_raw):
            E = t * K_raw - K_c
            outside = np.abs(E[~inside]).max(initial=0.0) / (rtol * (1.0 + np.abs(K_c[~inside]).max(initial=0.0)))
            if not len(rows):
                return outside
            S = E[np.ix_(rows, cols)] / info["W_l"][:, None] / info["W_r"][None, :]
            return max(np.linalg.norm(S, 2), outside)

        best = min(
            minimize_scalar(
                lambda u, s=s: excess(s / u), bounds=(1e-12, p), method="bounded", options={"xatol": 1e-12}
            ).fun
            for s in (1.0, -1.0)
        )
        out[i] = best <= 1.0 + 1e-7
    return out
