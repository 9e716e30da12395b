"""The factors' Hessian over a box by Taylor-model jets: the cancellations of ``Y dM Y dM Y`` kept.

The second-order Taylor form (:mod:`~polyrob.bounds.certified.factors.taylor2`)
needs the factors' Hessian in ``(q, qdot)`` at every point of a box.
Evaluated in ball arithmetic over the box (``FactorProblem._factors`` on
ball jets), every ingredient -- ``Y = M_hat^-1``, the derivatives of
``M_hat`` and of the torques -- is one ball as wide as its whole variation
over the box, and the Hessian's terms ``Y dM Y dM Y psi`` multiply five such
balls: on ur5 at a fifth of the default task (q ±0.04 rad) an entry of the
wrists' ``J_q`` columns gets a Hessian radius of 8,000 where the sampled
Hessians vary by 0.006 (``tests/test_certified_hessian.py``).

Here the same computation runs on :class:`~polyrob.bounds.certified.taylor_jets.TaylorJet`
s: each ingredient is ``const + lin.d ± rest`` in the offset ``d`` of ``q``
from the box's centre, with thin ``const`` and ``lin`` (``M_hat``'s and the
torques' jets at the centre, up to the third derivatives) and a ``rest`` of
second order in the box (or first order, from the third derivatives over
the box, for the highest component).  ``Y`` is

    Y(c + d) in C + sum_p (-C dM_hat/dq_p(c) C) d_p  ±  (|rest| |C| + |E|^2 |Y|)

from ``Y = C + E C + E^2 Y``, ``E = I - C M_hat = sum_p (-C dM_hat/dq_p(c)) d_p + rest``
(:mod:`~polyrob.bounds.certified.factors.inverse`: ``C`` the float inverse
at the centre, ``|E|`` and ``|Y|`` the proved bounds over the box).  The
products keep their linear parts exact, so the Hessian's own first-order
variation is what it is at the centre and only second-order terms are
bounded by magnitudes.

The velocity at the box's centre is enough (:func:`centre_velocity_models`).
At ``a = 0`` the factors are polynomials of degree two in ``qdot`` (the
torques ``h = C(q)[qdot, qdot] + g(q) + D qdot`` are, and ``M_hat``, ``Y`` do
not depend on ``qdot``), and their ``a``-coefficients do not depend on it.
For such an ``f`` and ``x = (q_c + d_q, qdot_c + d_v)``::

    f(x) = f(c) + grad f(c).d + 1/2 d_q' H_qq(xi_1) d_q + d_v' H_vq(xi_2) d_q + 1/2 d_v' H_vv(xi_3) d_v

with every ``xi`` in the box's ``q`` part and ``qdot = qdot_c`` (Taylor's
theorem in ``q`` on ``f(., qdot_c)`` and the mean-value theorem on
``f_v(., qdot_c).d_v``; the expansion in ``d_v`` is exact, and ``H_vv``
does not depend on ``qdot``).  So the Taylor form of
:mod:`~polyrob.bounds.certified.factors.taylor2` may take the Hessian over
the box *thin in* ``qdot``: the variation of the third derivatives of
``C(q)[qdot, qdot]`` with ``qdot`` (the largest part of the models'
remainders: about three quarters on ur5's boxes of a fifth of its task)
drops out.  It is not the Hessian at every point of the box: the gradient's
``q`` components vary with ``qdot`` through the third derivatives, so the
monotonicity test takes only the ``qdot`` components from it
(:meth:`FactorProblem._taylor2 <polyrob.bounds.certified.factors.ranges.FactorProblem._taylor2>`).

Those models are also of second order in ``q`` (``pairs``: the products
``d_p d_l`` of the joint angles' offsets are symbols of their own,
:class:`~polyrob.bounds.certified.taylor_jets.TaylorJet`): what Newton-Euler
multiplies stays exact to second order, and only third-order terms are
bounded by magnitudes.  The Hessian's ball is then of second order in the
box where it was of first, and it keeps the cancellations between the
torques' components that ``Y`` combines; on ur5's nearly constant entries
(an axisymmetric wrist) that remainder was all of the Taylor form's excess
(``tests/test_certified_hessian.py`` measures the radii).
"""

from __future__ import annotations

import numpy as np

from polyrob.bounds.certified.ball_jets import GAMMA, TINY, BallJet, centre_radius, upper
from polyrob.bounds.certified.factors.inverse import jet_parts, neumann_inverse, residual_ball, taylor_residual
from polyrob.bounds.certified.factors.taylor_inputs import from_ball_jets, taylor_sin_cos
from polyrob.bounds.certified.jet_rnea import rnea
from polyrob.bounds.certified.taylor_jets import TaylorJet
from polyrob.errors import ArgumentError

__all__ = [
    "inverse_model",
    "inverse_jet",
    "factor_hessians",
    "tighter",
    "taylor_dynamics",
    "box_models",
    "centre_velocity_models",
    "hessian_enclosure",
]


