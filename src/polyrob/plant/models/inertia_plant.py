"""The ``inertia`` uncertainty model: an inertia that stays positive definite, for any number of joints.

The arm's lower state rows are ``M(q) q̈-part = N(x, u) x + u``:
``[A_low B_low] = M(q)⁻¹ [N I]`` with ``N = M(q) A_low`` the torque-side
Jacobian.  The model puts each factor on its own set:

* ``M`` on the ``L D Lᵀ`` factors of the robot's inertia
  (:mod:`polyrob.plant.models.inertia_factors`): every member is positive
  definite, so every member's input matrix ``B_low = M⁻¹`` is too (the
  ``axes`` model on ``[A B]`` has 33-100 % of its members with an
  indefinite ``B_low`` on the URDF arms), and ``M⁻¹`` is an exact LFT;
* ``N`` on an ``axes`` model (:mod:`polyrob.plant.models.axes`) of a second PLDI,
  the one of the torque-side Jacobians ``[0 I; N]``, ``[0; I]`` (the same
  sampled, searched and verified extreme search as the PLDI's).

Then ``x_low' = M(δ_M)⁻¹ (N(z, Δ) x + u)`` is one LFT: the ``N`` model's
channels first (its residual block, then its directions), then the
inertia's factors.  Applies to any arm whose ``B`` is ``[0; M(q)⁻¹]`` (no
motor model in front).

Examples
--------
>>> import numpy as np, polyrob
>>> from polyrob.plant.models.inertia_plant import inertia_plant
>>> robot = polyrob.load_robot("paper_2r")
>>> pldi = polyrob.bound_pldi(robot, samples=256, coverage=0, progress=False)
>>> unc = inertia_plant(pldi)
>>> unc.model, unc.parameter_names[-3:]
('inertia', ('l21', 'd1', 'd2'))
>>> B = unc.matrices_at(np.ones(unc.n_params))[1][2:]
>>> bool(np.linalg.eigvalsh(B).min() > 0)
True
"""

from __future__ import annotations

import time

import numpy as np

from polyrob.errors import NotApplicable
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models import assembly
from polyrob.plant.models.axes import RESIDUAL_TOL, axes_contains, axes_plant
from polyrob.plant.models.inertia_factors import factor_ranges, inverse_channels
from polyrob.plant.models.inertia_lft import torque_side_pldi

__all__ = ["inertia_plant", "inertia_contains"]


def _n_coordinates(sub: UncertainPlant, N) -> np.ndarray:
    """Normalised directions ``z / z_rad`` of torque-side Jacobians ``N`` (n, m, 2m) in an ``axes`` model."""
    info, m = sub.info, sub.m
    AB = np.concatenate([N, np.repeat(np.eye(m)[None], len(N), axis=0)], axis=2)
    p = AB[:, info["layout"][:, 0], info["layout"][:, 1]]
    z = (p - info["centre"]) @ info["W"].T
    zr = info["z_rad"]
    return assembly.normalised(z, zr)


