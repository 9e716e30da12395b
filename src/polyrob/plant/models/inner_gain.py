"""The ``inner-gain`` model: a computed-torque inner loop whose model is off by one inertia factor.

With computed torque ``u = M_hat(q) v + h_hat(q, qdot)`` computed from a
model whose link masses and inertias are the true robot's divided by ``s``
(all links by one factor, :mod:`polyrob.model.inner`), the true robot has
``M = s M_hat`` and ``h = s h_links + D qdot``, so the inner closed loop is exactly::

    qddot = t v + (t - 1) phi(q, qdot),     t = 1/s,  phi = M_hat^-1 h_links

and its Jacobians are ``[A_low B_low] = [0 I] + eps [J(x) I]`` with
``eps = t - 1`` in ``[1/(1+p) - 1, 1/(1-p) - 1]`` and ``J = d phi / dx``
the same for every true robot.  One repeated real scalar ``eps`` (rank
``m``) along the direction ``[J_c I]`` carries the whole gain uncertainty;
the rest, ``eps (J(x) - J_c)``, is a small residual (``|eps| <= p/(1-p)``
times the half-width of ``J``) covered by one full complex block, as the
``axes`` model covers its residual.  The ranges of ``J`` come from the
PLDI itself: each true robot's entries ``eps_k J_e(x)`` lie in its
interval ``[lo_e, hi_e]``, so ``J_e`` lies in ``[lo_e/eps_k, hi_e/eps_k]``
(bounds swapped for ``eps_k < 0``) for both ``k``; the model is as sound as
the PLDI, and its coverage is checked on fresh points as any model's.

The general ``axes`` model on the same PLDI takes 12 principal directions
of a 72-entry cloud (ur5) and a residual block larger than the cloud's
spread (LP bounds over the polytope): μ about 10 where this model gives
one direction and a residual of a few percent.

With reflected rotor inertia or a payload range ``M != s M_hat``: the
model is then the LFT in the physical scalars of
:mod:`~polyrob.plant.models.inner_factors` (the same name, ``inner-gain``).

The plant is ``axes``-shaped (``info`` keys of :func:`polyrob.plant.models.axes.axes_plant`),
so membership is :func:`~polyrob.plant.models.axes.axes_contains`.
"""

from __future__ import annotations

import numpy as np

from polyrob.errors import NotApplicable
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models.assembly import at_pldi_nominal, model_plant, normalised
from polyrob.plant.models.axes import AxesChannels, centred_matrices, entry_layout

__all__ = ["inner_gain_plant", "gain_range", "applies"]


def applies(robot) -> str | None:
    """Why the model does not apply to ``robot`` (``None`` when it does)."""
    if getattr(robot, "inner", None) != "computed-torque":
        return "inner-gain: needs a computed-torque inner layer (--inner computed-torque)"
    if not getattr(robot, "model_error", 0.0) and getattr(robot, "payload", None) is None:
        return "inner-gain: no model error (--model-error) or payload range to carry"
    return None


def has_armature(robot) -> bool:
    """Whether the inner loop's robot has reflected rotor inertia (then ``M = R + s L``, not ``s M_hat``)."""
    armature = getattr(getattr(robot.model_robot, "model", None), "armature", None)
    return armature is not None and bool(np.any(np.asarray(armature) != 0))


def gain_range(model_error: float) -> tuple[float, float]:
    """``(eps_lo, eps_hi)`` of ``eps = 1/s - 1`` for ``s`` in ``[1 - p, 1 + p]``."""
    p = float(model_error)
    return 1.0 / (1.0 + p) - 1.0, 1.0 / (1.0 - p) - 1.0


