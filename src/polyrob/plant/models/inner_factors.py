"""``inner-gain`` with rotor inertia or a payload: computed torque as an exact LFT in its physical scalars.

A computed-torque inner layer ``u = M_hat(q) v + h_hat(q, qdot)`` computes
with a model that has the true rotor (armature) inertia ``R``, link masses
and inertias ``L`` off by one factor, and the middle of a payload range.
The true robot differs from the model by scalars ``theta_k`` on which its
inertia and its torques depend affinely: the link factor (``theta = 1 -
s``: ``M = M_hat - theta L``) and the payload mass (``theta = mass -
mass_mid`` at a fixed centre of mass: ``M = M_hat + theta P``).  Writing
``M = M_hat (I - sum theta_k G_k)`` and the torque mismatch the same way,
the outer input ``v`` and the true robot's acceleration ``a`` satisfy
exactly::

    a = v + sum_k theta_k (G_k(q) a + phi_k(q, qdot))

(``G = M_hat^-1 L`` for the links, ``-M_hat^-1 P`` for the payload), so the
inner loop's Jacobians are ``[A_low B_low] = (I - sum theta_k G_k)^-1 [sum
theta_k J_k, I]`` with ``J_k = d(G_k a + phi_k)/dx``, and the loop is the LFT::

    a = v + sum_k w_k,   w_k = theta_k z_k,   z_k = K_k [x; a],   K_k = [J_k  G_k]

one real scalar per ``theta_k`` repeated on ``m`` channels; ``G_k`` is fed
back through them (``D_vd``).  Without armature and payload ``G = I`` and
this is the one-gain model of :mod:`~polyrob.plant.models.inner_gain`; with
them ``B_low`` is no multiple of ``I`` (talos' arm: ``G`` has eigenvalues
from about 0 on the wrist to 0.9 on the shoulder).  The factors move over
the domain: ``K_k = K_k,c + E_k``, the stacked ``E_k`` within the
half-widths of their ranges carried by one full complex block (as ``axes``
carries its residual), inside the ``theta`` loops.  Every true robot is
then a member exactly (its ``theta``, its ``K`` less the centre).  ``K_k``
does not depend on the ``theta``: a task domain fixes ``a``, so each
factor's ranges come from one true robot that differs from the model in
``theta_k`` alone, ``K_k = [B_low^-1 A_low, I - B_low^-1] / theta_k``,
bounded by the PLDI's own search on that map (:class:`FactorLoop`).  A
torque box (``a`` would depend on the ``theta``) and a payload whose centre
of mass ranges (it enters as ``mass x offset``) are refused.

Why by hand: MATLAB's ``uss`` would hold this LFT, but the factors and their
ranges over a robot's task are polyrob's own.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, fields, replace

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from polyrob.errors import NotApplicable
from polyrob.model.inner import InnerLoopRobot
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models.axes import entry_layout, residual_of_radii

__all__ = ["FactorLoop", "factor_parameters", "inner_factors_plant", "inner_factors_contains"]


@dataclass(frozen=True, eq=False)
class FactorLoop(InnerLoopRobot):
    """A true robot's inner loop whose Jacobians are reported as its factor ``K = [J G]``.

    The true robot differs from the model in one scalar, ``theta``:
    ``jacobians_batch`` returns ``A`` with lower rows ``J = B_low^-1 A_low /
    theta`` and ``B`` with lower rows ``G = (I - B_low^-1) / theta``, so that
    :func:`polyrob.bound_pldi` bounds ``K`` with the search it uses for any
    Jacobian.
    """

    theta: float = 0.1
    #: ``B`` is a factor, not an inverse inertia: the bounds do not check it for positive definiteness.
    jacobians_are_factors = True

    def jacobians_batch(self, q, qdot, v):
        A, B = super().jacobians_batch(q, qdot, v)
        m = self.m
        inverse = np.linalg.inv(B[:, m:])
        A[:, m:] = inverse @ A[:, m:] / self.theta
        B[:, m:] = (np.eye(m) - inverse) / self.theta
        return A, B


def factor_parameters(robot) -> list[tuple[str, float, FactorLoop]]:
    """``(name, half range, factor loop)`` of each scalar in which ``robot``'s true robots differ from its model.

    Raises
    ------
    NotApplicable
        A payload whose centre of mass ranges.
    """
    payload = robot.payload
    mass, com = payload.midpoint if payload is not None else (0.0, np.zeros(3))
    if payload is not None and np.any(np.array(payload.com_upper) > np.array(payload.com_lower)):
        raise NotApplicable("inner-gain: a payload whose centre of mass ranges enters as mass x offset (not affine)")

    def loop(true, theta):
        values = {f.name: getattr(true, f.name) for f in fields(InnerLoopRobot) if f.init}
        return FactorLoop(**values, theta=float(theta))

    out = []
    if robot.model_error:
        p = float(robot.model_error)
        out.append(("links", p, loop(robot.with_true(mass, com, 1.0 - p), p)))
    if payload is not None and payload.mass_upper > payload.mass_lower:
        r = 0.5 * (payload.mass_upper - payload.mass_lower)
        out.append(("payload", r, loop(robot.with_true(mass + r, com, 1.0), r)))
    return out


def _factor_range(pldi, factor: FactorLoop):
    """``(K_c, radii)``: the centre of the factor (``m x 3m``) and its entries' half-widths (``m x 3m``)."""
    from polyrob.bounds.pldi import bound_pldi

    samples = int((pldi.info or {}).get("samples", 256))
    one = bound_pldi(
        factor,
        replace(pldi.domain, robot=factor),
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
    radii = np.zeros_like(K)
    radii[lay[:, 0], lay[:, 1]] = 0.5 * (hi - lo)
    return K, radii


def inner_factors_plant(pldi, robot) -> UncertainPlant:
    """The exact LFT of the module text for a computed-torque loop (armature, payload mass, link factor).

    Raises
    ------
    NotApplicable
        Not a task domain, a payload whose centre of mass ranges, or a true
        robot whose ``I - sum theta_k G_k`` may be singular.
    """
    from polyrob.domains.task import TaskDomain

    if not isinstance(pldi.domain, TaskDomain):
        raise NotApplicable("inner-gain: with rotor inertia or a payload it needs a task domain, not a torque box")
    m, n = pldi.m, 2 * pldi.m
    params = factor_parameters(robot)
    centres, radii = zip(*(_factor_range(pldi, loop) for _, _, loop in params))
    ranges = np.array([r for _, r, _ in params])
    if sum(r * np.max(np.abs(np.linalg.eigvals(K[:, n:]))) for r, K in zip(ranges, centres)) >= 1.0:
        raise NotApplicable("inner-gain: I - sum theta_k G_k may be singular inside the ranges")
    Bf, Cf, gains = residual_of_radii(np.vstack(radii))
    k, P = (0 if Bf is None else Bf.shape[1]), len(params)
    # channels: the residual block, then each theta repeated m times (every w_k enters the accelerations)
    nd = k + P * m
    B_d = np.zeros((n, nd))
    B_d[m:, k:] = np.tile(np.eye(m), P)
    C_v, D_vu, D_vd = np.zeros((nd, n)), np.zeros((nd, m)), np.zeros((nd, nd))
    if k:
        C_v[:k], D_vu[:k], D_vd[:k, k:] = Cf[:, :n], Cf[:, n:], np.tile(Cf[:, n:], P)
    for j, (r, K) in enumerate(zip(ranges, centres)):
        rows = slice(k + j * m, k + (j + 1) * m)
        C_v[rows], D_vu[rows], D_vd[rows, k:] = r * K[:, :n], r * K[:, n:], np.tile(r * K[:, n:], P)
        if k:
            D_vd[rows, :k] = r * Bf[j * m : (j + 1) * m]
    A_mid = np.zeros((n, n))
    A_mid[:m, m:] = np.eye(m)
    B_mid = np.zeros((n, m))
    B_mid[m:] = np.eye(m)
    names = tuple(name for name, _, _ in params)
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
        parameter_names=names,
        parameter_lower=-ranges,
        parameter_upper=ranges,
        channel_names=tuple([f"res#{i}" for i in range(k)] + [f"{nm}#{i}" for nm in names for i in range(m)]),
        channel_parameter=np.array([-1] * k + [j for j in range(P) for _ in range(m)], int),
        channel_index=None,
        channel_lower=None,
        channel_upper=None,
        nominal_delta=np.zeros(P),
        offset=np.zeros(P),
        block_structure=np.array(([[k, k]] if k else []) + [[-m, 0]] * P, int).reshape(-1, 2),
        info={
            "enclosure": "sampled",
            "enclosure_inputs": {"PLDI": pldi.enclosure, "factors": "sampled"},
            "factors": names,
            "theta_range": ranges,
            "K_centres": np.array(centres),
            "K_radii": np.array(radii),
            "residual_gain": float(np.linalg.norm(np.vstack(radii) * np.repeat(ranges, m)[:, None])),
            "n_directions": P,
            **gains,
        },
        model="inner-gain",
    )


