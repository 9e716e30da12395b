"""Proved ranges of the factors of a computed-torque inner loop over a task box, for arms of up to 7 joints.

A computed-torque inner layer computes with a model ``(M_hat, h_hat)``; a
true robot differs from it by scalars ``theta_k`` in directions ``Delta_k``
of the inertial parameters (the link factor, the payload mass:
:mod:`polyrob.plant.models.inner_factors`), and the ``inner-gain`` model
needs the range of each factor ``K_k = [J_k G_k]`` (``m x 3m``) over the
task box ``(q, qdot, qddot)``.  Torques are linear in the inertial
parameters, so with ``R_k(q, qdot, a)`` the inverse dynamics of the
parameters ``Delta_k`` (gravity included), ``Y = M_hat^-1`` and
``psi_k = Y R_k``::

    G_k = -Y M_k,    J_k[:, q_p] = Y (dM_hat/dq_p psi_k - dR_k/dq_p),    J_k[:, qdot_l] = -Y dR_k/dqdot_l

exactly (the factor does not depend on ``theta_k``; ``tests/test_certified_arms.py``
checks it against :class:`~polyrob.plant.models.inner_factors.FactorLoop` at points).

How a box is enclosed (:meth:`FactorProblem.enclose`):

* ``M_hat``, ``M_k`` (the torques of unit accelerations) and ``R_k`` at
  rest in acceleration are computed by Newton-Euler
  (:mod:`polyrob.bounds.certified.jet_rnea`) in ball arithmetic with
  derivatives: at the box's centre (values and derivatives, thin) and over
  the box (values and derivatives up to the third); ``Y`` by a
  preconditioned ball inverse at the centre, by a fixed point over the box;
* three proved enclosures of every entry, intersected: the mean-value form
  ``K(c, a) + sum_p dK/dx_p(Q, a) [-r_p, r_p]`` in ``x = (q, qdot)``; the
  slope form of :mod:`polyrob.bounds.certified.factors.slope_form` (``Y`` enters
  once); and (``taylor=True``, the branch and bound's default) the
  second-order Taylor form of :mod:`polyrob.bounds.certified.factors.taylor2`
  (value and gradient exact at the centre, Hessian over the box's ``q`` part at its centre's ``qdot``);
* ``K`` is affine in the acceleration ``a``: every ``K`` is a convex
  combination of its values at the vertices of the ``a``-box, which are
  enumerated (``2^m``), never split;
* ``qdot`` is split like ``q``.

The branch and bound over the task box that calls :meth:`FactorProblem.enclose`
on batches of boxes is :mod:`~polyrob.bounds.certified.factors.proof`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio

from polyrob.bounds.certified import ball_jets as bj
from polyrob.bounds.certified.ball_jets import GAMMA, TINY, BallJet, ball_inverse, ball_sin_cos, intersect, lower, upper
from polyrob.bounds.certified.factors.hessian import box_models, centre_velocity_models, factor_hessians
from polyrob.bounds.certified.factors.inverse import (
    fixed_point_inverse,
    jet_parts,
    loewner_inverse,
    taylor_neumann_inverse,
)
from polyrob.bounds.certified.factors.monotone import gradient_signs
from polyrob.bounds.certified.factors.slope_form import residuals, slope_spread, vertex_gradients
from polyrob.bounds.certified.factors.taylor2 import (
    at_vertices,
    cell_grid,
    gradient_bounds,
    taylor2_bounds,
    taylor2_cells,
)
from polyrob.bounds.certified.jet_rnea import PARAMETER_RTOL, Chain, rnea
from polyrob.errors import CertificationError

__all__ = ["FactorProblem"]


@dataclass(frozen=True, eq=False)
class FactorProblem:
    """The chain, the model's inertial parameters and each factor's direction ``Delta_k`` (balls)."""

    chain: Chain
    names: tuple
    params: np.ndarray  # (1 + F, m, 14): the model, then each Delta_k (Chain.parameters)
    params_rad: np.ndarray
    #: The Pinocchio models of the inner layer's model and of each factor's true robot, and each ``theta_k``:
    #: the float values that steer the proof (:meth:`value_parts`), never a bound.  Empty: ball arithmetic's midpoints.
    float_models: tuple = ()
    thetas: tuple = ()

    @property
    def m(self) -> int:
        return self.chain.m

    @classmethod
    def from_loops(cls, loops) -> FactorProblem:
        """From ``[(name, loop), ...]``: :func:`~polyrob.bounds.certified.factors.directions.factor_directions`, or the plant's ``FactorLoop`` objects.

        ``Delta_k = (true - model) / theta_k`` in the parameters, with a
        radius covering the float arithmetic of the difference.
        """
        if not loops:
            raise CertificationError("no factor to prove: the inner loop has no model error or payload range")
        model = loops[0][1].model_robot.model
        chain = Chain.from_model(model)
        hat = Chain.parameters(model)
        params, rads = [hat], [PARAMETER_RTOL * np.abs(hat)]
        models, thetas = [model], []
        for _, loop in loops:
            if loop.inner != "computed-torque":
                raise CertificationError("proved factor ranges need a computed-torque inner layer")
            armature = np.asarray(getattr(loop.true_robot.model, "armature", np.zeros(chain.m)), float)
            hat_armature = np.asarray(getattr(model, "armature", np.zeros(chain.m)), float)
            if np.any(armature != hat_armature) or np.any(
                np.asarray(loop.true_robot.damping) != np.asarray(loop.model_robot.damping)
            ):
                raise CertificationError(
                    "proved factor ranges need the model's rotor inertia and damping on the true robot"
                )
            true = Chain.parameters(loop.true_robot.model)
            theta = float(loop.theta)
            params.append((true - hat) / theta)
            rads.append(PARAMETER_RTOL * (np.abs(true) + np.abs(hat)) / abs(theta) + TINY)
            models.append(loop.true_robot.model)
            thetas.append(theta)
        names = tuple(name for name, _ in loops)
        return cls(chain, names, np.array(params), np.array(rads), tuple(models), tuple(thetas))

    def values(self, q, qd, a):
        """Float values of every factor at points ``(n, m)``: ``(n, F, m, 3m)`` (:meth:`value_parts`'s)."""
        K, Ka = self.value_parts(q, qd)
        K[..., : self.m] += np.einsum("bfipj,bj->bfip", Ka, a)
        return K

    def value_parts(self, q, qd):
        """``K = K0 + Ka a`` at points ``(n, m)``: float ``K0`` ``(n, F, m, 3m)`` and ``Ka`` ``(n, F, m, m, m)`` (its ``q`` columns).

        By Pinocchio's floats when the problem has its models (:meth:`from_loops`),
        else the midpoints of thin ball enclosures.  Either only steers.
        """
        if self.float_models:
            return self._float_parts(np.asarray(q, float), np.asarray(qd, float))
        zero = np.zeros_like(q)
        K0, Ka, _ = self._factors(*self._dynamics(q, zero, qd, zero, 1))
        return K0.mid[0].copy(), Ka.mid[0]

    def _float_parts(self, q, qd):
        """:meth:`value_parts` by Pinocchio: ``computeRNEADerivatives`` of each model at ``a = 0`` and ``a = e_j``.

        The torques are linear in ``a``, so the derivatives at ``e_j`` less those
        at 0 are ``d(M e_j)/dq``; each direction ``Delta_k`` is its true robot
        less the model, over ``theta_k`` (about 17 times faster than the ball
        recursion, which the proof needs only for its bounds).
        """
        n, m = q.shape
        P = len(self.float_models)
        h, dhq, dhv = np.empty((n, P, m)), np.empty((n, P, m, m)), np.empty((n, P, m, m))
        M, dM = np.empty((n, P, m, m)), np.empty((n, P, m, m, m))  # dM[..., j, i, p] = d M_ij / d q_p
        zero, unit = np.zeros(m), np.eye(m)
        for P_k, model in enumerate(self.float_models):
            data, config = model.createData(), _configuration(model, q)
            for b in range(n):
                dq, dv, da = pinocchio.computeRNEADerivatives(model, data, config[b], qd[b], zero)
                h[b, P_k], dhq[b, P_k], dhv[b, P_k], M[b, P_k] = data.tau, dq, dv, da
                for j in range(m):
                    # the returned arrays are views of data's buffers: subtract the copy kept above
                    dM[b, P_k, j] = (
                        pinocchio.computeRNEADerivatives(model, data, config[b], qd[b], unit[j])[0] - dhq[b, P_k]
                    )
        M = np.triu(M) + np.swapaxes(np.triu(M, 1), -1, -2)  # Pinocchio fills the upper triangle
        dM = dM.transpose(0, 1, 4, 3, 2)  # (n, P, p, i, j)
        theta = np.asarray(self.thetas, float)
        lift = (slice(None), slice(1, None))

        def direction(x):  # (true_k - model) / theta_k
            return (x[lift] - x[:, :1]) / theta.reshape(1, -1, *([1] * (x.ndim - 2)))

        hd, dhqd, dhvd, Md, dMd = (direction(x) for x in (h, dhq, dhv, M, dM))
        Y = np.linalg.inv(M[:, 0])[:, None]  # (n, 1, i, j)
        dMh = dM[:, 0][:, None]  # (n, 1, p, i, j)
        psi_a = Y @ Md  # (n, F, i, j)
        w0 = np.einsum("nfij,nfj->nfi", Y, hd)
        inner0 = np.einsum("npij,nfj->nfip", dM[:, 0], w0) - dhqd  # (n, F, i, p)
        Jq0 = Y @ inner0
        Jqd = -(Y @ dhvd)
        Wa = dMh @ psi_a[:, :, None] - dMd  # (n, F, p, i, j)
        Ja = Y[:, :, None] @ Wa
        return np.concatenate([Jq0, Jqd, -psi_a], -1), Ja.transpose(0, 1, 3, 2, 4)

    def interval_gradient(self, q_lo, q_hi, qd_lo, qd_hi):
        """``(mid, rad)`` of the factors' gradients in ``(q, qdot)`` over boxes ``(B, m)``, at ``a = 0``: ``(2m, B, F, m, 3m)``.

        The gradient enclosure of the mean-value form (ball arithmetic over
        the box), for diagnosis: its radius against the box's half-width is
        the over-estimation that form adds per unit of width.
        """
        qc, qr = bj.centre_radius(np.asarray(q_lo, float), np.asarray(q_hi, float))
        vc, vr = bj.centre_radius(np.asarray(qd_lo, float), np.asarray(qd_hi, float))
        zero = np.zeros_like(qr)
        radii = np.concatenate([qr, vr], -1)
        with np.errstate(over="ignore", invalid="ignore"):
            Mb, hb = self._dynamics(qc, qr, vc, vr, 2)
            Y_box = self._box_inverse(self._dynamics(qc, zero, vc, zero, 1)[0], Mb, radii)[:2]
            K0b, _, _ = self._factors(Mb, hb, Y_box)
        return K0b.mid[1:], K0b.rad[1:]

    # ------------------------------------------------------------------ one batch of boxes
    def _dynamics(self, qc, qr, vc, vr, order):
        """``(M, h)``: jets (``order``) of the mass matrices ``(B, P, m, m)`` (in ``q``) and torques ``(B, P, m)`` (in ``q, qdot``)."""
        m = self.m
        s, c = ball_sin_cos(qc, qr, order)
        M = rnea(self.chain, s, c, None, np.eye(m), False, self.params, self.params_rad)  # (B, S=j, P, i)
        M = M.transpose(0, 2, 3, 1)  # (B, P, i, j)
        s2, c2 = ball_sin_cos(np.concatenate([qc, vc], -1), np.concatenate([qr, np.zeros_like(vr)], -1), order)
        qd = BallJet.variables(np.concatenate([qc, vc], -1), np.concatenate([qr, vr], -1), order)[:, m:]
        h = rnea(self.chain, s2[:, :m], c2[:, :m], qd, None, True, self.params, self.params_rad)[:, 0]  # (B, P, m)
        return M, h

    @staticmethod
    def _split_jet(J, index, nvars):
        """Value (``index=None``) or derivative ``index`` of a jet, one order lower, in ``nvars`` variables (zero-padded)."""
        if J.order == 1:
            return J.value() if index is None else J.derivative_value(index)
        return J.lowered(index, min(nvars, J.n)).padded(nvars)  # M does not depend on qdot: zeros

    @staticmethod
    def _box_inverse(Mc, Mb, radii):
        """``(mid, rad, sensitivity)`` of ``M_hat(q)^-1`` on each box (``rad = inf`` where not proved invertible).

        :func:`~polyrob.bounds.certified.factors.inverse.taylor_neumann_inverse`
        with the Taylor form of the highest order the jets allow: ``Mc`` the
        jets at the centre (thin), ``Mb`` over the box, both in ``q``; where
        it proves nothing, the wider
        :func:`~polyrob.bounds.certified.factors.inverse.loewner_inverse`,
        whose ``sensitivity`` ``(B, m)`` says which position moves ``M_hat``
        most (where to split a box on which neither proves).
        """
        k = min(Mb.order, Mc.order + 1)
        centre, box, qr = jet_parts(Mc, k - 1), jet_parts(Mb, k)[k], radii[:, : Mc.n]
        mid, rad, _ = taylor_neumann_inverse(centre, box, qr)
        sensitivity = np.zeros_like(qr)
        failed = ~np.isfinite(rad).all((-1, -2))
        if failed.any():  # the Loewner bounds on the boxes the Neumann bound leaves
            pick = [(x[0][..., failed, :, :], x[1][..., failed, :, :]) for x in centre]
            l_mid, l_rad, sensitivity[failed] = loewner_inverse(
                pick, (box[0][..., failed, :, :], box[1][..., failed, :, :]), qr[failed]
            )
            mid[failed], rad[failed] = l_mid, l_rad
        return mid, rad, sensitivity

    def inverse_enclosure(self, q_lo, q_hi, method: str = "taylor3"):
        """``(mid, rad, proved)`` of ``M_hat(q)^-1`` over boxes ``(B, m)`` in ``q`` (for measurement and tests).

        ``method``: ``taylor3`` or ``taylor2`` (the Taylor form of that order
        and the Perron-weighted Neumann bound, :mod:`~polyrob.bounds.certified.factors.inverse`;
        with ball jets), ``loewner``
        (:func:`~polyrob.bounds.certified.factors.inverse.loewner_inverse`
        with the third-order form of ball jets), ``branch-and-bound`` (what
        the branch and bound's boxes get: the ball jets tightened by the
        Taylor models', then ``taylor3``, and ``loewner`` where it fails),
        or ``fixed-point`` (the earlier method, a ball around the centre's
        inverse).
        """
        qc, qr = bj.centre_radius(np.asarray(q_lo, float), np.asarray(q_hi, float))
        order = {"taylor3": 3, "taylor2": 2, "fixed-point": 1, "loewner": 3, "branch-and-bound": 3}[method]
        zero = np.zeros_like(qr)
        with np.errstate(over="ignore", invalid="ignore"):
            Mc = self._dynamics(qc, zero, zero, zero, max(order - 1, 1))[0]
            Mb = self._dynamics(qc, qr, zero, zero, max(order, 2))[0]
            if method == "fixed-point":
                Yc, _ = self._inverse(Mc, None)
                dM = jet_parts(Mb, 1)[1]
                rad, proved = fixed_point_inverse((Yc.mid[0], Yc.rad[0]), dM, qr)
                return Yc.mid[0], rad, proved
            if method == "branch-and-bound":
                mid, rad, _ = self._bnb_inverse(np.asarray(q_lo, float), np.asarray(q_hi, float))
                return mid, rad, np.isfinite(rad).all((-1, -2))
            form = loewner_inverse if method == "loewner" else taylor_neumann_inverse
            mid, rad, _ = form(jet_parts(Mc, order - 1), jet_parts(Mb, order)[order], qr)
        return mid, rad, np.isfinite(rad).all((-1, -2))

    def _inverse(self, M, Y_box):
        """``Y = M_hat^-1`` at one order below ``M``, and the boxes where it is not provably enclosed.

        At a point (``Y_box`` None, ``M`` of order 1): a preconditioned ball
        inverse.  Over a box: ``Y_box`` (:meth:`_box_inverse`) is ``Y``'s
        value, and its derivatives follow from ``dY = -Y dM_hat Y``.
        """
        m = self.m
        Mv = self._split_jet(M, None, m)
        if Y_box is None:
            Ym, Yr = ball_inverse(Mv.mid[0, :, 0], Mv.rad[0, :, 0])
            singular = ~np.isfinite(Yr).all((-1, -2))
            if Mv.order == 0:
                return BallJet(Ym[None], np.where(singular[:, None, None], 0.0, Yr)[None], m, 0), singular
            Y_box = (Ym, Yr)
        dM = [BallJet(Mv.mid[1 + p : 2 + p, :, 0], Mv.rad[1 + p : 2 + p, :, 0], m, 0) for p in range(m)]
        singular = ~np.isfinite(Y_box[1]).all((-1, -2))
        Y0 = BallJet(Y_box[0][None], np.where(singular[:, None, None], 0.0, Y_box[1])[None], m, 0)
        # dY/dq_p = -Y dM/dq_p Y, and d2Y/dq_p dq_l = -(dY_l dM_p Y + Y d2M_pl Y + Y dM_p dY_l), with Y in Y0
        grads = [-(Y0 @ (dM[p] @ Y0)) for p in range(m)]
        pieces = [Y0] + grads
        if Mv.order >= 2:
            for p in range(m):
                for ell in range(m):
                    k = 1 + m + p * m + ell
                    d2M = BallJet(Mv.mid[k : k + 1, :, 0], Mv.rad[k : k + 1, :, 0], m, 0)
                    pieces.append(-(grads[ell] @ (dM[p] @ Y0) + Y0 @ (d2M @ Y0) + Y0 @ (dM[p] @ grads[ell])))
        mid = np.concatenate([piece.mid for piece in pieces])
        radius = np.concatenate([piece.rad for piece in pieces])
        return BallJet(mid, radius, m, Mv.order).padded(2 * m), singular  # Y does not depend on qdot

    def _factors(self, M, h, Y_box=None, residual=None, Y=None):
        """``(K0, Ka, singular)``: the factor at ``a = 0`` ``(B, F, m, 3m)`` and its ``a``-coefficients ``(B, F, m, m_p, m_j)``, one order below ``M``, ``h``, in ``(q, qdot)``.

        With ``residual = (K0c, Kac)`` (the factor's balls at the box's
        centre): ``(g0, ga, Y)`` instead, the residuals ``g = W - M_hat K_c``
        of ``M_hat K = W`` (``K = Y W``) and ``Y``'s value over the box, for
        :func:`polyrob.bounds.certified.factors.slope_form.slope_spread`.
        """
        m = self.m
        nv = 2 * m
        if Y is None:
            Y, singular = self._inverse(M, Y_box)
        else:  # given (a TaylorJet: factors/hessian.py), with its own record of where it is proved
            singular = None
        Mv, hv = self._split_jet(M, None, nv), self._split_jet(h, None, nv)
        dM = type(M).stack([self._split_jet(M, p, nv) for p in range(m)], 1)  # (B, p, P, i, j)
        dhq = type(M).stack([self._split_jet(h, p, nv) for p in range(m)], 1)  # (B, p, P, i)
        dhv = type(M).stack([self._split_jet(h, m + p, nv) for p in range(m)], 1)  # (B, l, P, i)
        Yb = Y[:, None]  # (B, 1, i, j) against the factors' axis
        Md, hd = Mv[:, 1:], hv[:, 1:]  # (B, F, i, j), (B, F, i)
        dMh, dMd = dM[:, :, 0], dM[:, :, 1:]  # (B, p, i, j), (B, p, F, i, j)
        psi_a = Yb @ Md  # (B, F, i, j)
        w0 = Yb.form("matvec", hd)  # (B, F, i)
        # J_q at a = 0: Y (dM_hat/dq_p w0 - dR/dq_p)
        inner0 = dMh[:, :, None].form("matvec", w0[:, None]) - dhq[:, :, 1:]  # (B, p, F, i)
        Jq0 = Yb[:, None].form("matvec", inner0)  # (B, p, F, i)
        Jqd = -(Yb[:, None].form("matvec", dhv[:, :, 1:]))  # (B, l, F, i)
        G = -psi_a  # (B, F, i, j)
        # the a-coefficients of J_q: Y (dM_hat/dq_p Psi - dM_k/dq_p)
        Wa = dMh[:, :, None] @ psi_a[:, None] - dMd  # (B, p, F, i, j)
        if residual is not None:
            W0 = _columns(inner0.transpose(0, 2, 3, 1), -(dhv[:, :, 1:].transpose(0, 2, 3, 1)), -Md, m)
            return residuals(Mv[:, 0], W0, Wa.transpose(0, 2, 3, 1, 4), *residual) + (Y.value(),)
        Ja = Yb[:, None] @ Wa  # (B, p, F, i, j)
        return (
            _columns(Jq0.transpose(0, 2, 3, 1), Jqd.transpose(0, 2, 3, 1), G, m),
            Ja.transpose(0, 2, 3, 1, 4),
            singular,
        )

    def enclose(
        self,
        q_lo,
        q_hi,
        qd_lo,
        qd_hi,
        a_lo,
        a_hi,
        *,
        taylor: bool = False,
        attained: bool = False,
        entries=None,
        check_inverse=None,
    ):
        """Proved bounds of every factor entry on each box: ``(lower, upper, contribution)``.

        ``q_lo`` ... ``qd_hi``: ``(B, m)``; ``a_lo``, ``a_hi``: ``(m,)`` (the
        acceleration box is never split).  ``lower``, ``upper``: ``(B, F, m, 3m)``
        (``inf`` where ``M_hat`` is not provably invertible on the box);
        ``contribution``: ``(B, F, m, 3m, 2m)``, the over-estimation bound
        each coordinate (``q``, then ``qdot``) adds to each entry (of the
        mean-value or slope form).  ``taylor``: intersect with the
        second-order Taylor form (:mod:`polyrob.bounds.certified.factors.taylor2`);
        ``entries`` (bool ``(B, F, m, 3m)``, with ``taylor``): the entries whose
        Taylor form is also bounded on cells (:func:`~polyrob.bounds.certified.factors.taylor2.taylor2_cells`:
        the branch and bound's open ones).
        ``attained``: also return the smallest and largest values attained
        at the box's centre and the acceleration vertices ``(B, F, m, 3m)``,
        and the proved sign of each entry's gradient over the box at every
        acceleration vertex ``(B, F, m, 3m, 2m)`` (``+1``, ``-1``, ``0``: not
        proved; :func:`~polyrob.bounds.certified.factors.monotone.gradient_signs`).
        ``check_inverse`` (bool ``(B,)``, with ``taylor``): the boxes whose
        ``M_hat`` may not be invertible (their parent's was not proved): its
        inverse is checked first (``inverse_enclosure(..., "branch-and-bound")``),
        a box where it is not proved gets infinite bounds (values attained:
        NaN) without the rest, and one where it is gets the first-order and
        slope forms on the Taylor models' ranges, without the second-order
        Taylor form: its first finite enclosure, cheaper (about a quarter of
        the cost on panda's wide boxes, measured by hand on 2026-12-02); its
        children get every form.
        """
        B = len(q_lo)
        # per box: 0 skipped (M_hat^-1 not proved), 1 first-order forms only (proved, its parent's not), 2 all forms
        kind = np.full(B, 2 if taylor else 0)
        if taylor and check_inverse is not None and np.any(check_inverse):
            at = np.flatnonzero(check_inverse)
            proved, sensitivity = self._inverse_check(np.asarray(q_lo, float)[at], np.asarray(q_hi, float)[at])
            kind[at] = np.where(proved, 1, 0)
        with np.errstate(over="ignore", invalid="ignore"):  # a box whose M_hat may be singular gets inf
            if not taylor or (kind == 2).all():
                out = self._enclose(q_lo, q_hi, qd_lo, qd_hi, a_lo, a_hi, taylor, entries)
            else:
                F, m = len(self.names), self.m
                lo, hi = np.full((B, F, m, 3 * m), -np.inf), np.full((B, F, m, 3 * m), np.inf)
                contribution = np.zeros((B, F, m, 3 * m, 2 * m))
                seen_lo, seen_hi = np.full((B, F, m, 3 * m), np.nan), np.full((B, F, m, 3 * m), np.nan)
                sign = np.zeros((B, F, m, 3 * m, 2 * m), int)
                out = (lo, hi, contribution, seen_lo, seen_hi, sign)
                for level in (1, 2):
                    pick = kind == level
                    if pick.any():
                        part = self._enclose(*(np.asarray(x)[pick] for x in (q_lo, q_hi, qd_lo, qd_hi)), a_lo, a_hi,
                                             True, None if entries is None else np.asarray(entries)[pick],
                                             hessians=level == 2)  # fmt: skip
                        for full, piece in zip(out, part):
                            full[pick] = piece
                # split the position that moves M_hat most (the inverse depends on q alone)
                skip = kind == 0
                contribution[skip, ..., :m] = sensitivity[~proved][:, None, None, None, :]
        return out if attained else out[:3]

    def _inverse_check(self, q_lo, q_hi):
        """``(proved, sensitivity)``: where ``inverse_enclosure(..., "branch-and-bound")`` proves ``M_hat``
        invertible, and per box how much each position moves it (:func:`~polyrob.bounds.certified.factors.inverse.loewner_inverse`)."""
        _, rad, sensitivity = self._bnb_inverse(q_lo, q_hi)
        return np.isfinite(rad).all((-1, -2)), sensitivity

    def _bnb_inverse(self, q_lo, q_hi):
        """:meth:`_box_inverse` on boxes in ``q`` with the ball jets the branch and bound's boxes have (tightened by
        the Taylor models')."""
        qc, qr = bj.centre_radius(q_lo, q_hi)
        zero = np.zeros_like(qr)
        with np.errstate(over="ignore", invalid="ignore"):
            Mc3, hc3 = self._dynamics(qc, zero, zero, zero, 3)
            Mb3, hb3 = self._dynamics(qc, qr, zero, zero, 3)
            M3 = box_models(self, qc, qr, zero, zero, (Mc3, hc3), (Mb3, hb3))[0]
            radii = np.concatenate([qr, zero], -1)
            return self._box_inverse(Mc3.truncated(2), intersect(Mb3, M3.to_ball()), radii)

    def _taylor2(self, centre, M3, h3, Y_centre, Y_box, radii, V, entries=None):
        """Per-vertex ``(lower, upper)`` ``(B, F, i, 3m, nv)`` of the second-order Taylor form (taylor2.py).

        ``centre``: order-3 jets at the boxes' centres; the value and gradient
        come from them, the Hessian over the box's ``q`` part at the centre's
        ``qdot`` from Taylor-model jets ``M3``, ``h3``
        (:func:`~polyrob.bounds.certified.factors.hessian.factor_hessians`,
        :func:`~polyrob.bounds.certified.factors.hessian.centre_velocity_models`).
        The gradient bounds returned hold for the ``qdot`` components only
        (the others are infinite).
        """
        n = 2 * self.m
        K0p, Kap, _ = self._factors(centre[0].truncated(2), centre[1].truncated(2), Y_centre)
        # the Hessian by Taylor-model jets (hessian.py): ball jets over the box lose the cancellations of Y dM Y dM Y
        q_only = np.concatenate([radii[:, : self.m], np.zeros_like(radii[:, self.m :])], -1)
        K0h, Kah = factor_hessians(self, centre[0], M3, h3, q_only)
        lows, highs, parts, g_lows, g_highs = [], [], [], [], []
        for chunk in np.array_split(V, max(1, len(V) // 8)):  # the Hessians at 8 vertices at a time
            vm, vr = at_vertices(K0p.mid[:1], K0p.rad[:1], Kap.mid[:1], Kap.rad[:1], chunk)
            gm, gr = at_vertices(K0p.mid[1:], K0p.rad[1:], Kap.mid[1:], Kap.rad[1:], chunk)
            hm, hr = at_vertices(K0h.mid[1 + n :], K0h.rad[1 + n :], Kah.mid[1 + n :], Kah.rad[1 + n :], chunk)
            hess = (hm.reshape(n, n, *hm.shape[1:]), hr.reshape(n, n, *hr.shape[1:]))
            lo, hi, part = taylor2_bounds((vm[0], vr[0]), (gm, gr), hess, radii)
            if entries is not None and entries.any():  # the open entries' quadratic on cells (taylor2.py)
                at = np.nonzero(np.broadcast_to(entries[..., None], lo.shape))
                every = (slice(None),) + at
                c_lo, c_hi = taylor2_cells(
                    (vm[0][at], vr[0][at]),
                    (gm[every].T, gr[every].T),
                    (
                        np.moveaxis(hess[0][(slice(None),) + every], -1, 0),
                        np.moveaxis(hess[1][(slice(None),) + every], -1, 0),
                    ),
                    radii[at[0]],
                    *cell_grid(len(at[0])),
                )
                lo[at], hi[at] = np.maximum(lo[at], c_lo), np.minimum(hi[at], c_hi)
            lows.append(lo)
            highs.append(hi)
            parts.append(part.max(-1))
            g_lo, g_hi = gradient_bounds((gm, gr), hess, radii)
            g_lo[: self.m], g_hi[: self.m] = -np.inf, np.inf  # the q components vary with qdot beyond this Hessian
            g_lows.append(g_lo)
            g_highs.append(g_hi)
        contribution = np.moveaxis(np.max(parts, axis=0), 0, -1)  # (B, F, i, 3m, 2m)
        gradient = (np.concatenate(g_lows, -1), np.concatenate(g_highs, -1))
        return np.concatenate(lows, -1), np.concatenate(highs, -1), contribution, gradient

    def _enclose(self, q_lo, q_hi, qd_lo, qd_hi, a_lo, a_hi, taylor=False, entries=None, hessians=True):
        m = self.m
        qc, qr = bj.centre_radius(np.asarray(q_lo, float), np.asarray(q_hi, float))
        vc, vr = bj.centre_radius(np.asarray(qd_lo, float), np.asarray(qd_hi, float))
        zero = np.zeros_like(qr)
        Mc3, hc3 = self._dynamics(qc, zero, vc, zero, 3 if taylor else 1)  # the Taylor models take order 3
        Mc2 = Mc3.truncated(min(2, Mc3.order))
        Mc, hc = Mc3.truncated(1), hc3.truncated(1)
        K0c, Kac, singular_c = self._factors(Mc, hc)
        Yc, _ = self._inverse(Mc, None)
        radii = np.concatenate([qr, vr], -1)  # (B, 2m)
        Mb, hb = self._dynamics(qc, qr, vc, vr, 3 if taylor else 2)
        if taylor:  # Taylor-model jets over the box: the Hessian's (hessian.py), and their ranges tighten the balls
            M3, h3 = box_models(self, qc, qr, vc, vr, (Mc3, hc3), (Mb, hb))
            Mb, hb = intersect(Mb, M3.to_ball()), intersect(hb, h3.to_ball())
            if hessians:  # the Hessian's models: qdot at the centre is enough (hessian.py)
                M3, h3 = centre_velocity_models(self, qc, qr, vc, (Mc3, hc3), (Mb, hb))
        *Y_box, sensitivity = self._box_inverse(Mc2, Mb, radii)  # the Taylor form of M_hat of the highest order
        Mb, hb = Mb.truncated(2), hb.truncated(2)
        K0b, Kab, singular_b = self._factors(Mb, hb, Y_box)
        g0, ga, Yb = self._factors(Mb, hb, Y_box, residual=(K0c, Kac))
        unbounded = singular_c | singular_b
        # a-vertices: the factor is affine in a, so its extremes over the a-box are at them
        a_lo, a_hi = np.asarray(a_lo, float), np.asarray(a_hi, float)
        free = np.flatnonzero(a_hi > a_lo)
        V = np.tile(a_lo, (2 ** len(free), 1))
        for bit, j in enumerate(free):
            V[(np.arange(len(V)) >> bit) & 1 == 1, j] = a_hi[j]
        Va = np.abs(V)
        k = 2 * m + 2
        # value at the centre (q_c, qdot_c), a at each vertex: K0 + Ka V (columns q only)
        vm = K0c.mid[0][..., None].repeat(len(V), -1)  # (B, F, i, 3m, nv)
        vrad = K0c.rad[0][..., None].repeat(len(V), -1)
        vmag = np.abs(vm).copy()
        am, ar = Kac.mid[0], Kac.rad[0]  # (B, F, i, p, j)
        vm[:, :, :, :m] += am @ V.T
        vrad[:, :, :, :m] += ar @ Va.T
        vmag[:, :, :, :m] += np.abs(am) @ Va.T
        vrad = (vrad + GAMMA * k * (vmag + np.abs(vm))) * (1 + GAMMA) + TINY
        # the gradient in (q, qdot) over the box, at each vertex: sup |dK/dx_p|
        gm, gr = vertex_gradients(K0b, Kab, V, k)
        gabs = np.abs(gm) + gr
        spread = np.einsum("pbfiev,bp->bfiev", gabs, radii)
        spread = spread * (1 + 8 * m * GAMMA) + TINY
        contribution = (gabs.max(-1) * radii.T[:, :, None, None, None]).transpose(1, 2, 3, 4, 0)  # (B, F, i, e, 2m)
        # the slope form (slope_form.py): both forms are proved, so each entry keeps the narrower one
        slope, slope_contribution = slope_spread(g0, ga, Yb, V, radii)
        narrower = slope < spread
        spread = np.where(narrower, slope, spread)
        contribution = np.where(narrower.all(-1)[..., None], slope_contribution, contribution)
        hi, lo = upper(vm, vrad + spread), lower(vm, vrad + spread)
        g_lo, g_hi = gm - gr, gm + gr
        if taylor and hessians:  # both enclose K at each vertex: their intersection does (M_hat's inverse as proved)
            centre = (Mc3, hc3)
            t_lo, t_hi, t_contribution, t_grad = self._taylor2(
                centre, M3, h3, (Yc.mid[0], Yc.rad[0]), Y_box, radii, V, entries
            )
            # where the Taylor form is the narrower, its second-order terms say where to split
            narrower = ((t_hi - t_lo) < (hi - lo)).all(-1)
            contribution = np.where(narrower[..., None], t_contribution, contribution)
            hi, lo = np.minimum(hi, t_hi), np.maximum(lo, t_lo)
            g_lo, g_hi = np.maximum(g_lo, t_grad[0]), np.minimum(g_hi, t_grad[1])
        hi, lo = hi.max(-1), lo.min(-1)
        hi[unbounded], lo[unbounded] = np.inf, -np.inf
        # a box where M_hat is not proved invertible: split the position that moves M_hat most (the inverse
        # depends on q alone; a split in qdot would not help it)
        contribution[unbounded] = np.concatenate([sensitivity, np.zeros_like(sensitivity)], -1)[
            np.nonzero(unbounded)[0]
        ][:, None, None, None, :]
        sign = gradient_signs(g_lo, g_hi)
        sign[unbounded] = 0
        # values attained at the box's centre and the a-vertices (float midpoints of thin balls): they only steer
        return lo, hi, contribution, vm.min(-1), vm.max(-1), sign


def _configuration(model, q):
    """Pinocchio's configurations ``(n, nq)`` of joint angles ``q`` ``(n, m)``: a continuous joint's as ``(cos, sin)``."""
    out = np.empty((len(q), model.nq))
    for i in range(1, model.njoints):
        k, j = model.joints[i].idx_q, i - 1
        if model.joints[i].nq == 2:
            out[:, k], out[:, k + 1] = np.cos(q[:, j]), np.sin(q[:, j])
        else:
            out[:, k] = q[:, j]
    return out


def _columns(Jq, Jqd, G, m):
    """``[J_q J_qd G]``: three ``(B, F, i, m)`` jets side by side, ``(B, F, i, 3m)``."""
    K = type(Jq).stack([Jq, Jqd, G], 3)  # (B, F, i, 3, m)
    return K.reshape(*K.shape[:3], 3 * m)