def inverse_model(Mc: BallJet, Mb: BallJet, radii):
    """The Taylor model of ``Y = M_hat^-1`` over each box (an order-0 :class:`TaylorJet` ``(B, m, m)``, linear in ``q``).

    ``Mc``: the mass matrices' jets at the centres (order >= 2, model set 0
    on axis 2), ``Mb`` over the boxes (order 3), in ``q``; ``radii``
    ``(B, >= m)``.  Where ``M_hat`` is not proved invertible the ball is
    ``inf``.
    """
    m = Mc.n
    rq = np.asarray(radii, float)[:, :m]
    k = min(Mb.order, Mc.order + 1)
    centre, box = jet_parts(Mc, k - 1), jet_parts(Mb, k)[k]
    M0 = centre[0][0]
    with np.errstate(all="ignore"):
        C = np.linalg.inv(M0)
    C = np.where(np.isfinite(C), C, 0.0)
    linear, rest = taylor_residual(C, centre, box, rq)
    Y_mid, Y_rad, _ = neumann_inverse(C, linear, rest, rq)  # the proved ball of Y (and where it is proved)
    E_mid, E_rad = residual_ball(linear, rest, rq)
    N = upper(np.abs(E_mid), E_rad)  # |E| over the box
    Y_abs = upper(np.abs(Y_mid), Y_rad)
    LC = BallJet(linear[0], linear[1], 0, 0).const_form("matmul", C, left=False)  # -C dM/dq_p(c) C, (m, B, m, m)
    rest_abs = upper(np.abs(rest[0]), rest[1])
    with np.errstate(over="ignore", invalid="ignore"):
        tail = upper(rest_abs @ np.abs(C), 0.0) + upper(N @ upper(N @ Y_abs, 0.0), 0.0)
        lin_rad = (LC.rad[0] * rq.T[:, :, None, None]).sum(0)
        R = (tail + lin_rad) * (1 + 4 * GAMMA) + TINY
    R = np.where(np.isfinite(R) & np.isfinite(Y_rad), R, np.inf)
    return TaylorJet(C[None], LC.mid[:, None], R[None], rq.T.copy(), m, 0)


def inverse_jet(M: TaylorJet, Y0: TaylorJet, nvars: int) -> TaylorJet:
    """``Y``'s jet (order 2, in ``nvars`` variables, ``q`` first) from ``M_hat``'s (order 3, in ``q``) and ``Y``'s value model.

    ``dY/dq_p = -Y dM_p Y`` and ``d2Y/dq_p dq_l = -(dY_l dM_p Y + Y d2M_pl Y + Y dM_p dY_l)``,
    as :meth:`FactorProblem._inverse <polyrob.bounds.certified.factors.FactorProblem>`
    does in balls.
    """
    m = M.n
    Mv = M.lowered(None, m)[:, 0]  # the model's mass matrix, order 2: (B, i, j)
    dM = [Mv.component(1 + p) for p in range(m)]
    grads = [-(Y0 @ (dM[p] @ Y0)) for p in range(m)]
    pieces = [Y0] + grads
    for p in range(m):
        for ell in range(m):
            d2M = Mv.component(1 + m + p * m + ell)
            pieces.append(-(grads[ell] @ (dM[p] @ Y0) + Y0 @ (d2M @ Y0) + Y0 @ (dM[p] @ grads[ell])))
    return TaylorJet.concatenate(pieces, m, 2).padded(nvars)


def tighter(a: TaylorJet, b: TaylorJet) -> TaylorJet:
    """Entry by entry, the model of ``a`` or of ``b`` (two Taylor models of one function) with the smaller ball."""
    pick = a.R <= b.R
    return a._with(np.where(pick, a.c, b.c), np.where(pick, a.L, b.L), np.where(pick, a.R, b.R))


def factor_hessians(problem, Mc: BallJet, M: TaylorJet, h: TaylorJet, radii):
    """``(K0, Ka)``: ball jets (order 2, over the boxes) of the factors at ``a = 0`` and of their ``a``-coefficients.

    ``Mc``: ``M_hat``'s jets at the boxes' centres (order 2 or more, in
    ``q``); ``M``, ``h``: order-3 Taylor-model jets of ``M_hat`` (in ``q``)
    and of the torques (in ``(q, qdot)``) over the boxes (:func:`taylor_dynamics`,
    or :func:`~polyrob.bounds.certified.factors.taylor_inputs.from_ball_jets`); ``radii`` ``(B, 2m)``.
    Every component is the range of its Taylor model over the box; the
    Hessian components (``[1 + 2m:]``) are what
    :func:`~polyrob.bounds.certified.factors.taylor2.taylor2_bounds` takes.
    """
    m = problem.m
    Y0 = inverse_model(Mc, M.to_ball(), radii).extended(M.linear_r, M.pairs)
    Y = inverse_jet(M, Y0, 2 * m)
    K0, Ka, _ = problem._factors(M, h, Y=Y)
    return K0.to_ball(), Ka.to_ball()


