"""The recursive Newton-Euler algorithm of a serial chain in ball-jet arithmetic, for several inertial parameter sets.

Pinocchio's ``rnea`` re-run on :class:`~polyrob.bounds.certified.ball_jets.BallJet`
scalars: body-fixed frames, joint placements, axes and inertias read from
the Pinocchio model (revolute joints of a serial chain), gravity as a base
acceleration.  The torques are linear in the inertial parameters
``(m, m c, I_origin)`` and the joints' armature, so one kinematic pass serves several parameter
sets (the model's and the directions in which its true robots differ:
:mod:`polyrob.bounds.certified.factors`).

Examples
--------
>>> import numpy as np, pinocchio as pin
>>> from polyrob.bounds.certified.ball_jets import ball_sin_cos
>>> model = pin.buildModelFromUrdf("urdf/planar_2r.urdf")
>>> model.armature[:] = [0.05, 0.02]
>>> chain = Chain.from_model(model)
>>> q, v, a = np.array([0.3, -0.4]), np.array([0.5, 0.2]), np.array([1.0, -2.0])
>>> s, c = ball_sin_cos(q[None], np.zeros((1, 2)), 0)
>>> tau = rnea(chain, s, c, BallJet.constant(v[None], 0.0, 2, 0), a[None], True, chain.parameters(model)[None])
>>> bool(np.allclose(tau.mid[0, 0, 0, 0], pin.rnea(model, model.createData(), q, v, a), atol=1e-12))
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.bounds.certified.ball_jets import BallJet
from polyrob.errors import CertificationError

__all__ = ["Chain", "rnea", "BallJet"]

_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}
# a continuous joint is a revolute one whose angle Pinocchio stores as (cos q, sin q): polyrob's coordinate is q
_AXES.update({k.replace("JointModelR", "JointModelRUB"): v for k, v in _AXES.items()})
#: Relative radius given to inertial parameters computed in floats (products, differences): 100 ulps.
PARAMETER_RTOL = 1e-14


def _skew(k):
    return np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])


@dataclass(frozen=True)
class Chain:
    """A serial chain of revolute joints: axes, placements (rotation, translation) in the parent joint's frame, gravity."""

    axes: np.ndarray  # (m, 3)
    rotations: np.ndarray  # (m, 3, 3)
    translations: np.ndarray  # (m, 3)
    gravity: np.ndarray  # (3,)

    @property
    def m(self) -> int:
        return len(self.axes)

    @classmethod
    def from_model(cls, model) -> Chain:
        """The chain of a Pinocchio model; refuses joints other than revolute ones (continuous included) and branching trees."""
        axes, rots, trans = [], [], []
        for i in range(1, model.njoints):
            joint = model.joints[i]
            kind = joint.shortname()
            if model.parents[i] != i - 1:
                raise CertificationError(f"proved enclosures need a serial chain; joint {model.names[i]} branches")
            if kind in _AXES:
                axis = np.array(_AXES[kind])
            elif kind in ("JointModelRevoluteUnaligned", "JointModelRevoluteUnboundedUnaligned"):
                axis = np.asarray(joint.extract().axis, float)
            else:
                raise CertificationError(
                    f"proved enclosures support revolute joints; {model.names[i]} is {kind}: drop --certify"
                )
            axes.append(axis)
            rots.append(np.asarray(model.jointPlacements[i].rotation, float))
            trans.append(np.asarray(model.jointPlacements[i].translation, float))
        return cls(np.array(axes), np.array(rots), np.array(trans), np.asarray(model.gravity.linear, float))

    @staticmethod
    def parameters(model) -> np.ndarray:
        """The inertial parameters ``(m, h = m c, I about the joint origin)`` of every body and its joint's armature: ``(m, 14)``.

        Layout per body: mass, ``h`` (3), ``I_o`` row-major (9), the
        reflected rotor inertia ``model.armature`` that Pinocchio adds to
        ``M(q)``'s diagonal (zero where the model has none).
        """
        out = []
        armature = np.asarray(getattr(model, "armature", np.zeros(model.nv)), float)
        for i in range(1, model.njoints):
            Y = model.inertias[i]
            mass, c, Ic = float(Y.mass), np.asarray(Y.lever, float), np.asarray(Y.inertia, float)
            Io = Ic + mass * (c @ c * np.eye(3) - np.outer(c, c))
            out.append(np.concatenate([[mass], mass * c, Io.ravel(), [armature[i - 1]]]))
        return np.array(out)

    def rotation(self, i: int, sin: BallJet, cos: BallJet) -> BallJet:
        """``R_i = R_placement Rot(k_i, q_i)`` (Rodrigues: ``k k^T + cos (I - k k^T) + sin [k]x``); jets of shape ``(..., 3, 3)``."""
        k = self.axes[i]
        Rp = self.rotations[i]
        parts = [Rp @ np.outer(k, k), Rp @ (np.eye(3) - np.outer(k, k)), Rp @ _skew(k)]
        # the float products above are exact for axis-aligned k; a margin covers the others
        rad = [1e-15 * (np.abs(Rp) @ np.abs(P0)) for P0 in (np.outer(k, k), np.eye(3) - np.outer(k, k), _skew(k))]
        c4, s4 = cos.expand(-1).expand(-1), sin.expand(-1).expand(-1)
        out = c4.const_form("mul", parts[1], rad[1]) + s4.const_form("mul", parts[2], rad[2])
        constant = out.constant_like(np.broadcast_to(parts[0], out.shape), np.broadcast_to(rad[0], out.shape))
        return out + constant