def _scaled_residual(unc: UncertainPlant, K_raw, theta, rtol: float) -> float:
    """The smallest scaled norm of a residual ``S`` with ``sum theta_k E_k = K_raw - sum theta_k K_k,c``.

    An entry that no residual reaches (outside the block's rows and columns)
    must match: its mismatch, relative to ``rtol`` and divided by the largest
    ``|theta_k|`` (so that, for one scalar, the whole is convex in
    ``1/theta``), counts instead when it is larger.  The least-squares
    ``S = C^+ R`` has the smallest spectral norm among all solutions (the
    others add a part in ``C``'s null space, orthogonal to it).
    """
    info, m = unc.info, unc.m
    R = K_raw - np.tensordot(theta, info["K_centres"], axes=1)
    rows, cols = info["residual_rows"], info["residual_cols"]
    if not np.any(theta):
        return np.inf
    scale = rtol * (1.0 + np.abs(K_raw).max()) * np.abs(theta).max()
    rest = np.ones(R.shape[1], bool)
    rest[cols] = False
    mismatch = np.abs(R[:, rest]).max(initial=0.0)
    if not len(rows):
        return max(np.abs(R).max(), mismatch) / scale
    C = np.zeros((m, len(rows)))  # joint row i of parameter j is stacked row j m + i
    C[rows % m, np.arange(len(rows))] = theta[rows // m] * info["W_l"]
    target = R[:, cols] / info["W_r"][None, :]
    S = np.linalg.lstsq(C, target, rcond=None)[0]
    mismatch = max(mismatch, np.abs((C @ S - target) * info["W_r"][None, :]).max())
    return max(float(np.linalg.norm(S, 2)), mismatch / scale)


def inner_factors_contains(unc: UncertainPlant, A, B, *, rtol: float = 1e-9) -> np.ndarray:
    """Whether Jacobians lie in the set of :func:`inner_factors_plant` (a sufficient test).

    A member has ``K_raw = [B_low^-1 A_low, I - B_low^-1] = sum theta_k K_k``
    for its ``theta`` in the box: the smallest scaled residual over the
    ``theta`` tried (the weighted least-squares fit of ``K_raw`` by the
    centres, a grid with the box's corners, where the bounds' true robots
    lie, then a local search; for one scalar a bounded search on each sign,
    where the residual is convex in ``1/theta``) must be at most 1.
    ``theta = 0`` (the model itself) is ``A_low = 0, B_low = I``.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    if A.ndim == 2:
        A, B = A[None], B[None]
    m = unc.m
    r = np.asarray(unc.info["theta_range"], float)
    P = len(r)
    grid = np.array(list(itertools.product(*[np.linspace(-x, x, 5) for x in r])))
    out = np.ones(len(A), bool)
    for i in range(len(A)):
        if not (np.allclose(A[i, :m], unc.A_mid[:m], atol=rtol) and np.allclose(B[i, :m], 0.0, atol=rtol)):
            out[i] = False
            continue
        if np.allclose(A[i, m:], 0.0, atol=rtol) and np.allclose(B[i, m:], np.eye(m), atol=rtol):
            continue  # theta = 0: the model robot itself
        inverse = np.linalg.inv(B[i, m:])
        K_raw = np.hstack([inverse @ A[i, m:], np.eye(m) - inverse])

        def f(theta, K_raw=K_raw):
            return _scaled_residual(unc, K_raw, np.asarray(theta, float), rtol)

        if P == 1:
            best = min(
                minimize_scalar(lambda u, s=s: f([s * u]), bounds=(1e-12 * r[0], r[0]), method="bounded").fun
                for s in (1.0, -1.0)
            )
        else:
            # the start: K_raw ~ sum theta_k K_k,c by least squares, weighted by each entry's spread
            # (exact where no residual reaches), then the grid's best if better, then a local search
            weight = 1.0 / (np.tensordot(r, unc.info["K_radii"], axes=1).ravel() + 1e-9 * np.abs(K_raw).max())
            basis = unc.info["K_centres"].reshape(P, -1).T * weight[:, None]
            fitted = np.clip(np.linalg.lstsq(basis, K_raw.ravel() * weight, rcond=None)[0], -r, r)
            candidates = [fitted, *grid]
            values = [f(t) for t in candidates]
            best = min(values)
            if best > 1.0:
                start = candidates[int(np.argmin(values))]
                best = min(best, minimize(f, start, method="Nelder-Mead", bounds=list(zip(-r, r))).fun)
        out[i] = best <= 1.0 + 1e-7
    return out