def inertia_plant(
    pldi,
    *,
    robot=None,
    nominal: str = "pldi",
    n_directions: int | None = None,
    residual_tol: float | None = None,
    bound_options: dict | None = None,
    factor_options: dict | None = None,
) -> UncertainPlant:
    """The ``inertia`` model of a PLDI (see the module docstring).

    Parameters
    ----------
    pldi : PLDI
    robot : Manipulator, optional
        Default: the PLDI's robot.
    nominal : {"pldi", "midpoint"}
    n_directions, residual_tol
        Of the ``axes`` model of ``N`` (:func:`~polyrob.plant.models.axes.axes_plant`).
    bound_options : dict, optional
        Passed to :func:`~polyrob.bounds.pldi.bound_pldi` when bounding ``N``
        (default: the PLDI's number of samples, no progress bars).
    factor_options : dict, optional
        Passed to :func:`~polyrob.plant.models.inertia_factors.factor_ranges`.

    Raises
    ------
    NotApplicable
        ``B`` is not ``[0; M(q)⁻¹]``.
    PolyrobError
        Unknown nominal.
    """
    assembly.check_nominal(nominal)
    robot = pldi.robot if robot is None else robot
    m = robot.m
    assembly.check_inverse_inertia_input(robot, pldi.domain, "inertia")
    factors = factor_ranges(robot, pldi.domain, **(factor_options or {}))
    t0 = time.perf_counter()
    npldi = torque_side_pldi(pldi, robot, bound_options)
    n_seconds = time.perf_counter() - t0
    tol = RESIDUAL_TOL if residual_tol is None else residual_tol
    sub = axes_plant(npldi, n_directions=n_directions, residual_tol=tol, nominal="midpoint")
    if np.abs(sub.B_mid[m:] - np.eye(m)).max() > 0 or np.abs(sub.D_vu).max() > 0:
        raise NotApplicable(f"{robot.name}: M(q) B is not constant; the inertia model does not apply")

    # the inertia: z = M(δ) y is z = M_c y + B1 d, v = C1 y + D11 d; its inverse y = M(δ)^-1 w
    M_c, B1, C1, D11, m_param = inverse_channels(factors)
    Minv = np.linalg.inv(M_c)
    N_c, BdN = sub.A_mid[m:], sub.B_d[m:]  # w = N_c x + u + BdN d_N
    low = assembly.into_accelerations(m)
    A_mid = assembly.arm_state_matrix(Minv @ N_c)
    B_mid = low @ Minv
    kN, kM = sub.n_delta, len(m_param)
    B_d = np.hstack([low @ Minv @ BdN, -(low @ Minv @ B1)])
    C_v = np.vstack([sub.C_v, C1 @ Minv @ N_c])
    D_vu = np.vstack([sub.D_vu, C1 @ Minv])
    D_vd = np.zeros((kN + kM, kN + kM))
    D_vd[:kN, :kN] = sub.D_vd
    D_vd[kN:, :kN] = C1 @ Minv @ BdN
    D_vd[kN:, kN:] = D11 - C1 @ Minv @ B1

    pN = sub.n_params
    n_names = tuple(f"n{name}" for name in sub.parameter_names)
    par_names = n_names + factors.names
    ch_param = np.r_[sub.channel_parameter, pN + m_param].astype(int)
    counts = np.bincount(m_param, minlength=len(factors.index))
    m_ch = [f"{factors.names[p]}#{k}" for p in range(len(factors.index)) for k in range(counts[p])]
    ch_names = tuple(f"n{c}" for c in sub.channel_names) + tuple(m_ch)
    blk = np.vstack([sub.block_structure.reshape(-1, 2), [[-int(c), 0] for c in counts]]).astype(int)
    inputs = {
        "PLDI": pldi.enclosure,
        "N PLDI": npldi.enclosure,
        "N directions": "sampled",
        "factors": "sampled",
    }
    lower = np.r_[sub.parameter_lower, factors.lower]
    upper = np.r_[sub.parameter_upper, factors.upper]
    plant = assembly.model_plant(
        pldi,
        "inertia",
        (A_mid, B_mid),
        assembly.Channels(B_d, C_v, D_vu, blk, ch_names, ch_param, D_vd),
        (par_names, lower, upper),
        {
            **assembly.enclosure_info(inputs),
            "N_enclosure": npldi.enclosure,
            "factors": factors,
            "N_plant": sub,
            "n_directions": sub.info["n_directions"],
            "N_seconds": round(n_seconds, 3),
        },
        nominal_kind=nominal,
    )
    if nominal == "midpoint":
        return plant
    _, delta = _locate(plant, pldi.A0, pldi.B0)
    nd = np.where(np.abs(delta[0]) <= 1.0 + 1e-9, np.clip(delta[0], -1.0, 1.0), delta[0])  # a nominal on a range's end
    return assembly.at_pldi_nominal(plant, pldi, nd, 0.5 * (upper - lower))


def _locate(unc: UncertainPlant, A, B):
    """``(inside, δ)`` of Jacobians (n, ...): membership of the inertia and of ``N``, and their coordinates."""
    m = unc.m
    A, B = np.asarray(A, float), np.asarray(B, float)
    if A.ndim == 2:
        A, B = A[None], B[None]
    factors, sub = unc.info["factors"], unc.info["N_plant"]
    Bl = B[:, m:, :]
    good = np.abs(np.linalg.det(Bl)) > 0
    M = np.linalg.inv(np.where(good[:, None, None], Bl, np.eye(m)))
    ok_m, d_m = factors.locate(M)
    N = M @ A[:, m:, :]
    top = np.zeros((len(A), m, 2 * m))
    top[:, :, m:] = np.eye(m)
    A_N = np.concatenate([top, N], axis=1)
    B_N = np.concatenate([np.zeros((len(A), m, m)), np.repeat(np.eye(m)[None], len(A), axis=0)], axis=1)
    ok_n = axes_contains(sub, A_N, B_N)
    ok = good & ok_m & ok_n
    ok &= np.all(np.abs(A[:, :m] - top) <= 1e-12, axis=(1, 2)) & np.all(B[:, :m] == 0, axis=(1, 2))
    return ok, np.hstack([_n_coordinates(sub, N), d_m])


def inertia_contains(unc: UncertainPlant, A, B) -> np.ndarray:
    """Whether Jacobians ``A`` (n, 2m, 2m), ``B`` (n, 2m, m) lie in an ``inertia`` model's set.

    ``M = B_low⁻¹`` must be a member of the factor model (positive definite,
    its ``L D Lᵀ`` factors in range) and ``N = M A_low`` a member of the
    ``axes`` model of ``N`` (its sufficient projection test).
    """
    return _locate(unc, A, B)[0]