def jacobian_range(pldi, robot, eps: float):
    """Entry ranges ``(lo, hi)`` of ``J = d phi / dx`` over the PLDI's domain, in the PLDI's entry order.

    ``J``'s entries are the PLDI entries of the one true robot with
    ``eps = 1/s - 1`` (``s = 1 - p``: the largest gain) divided by ``eps``,
    bounded by the same search as the PLDI (its sample count, one local
    search per direction, one verification round).  The PLDI's own
    intervals hold ``eps_k J`` of both true robots together, which loses
    the sign of ``eps``: on a constant ``J_e = c`` they give ``[-0.82 c, c]``
    at ``p = 0.1``.
    """
    from polyrob.plant.models.inner_factors import bound_one_robot

    one = bound_one_robot(robot.with_true(None, None, 1.0 - robot.model_error), pldi)
    lo, hi = np.zeros(len(pldi.entries)), np.zeros(len(pldi.entries))
    where = {name: i for i, name in enumerate(one.entries)}
    one_lo, one_hi = np.asarray(one.lower, float), np.asarray(one.upper, float)
    A0, B0 = one.A0, one.B0
    for i, (mat, r, c) in enumerate(np.asarray(pldi.entry_index, int).reshape(-1, 3)):
        name = pldi.entries[i]
        if name in where:
            lo[i], hi[i] = one_lo[where[name]], one_hi[where[name]]
        else:  # constant for this true robot
            lo[i] = hi[i] = (A0 if mat == 0 else B0)[r, c]
    return lo / eps, hi / eps


def inner_gain_plant(pldi, *, robot=None) -> UncertainPlant:
    """The ``inner-gain`` model of a PLDI of a computed-torque inner loop (see the module text).

    Raises
    ------
    NotApplicable
        Not a computed-torque loop with one inertia factor (:func:`applies`),
        or a PLDI whose input matrix varies off the diagonal.
    """
    if robot is None:  # an inner loop lives in the process that bounded it (a PLDI file records none)
        robot = pldi.source_robot if pldi.source_robot is not None else getattr(pldi.domain, "robot", None)
    why = applies(robot) if robot is not None else "inner-gain: no inner loop recorded with the PLDI"
    if why:
        raise NotApplicable(why)
    if has_armature(robot) or robot.payload is not None:  # M != s M_hat: the LFT in the physical scalars
        from polyrob.plant.models.inner_factors import inner_factors_plant

        return inner_factors_plant(pldi, robot)
    m = pldi.m
    n = 2 * m
    lay = entry_layout(pldi)
    lo, hi = np.asarray(pldi.lower, float), np.asarray(pldi.upper, float)
    e_lo, e_hi = gain_range(robot.model_error)
    isB = lay[:, 1] >= n
    diag = isB & (lay[:, 1] - n == lay[:, 0])
    if np.any(isB & ~diag):
        raise NotApplicable("inner-gain: the PLDI's input matrix varies off its diagonal (not t I)")
    j_lo, j_hi = jacobian_range(pldi, robot, e_hi)
    d = np.where(isB, 1.0, 0.5 * (j_lo + j_hi))  # the direction [J_c I]
    j_rad = np.where(isB, 0.0, 0.5 * (j_hi - j_lo))
    eps_max = max(abs(e_lo), abs(e_hi))
    rho = eps_max * j_rad
    # p = [0 I] + eps d + e: centre at eps_mid, one direction of half-width eps_rad
    base = np.where(isB, 1.0, 0.0)
    eps_mid, eps_rad = 0.5 * (e_lo + e_hi), 0.5 * (e_hi - e_lo)
    centre = base + eps_mid * d
    W = np.where(diag, 1.0 / m, 0.0)[None, :]  # reads eps from the diagonal of B
    A_mid, B_mid = centred_matrices(pldi, lay, centre)
    stack = AxesChannels(lay, m)
    gains = stack.residual(rho)
    stack.direction(d * eps_rad, "eps", 0)
    plant = model_plant(
        pldi,
        "inner-gain",
        (A_mid, B_mid),
        stack.channels(),
        (["eps"], [e_lo - eps_mid], [e_hi - eps_mid]),
        info={
            "enclosure": "sampled",
            "enclosure_inputs": {"PLDI": pldi.enclosure},
            "eps_range": (e_lo, e_hi),
            "residual_gain": float(np.linalg.norm(rho / np.maximum(hi - lo, 1e-300))),
            "n_directions": 1,
            "centre": centre,
            "basis": d[:, None],
            "W": W,
            "z_mid": np.array([eps_mid]),
            "z_rad": np.array([eps_rad]),
            **gains,
            "layout": lay,
        },
    )
    # the nominal: the PLDI's (the exact model, eps = 0)
    p0 = np.asarray(pldi.nominal, float)
    nd = normalised(W @ (p0 - centre), eps_rad)
    return at_pldi_nominal(plant, pldi, nd, eps_rad)