def _split(params: np.ndarray, rad: np.ndarray):
    """``(mass, h, I_o, armature)`` balls of a parameter array ``(P, m, 14)``."""
    return (
        (params[..., 0], rad[..., 0]),
        (params[..., 1:4], rad[..., 1:4]),
        (
            params[..., 4:13].reshape(*params.shape[:-1], 3, 3),
            rad[..., 4:13].reshape(*rad.shape[:-1], 3, 3),
        ),
        (params[..., 13], rad[..., 13]),
    )


def rnea(chain: Chain, sin: BallJet, cos: BallJet, qd, acc, gravity: bool, params, params_rad=None) -> BallJet:
    """Joint torques of every parameter set: a jet of shape ``(B, S, P, m)``.

    Parameters
    ----------
    chain : Chain
    sin, cos : BallJet, shape (B, m)
        Of the joint positions (or :class:`~polyrob.bounds.certified.taylor_jets.TaylorJet` s: then so is
        every quantity, ``qd`` included, and the torques).
    qd : BallJet of shape (B, m), or None
        Joint velocities (``None``: at rest).
    acc : ndarray (S, m) or None
        Joint accelerations, exact (``S`` sets; ``None``: zero, ``S = 1``).
    gravity : bool
        Whether the chain's gravity acts.
    params : ndarray (P, m, 14)
        Inertial parameters (:meth:`Chain.parameters`); ``params_rad`` their radii.
    """
    m = chain.m
    params = np.asarray(params, float)
    prad = np.zeros_like(params) if params_rad is None else np.asarray(params_rad, float)
    (mass, mass_r), (h, h_r), (Io, Io_r), (armature, armature_r) = _split(params, prad)
    B = sin.shape[0]
    # the whole recursion on the distinct derivatives only (BallJet.pack): the same floats, fewer of them
    sin, cos = sin.pack(), cos.pack()
    qd = None if qd is None else qd.pack()

    def zero(*shape):
        return sin.constant_like(np.zeros(shape), 0.0)

    # kinematics (B, S, 1, 3) in each body's frame; gravity enters as the base's acceleration -g
    omega = zero(B, 1, 1, 3)
    domega = zero(B, 1, 1, 3)
    lin = sin.constant_like(np.broadcast_to(-chain.gravity if gravity else np.zeros(3), (B, 1, 1, 3)), 0.0)
    rotations, forces, moments = [], [], []
    at_rest = qd is None
    for i in range(m):
        R = chain.rotation(i, sin[:, i], cos[:, i])[:, None, None]  # (B, 1, 1, 3, 3)
        Rt = R.swap(-1, -2)
        p = chain.translations[i]
        k = chain.axes[i]
        a_par = lin + domega.const_form("cross", p, left=False)
        if not at_rest:
            a_par = a_par + omega.form("cross", omega.const_form("cross", p, left=False))
        lin = Rt.form("matvec", a_par)
        domega = Rt.form("matvec", domega)
        if acc is not None:
            domega = domega + sin.constant_like(
                np.broadcast_to(acc[None, :, None, i, None] * k, (B, len(acc), 1, 3)), 0.0
            )
        if not at_rest:
            qdi = qd[:, i][:, None, None, None]  # (B, 1, 1, 1)
            omega = Rt.form("matvec", omega)
            # omega_i x (k qd_i) = qd_i (omega_i x k), with omega_i = R^T omega_{i-1} + k qd_i: k x k = 0
            domega = domega + qdi.form("mul", omega.const_form("cross", k, left=False))
            omega = omega + qdi.const_form("mul", k, left=False)
        rotations.append(R)
        # body i's force and moment about its joint origin (linear in m, h, I_o)
        m_i, h_i, I_i = (mass[:, i], mass_r[:, i]), (h[:, i], h_r[:, i]), (Io[:, i], Io_r[:, i])
        F = lin.const_form("mul", m_i[0][:, None], m_i[1][:, None], left=False)
        F = F + domega.const_form("cross", h_i[0], h_i[1], left=False)
        N = domega.const_form("matvec", I_i[0], I_i[1]) + lin.const_form("cross", h_i[0], h_i[1])
        if not at_rest:
            F = F + omega.form("cross", omega.const_form("cross", h_i[0], h_i[1], left=False))
            N = N + omega.form("cross", omega.const_form("matvec", I_i[0], I_i[1]))
        forces.append(F)
        moments.append(N)
    # backward pass: f_i = F_i + R_{i+1} f_{i+1}, n_i = N_i + R_{i+1} n_{i+1} + p_{i+1} x (R_{i+1} f_{i+1})
    taus = [None] * m
    f, nm = forces[-1], moments[-1]
    taus[m - 1] = nm.const_form("dot", chain.axes[m - 1], left=False)
    for i in range(m - 2, -1, -1):
        R = rotations[i + 1]
        Rf = R.form("matvec", f)
        f = forces[i] + Rf
        nm = moments[i] + R.form("matvec", nm) + Rf.const_form("cross", chain.translations[i + 1])
        taus[i] = nm.const_form("dot", chain.axes[i], left=False)
    if acc is not None and np.any(armature != 0):
        # the rotor's torque armature_i qddot_i (Pinocchio's rnea and crba add it); acc is exact, the product rounded
        for i in range(m):
            value = acc[None, :, None, i] * armature[None, None, :, i]  # (1, S, P)
            rad = np.abs(acc[None, :, None, i]) * armature_r[None, None, :, i] + np.abs(value) * 2.0**-52
            taus[i] = taus[i] + taus[i].constant_like(
                np.broadcast_to(value, taus[i].shape), np.broadcast_to(rad, taus[i].shape)
            )
    return type(taus[0]).stack(taus, len(taus[0].shape)).unpack()