def taylor_dynamics(problem, qc, qr, vc, vr, order, pairs: bool = False):
    """``(M, h)`` as :meth:`FactorProblem._dynamics <polyrob.bounds.certified.factors.ranges.FactorProblem._dynamics>`, in Taylor-model jets linear in ``q`` (:mod:`~polyrob.bounds.certified.taylor_jets`).

    ``pairs``: of second order in ``q`` (the monomials ``d_p d_l`` of the
    joint angles' offsets kept, :class:`~polyrob.bounds.certified.taylor_jets.TaylorJet`).
    """
    m = problem.m
    kq = m if pairs else 0
    s, c = taylor_sin_cos(qc, qr, order, m, pairs=kq)
    M = rnea(problem.chain, s, c, None, np.eye(m), False, problem.params, problem.params_rad).transpose(0, 2, 3, 1)
    return M.extended(np.concatenate([qr, vr], -1).T), taylor_torques(problem, qc, qr, vc, vr, order, kq)


def taylor_torques(problem, qc, qr, vc, vr, order, pairs: int = 0):
    """The torques ``h`` of :func:`taylor_dynamics` alone (Taylor-model jets linear in ``(q, qdot)``; ``pairs``: ``m`` or 0)."""
    m = problem.m
    x_c, x_r = np.concatenate([qc, vc], -1), np.concatenate([qr, vr], -1)
    # the torques are linear in (q, qdot): their quadratic terms in qdot keep their cancellations too
    s2, c2 = taylor_sin_cos(x_c, np.concatenate([qr, np.zeros_like(vr)], -1), order, 2 * m, x_r, pairs)
    qd = TaylorJet.variables(x_c, x_r, order, 2 * m, pairs)[:, m:]
    return rnea(problem.chain, s2[:, :m], c2[:, :m], qd, None, True, problem.params, problem.params_rad)[:, 0]


def box_models(problem, qc, qr, vc, vr, centre, box, pairs: bool = False):
    """Order-3 Taylor-model jets ``(M, h)`` of ``M_hat`` and the torques over the boxes.

    Two models of each: Newton-Euler in Taylor models (:func:`taylor_dynamics`)
    and Taylor's theorem on the ball jets at the centre and over the box
    (:func:`~polyrob.bounds.certified.factors.taylor_inputs.from_ball_jets`); entry by
    entry the one with the smaller ball (:func:`~polyrob.bounds.certified.factors.hessian.tighter`).
    ``centre``, ``box``: ``(M, h)`` ball jets of order 3.
    """
    m = problem.m
    radii = np.concatenate([qr, vr], -1)
    Mt, ht = taylor_dynamics(problem, qc, qr, vc, vr, 3, pairs)
    Mf, hf = (from_ball_jets(c, b, radii, 2 * m).extended(radii.T, Mt.pairs) for c, b in zip(centre, box))
    return tighter(Mt, Mf), tighter(ht, hf)


def centre_velocity_models(problem, qc, qr, vc, centre, box):
    """``(M, h)``: :func:`box_models` over the boxes' ``q`` part with ``qdot`` at the centres ``vc``, of second order in ``q``.

    What the factors' Hessian in the Taylor form needs (the module's
    docstring says why).  ``centre``, ``box``: ``(M, h)`` ball jets (order
    3) at the centres and over the whole boxes (which hold the thin ones).
    """
    return box_models(problem, qc, qr, vc, np.zeros_like(qr), centre, box, pairs=True)


def hessian_enclosure(problem, q_lo, q_hi, qd_lo, qd_hi, method: str = "taylor-model"):
    """``(mid, rad)`` of ``problem``'s factors' Hessians in ``(q, qdot)`` at ``a = 0`` over boxes ``(B, m)``: ``(2m, 2m, B, F, m, 3m)``.

    ``method``: ``taylor-model`` (:func:`box_models` and
    :func:`factor_hessians`), ``second-order`` (the same with the products
    of ``q``'s offsets kept: the branch and bound's, with ``qdot`` thin) or
    ``balls`` (the earlier one: ball jets over the box, ``Y`` by its
    proved ball).  For measurement and tests.
    """
    qc, qr = centre_radius(np.asarray(q_lo, float), np.asarray(q_hi, float))
    vc, vr = centre_radius(np.asarray(qd_lo, float), np.asarray(qd_hi, float))
    zero, n = np.zeros_like(qr), 2 * problem.m
    radii = np.concatenate([qr, vr], -1)
    with np.errstate(over="ignore", invalid="ignore"):
        Mc, hc = problem._dynamics(qc, zero, vc, zero, 3)
        Mb, hb = problem._dynamics(qc, qr, vc, vr, 3)
        if method in ("taylor-model", "second-order"):  # linear in q, or with the products of q's offsets
            M, h = box_models(problem, qc, qr, vc, vr, (Mc, hc), (Mb, hb), pairs=method == "second-order")
            K0 = factor_hessians(problem, Mc, M, h, radii)[0]
        elif method == "balls":
            K0 = problem._factors(Mb, hb, problem._box_inverse(Mc.truncated(2), Mb, radii)[:2])[0]
        else:
            raise ArgumentError(
                f"hessian_enclosure: method must be 'taylor-model', 'second-order' or 'balls' (got {method!r})"
            )
    shape = (n, n, *K0.mid.shape[1:])
    return K0.mid[1 + n :].reshape(shape), K0.rad[1 + n :].reshape(shape)
