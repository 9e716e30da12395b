"""``inner-links``: a computed-torque loop over a per-link robot-uncertainty set, exact in the parameters.

With the inner layer ``u = M_hat(q) v + h_hat(q, qdot)`` computing with the
parameters ``pi_hat`` (:func:`~polyrob.uncertainty_set.draw.model_of_set`:
nominal links, the middle payload, the middle viscous friction) and a true
robot ``pi = pi_hat + dpi``, the rigid-body torque is linear in the
parameters, ``tau = Y(q, qdot, a) pi`` (Pinocchio's joint-torque
regressor, viscous friction a column ``qdot_k`` per joint), so the outer
input that gives the acceleration ``a`` is::

    v(x, a) = a + M_hat(q)^-1 Y(q, qdot, a) dpi

and the factor of :mod:`~polyrob.plant.models.inner_factors`,
``K_raw = [B_low^-1 A_low, I - B_low^-1] = -d(v - a)/d[x; a]``, is exactly
linear in ``dpi`` at every point of a task domain (which fixes ``a``):
``K_raw(x) = sum_j dpi_j K_j(x)``.

The set's ``dpi`` lies in a box of a few scalars per source, each with its
exact per-unit direction in parameter space:

* a link given as ``±p`` (mass ``a m``, first moment ``b h``, inertia about
  the CoM ``d I_c``): its parallel-axis term ``m S(c)^T S(c)`` scales by
  ``b^2/a`` (the CoM moves to ``(b/a) c``), which is ``1 + 2 (b - 1) - (a -
  1) + (b - a)^2/a``, so the four scalars are ``a - 1`` (the mass, less the
  parallel-axis term), ``b - 1`` (the first moment, plus twice that term),
  ``d - 1`` within ``±p`` and the curvature ``(b - a)^2/a`` within ``[0,
  4 p^2/(1 - p)]`` (widened to ``±``, 0.044 at 10 %): a box that holds every
  ``(a, b, d)``, with the parallel-axis term moving with the mass and the
  moment as it does (an independent scalar ``b^2/a - 1`` within ``±0.34``
  let it move against them);
* a link given as ten-parameter intervals: one scalar per parameter about
  the box's centre (the model's value);
* the payload in the flange frame: its mass (with its solid body's
  inertia, linear in the mass), its first moment ``m c`` (three scalars)
  and the six entries of ``m S(c)^T S(c)`` over the mass range and the
  centre-of-mass ball or box, moved to the last body by the flange's
  placement (a linear map of the ten parameters);
* each joint's viscous friction over its range.

Each box is symmetric about the model (an asymmetric range is widened to
its larger side).  ``K_j(x)`` is computed exactly at sampled points of the
task domain, uniform points and as many random corners (:func:`_task_samples`;
one true robot per scalar, at its half range).  Forty-odd
scalars repeated ``m`` times are far too many for μ, so the model keeps
``P`` principal directions ``D_k`` of the state columns ``J_j(x)`` in
*matrix space*, over the scalars and the samples, with coefficients
``t_k(u, x) = sum_j u_j <J_j(x), D_k>`` (``u`` the scalars per unit of their
half range), whose range is the largest ``sum_j |<J_j(x), D_k>|`` over the
samples (the payload's part at the points of its physical set) times
:data:`RANGE_MARGIN`.  One direction per *parameter* would leave in the
residual how an off-axis payload's stiffness turns with the wrist over the
task (ur5: the residual's entry bounds fell from 16.7 to 4.6 in Frobenius
norm with 6 directions, and the per-joint PID start's robust-stability μ
from 2.89 to 1.19).  The rest, ``E = sum_j u_j (K_j(x) - sum_k
<J_j(x), D_k> D_k)``, is bounded entrywise by ``sum_j |...|`` at each
sample, its largest value over the samples times :data:`SPREAD_MARGIN`,
carried by the full blocks of
:func:`~polyrob.plant.models.inner_factors.residual_blocks`.  The enclosure
over the task domain is therefore *sampled* (and checked on fresh points
like every model's coverage); over the parameters it is exact: every true
robot of the set is a member with its own ``t_k(u, x)`` (:func:`set_witness`).

Coulomb friction is no Jacobian term: it is said in the set's words and not
carried by this model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio

from polyrob.errors import NotApplicable
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models.inner_links_inertia import (
    exactly_weighted,
    inertia_block,
    inertia_range,
    inertia_ratio,
    residual_norm_bounds,
)
from polyrob.uncertainty_set.payload_body import (
    SECOND_MOMENT_ENTRIES,
    payload_coordinates,
    payload_points,
    payload_sampling_words,
)

__all__ = [
    "SPREAD_MARGIN",
    "DEFAULT_DIRECTIONS",
    "Scalar",
    "applies",
    "set_scalars",
    "payload_set_points",
    "model_samples",
    "SAMPLE_SEED",
    "payload_sampling_words",
    "unit_factors",
    "residual_weighting",
    "factor_of",
    "inner_links_plant",
    "light_model",
    "carried",
    "scalars_of_true",
    "set_witness",
]

#: The sampled residual bound is widened by this factor before it is carried (points between samples).
SPREAD_MARGIN = 1.25
#: The sampled bound of the inertia block is widened by this factor (it varies little over a task's positions).
G_MARGIN = 1.05
#: A scalar whose factor stays below this fraction of the largest scalar's at every sample moves nothing (dropped).
NEGLIGIBLE = 1e-10
#: Principal directions kept as repeated real scalars (the rest is the residual block).
DEFAULT_DIRECTIONS = 6
#: The directions' sampled ranges are widened by this factor (points between samples).
RANGE_MARGIN = 1.1


@dataclass(frozen=True)
class Scalar:
    """One scalar of the set's box: ``dpi = u * half_range * params`` on Pinocchio body ``body`` (or viscous friction on ``joint``)."""

    name: str
    half_range: float
    body: int
    params: np.ndarray
    joint: int = -1


def applies(robot) -> str | None:
    """Why the model does not apply to ``robot`` (``None`` when it does)."""
    if getattr(robot, "uncertainty", None) is None:
        return "inner-links: needs a robot-uncertainty set (--robot-uncertainty FILE or --link-error P)"
    if robot.inner != "computed-torque":
        return (
            f"inner-links: a per-link set is carried for a computed-torque inner layer only, not '{robot.inner}' "
            "(its factor is then not linear in the parameters)"
        )
    return None


def _about_com(theta) -> np.ndarray:
    m, h = theta[0], theta[1:4]
    c = h / m
    shift = m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    return _six(_three(theta[4:]) - shift)


def _three(six) -> np.ndarray:
    ixx, ixy, iyy, ixz, iyz, izz = six
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


def _six(M) -> np.ndarray:
    return np.array([M[0, 0], M[0, 1], M[1, 1], M[0, 2], M[1, 2], M[2, 2]])


def _parallel_axis_range(p: float) -> float:
    """``max (b - a)^2 / a`` for ``a, b`` in ``[1 - p, 1 + p]``: the parallel-axis term's curvature, ``4 p^2 / (1 - p)``."""
    return 4.0 * p * p / (1.0 - p)


def _flange_map(robot) -> np.ndarray:
    """The 10 x 10 matrix taking a body's parameters in the flange frame to the last joint's body frame (linear)."""
    from polyrob.model.payload import flange_frame

    _, placement = flange_frame(robot)
    base = np.array([10.0, 0, 0, 0, 10.0, 0, 10.0, 0, 0, 10.0])

    def moved(theta):
        return np.asarray(placement.act(pinocchio.Inertia.FromDynamicParameters(theta)).toDynamicParameters(), float)

    zero = moved(base)
    return np.column_stack([moved(base + np.eye(10)[k]) - zero for k in range(10)])


def _payload_scalars(robot, body) -> list[Scalar]:
    """The payload's scalars (see the module text), on the last body, about the model's payload."""
    from polyrob.uncertainty_set.draw import payload_middle

    T = _flange_map(robot)
    last = robot.model.njoints - 1
    m0, c0, second0 = payload_middle(body)
    solid = _six(body.rotational_inertia(1.0))
    out = []

    def add(name, lo, hi, flange_params):
        half = max(abs(lo), abs(hi))
        if half > 0:
            out.append(Scalar(f"payload.{name}", half, last, T @ flange_params))

    add("mass", body.mass_lower - m0, body.mass_upper - m0, np.concatenate([[1.0, 0, 0, 0], solid]))
    h_lo, h_hi = body.moment_range()
    for i, axis in enumerate("xyz"):
        add(f"m{axis}", h_lo[i] - m0 * c0[i], h_hi[i] - m0 * c0[i], np.eye(10)[1 + i])
    s_lo, s_hi = body.second_moment_range()
    for k, (i, j) in enumerate(SECOND_MOMENT_ENTRIES):
        add(f"second{i}{j}", s_lo[k] - second0[k], s_hi[k] - second0[k], np.eye(10)[4 + k])
    return out


def set_scalars(loop) -> list[Scalar]:
    """The scalars of the box that holds ``loop``'s set (see the module text), in a fixed order."""
    from polyrob.uncertainty_set.links import link_names

    spec, robot = loop.uncertainty, loop.uncertainty_robot
    explicit = {li.link: li for li in spec.links}
    p = spec.link_error or 0.0
    out = []
    for name, j in link_names(robot).items():
        if name in explicit:
            li = explicit[name]
            half = 0.5 * (np.array(li.upper) - np.array(li.lower))
            out += [Scalar(f"{name}.{k}", float(half[k]), j, np.eye(10)[k]) for k in range(10) if half[k] > 0]
            continue
        if p == 0:
            continue
        theta = np.asarray(robot.model.inertias[j].toDynamicParameters(), float)
        ic = _about_com(theta)
        zero3 = np.zeros(3)
        parallel = theta[4:] - ic  # m S(c)^T S(c): scaled by b^2/a = 1 + 2 (b - 1) - (a - 1) + (b - a)^2 / a
        out += [
            Scalar(f"{name}.mass", p, j, np.concatenate([[theta[0]], zero3, -parallel])),
            Scalar(f"{name}.moment", p, j, np.concatenate([[0.0], theta[1:4], 2.0 * parallel])),
            Scalar(f"{name}.inertia", p, j, np.concatenate([[0.0], zero3, ic])),
            Scalar(f"{name}.parallel", _parallel_axis_range(p), j, np.concatenate([[0.0], zero3, parallel])),
        ]
    if spec.payload is not None and spec.payload.mass_upper > 0:
        out += _payload_scalars(robot, spec.payload)
    for f in spec.friction:
        half = 0.5 * (f.viscous[1] - f.viscous[0])
        if half > 0:
            out.append(Scalar(f"{f.joint}.viscous", half, 0, np.zeros(10), robot.joint_names.index(f.joint)))
    return out


def _moved(loop, scalar: Scalar, sign: float):
    """The inner loop's model robot moved by ``sign`` times the scalar's half range."""
    from dataclasses import replace

    base = loop.model_robot
    model = base.model.copy()
    damping = np.array(base.damping, float)
    if scalar.joint >= 0:
        damping[scalar.joint] += sign * scalar.half_range
        model.damping[:] = damping
    else:
        theta = np.asarray(model.inertias[scalar.body].toDynamicParameters(), float)
        model.inertias[scalar.body] = pinocchio.Inertia.FromDynamicParameters(
            theta + sign * scalar.half_range * scalar.params
        )
    return replace(base, model=model, damping=damping)


def factor_of(loop, true_robot, q, qdot, a) -> np.ndarray:
    """``K_raw = [B_low^-1 A_low, I - B_low^-1]`` (n, m, 3m) of the loop closed on ``true_robot`` at ``(q, qdot, a)``."""
    from dataclasses import replace

    one = replace(loop, true_robot=true_robot, _scenarios=())
    v = one.inverse_dynamics(q, qdot, a)
    A, B = one.jacobians_batch(q, qdot, v)
    m = loop.m
    inverse = np.linalg.inv(B[:, m:])
    return np.concatenate([inverse @ A[:, m:], np.eye(m) - inverse], axis=2)


def unit_factors(loop, scalars, q, qdot, a) -> np.ndarray:
    """``K_j(x)`` per unit of each scalar's half range, (N, n, m, 3m): exact (the factor is linear in ``dpi``).

    Each is the factor of one true robot moved by the scalar's half range
    (the other way, negated, when that would make the body's mass vanish).
    """
    out = []
    for s in scalars:
        sign = 1.0
        if s.joint < 0:
            mass = float(loop.model_robot.model.inertias[s.body].mass)
            sign = 1.0 if mass + s.half_range * s.params[0] > 0.05 * mass else -1.0
        out.append(sign * factor_of(loop, _moved(loop, s, sign), q, qdot, a))
    return np.array(out)


def light_model(loop, domain, *, samples: int = 64) -> UncertainPlant:
    """The model of ``loop``'s set over ``domain`` on a light stand-in for a PLDI (raises :class:`NotApplicable`).

    The build reads of the PLDI only its domain, size and nominal, so a
    stand-in answers in seconds what the bounds would take minutes to reach;
    its ``info`` holds the inertia block's bound (``residual_g_norm``) and
    centre (``K_offset``).
    """
    from types import SimpleNamespace

    q, qdot, a = _domain_points(domain, 1, seed=0)
    A0, B0 = loop.jacobians_batch(q, qdot, loop.inverse_dynamics(q, qdot, a))
    stand_in = SimpleNamespace(m=loop.m, domain=domain, A0=A0[0], B0=B0[0], enclosure="sampled", robot_name=loop.name)
    return inner_links_plant(stand_in, loop, samples=samples)


def carried(loop, domain, *, samples: int = 64) -> str | None:
    """Why the model cannot carry ``loop``'s set over ``domain`` (``None``: it can), measured on :func:`light_model`."""
    try:
        light_model(loop, domain, samples=samples)
    except NotApplicable as exc:
        return str(exc).removeprefix("inner-links: ")
    return None


def _domain_points(domain, n: int, seed):
    q, qdot, a = domain.split(domain.sample_box(n, method="uniform", seed=seed))
    return q, qdot, a


#: The seed of the model's own samples of the task (:func:`model_samples`).
SAMPLE_SEED = (7, 38)


def model_samples(domain, samples: int):
    """The points of ``domain`` the model is built on: :func:`_task_samples` with :data:`SAMPLE_SEED`."""
    return _task_samples(domain, samples, seed=list(SAMPLE_SEED))


def payload_set_points(body, scalars) -> np.ndarray:
    """``(points, I)``: the payload's scalars among ``scalars`` (per unit of their half range) at the points of its physical set."""
    on = [s for s in scalars if s.name.startswith("payload.")]
    points = (payload_coordinates(body, mass, com) for mass, com in payload_points(body))
    return np.array([[c[s.name] / s.half_range for s in on] for c in points])


def _task_samples(domain, n: int, seed):
    """``n`` uniform points of the task domain and ``n`` random corners of it, ``(q, qdot, a)``.

    The directions' reach is largest at the task's corners, which uniform
    points seldom approach: on uniform samples alone, true robots at the
    set's vertices frozen at corners of ur5's task exceeded the sampled
    ranges by up to half (``tests/test_arm_uncertainty_model.py`` checks them).
    """
    points = domain.sample_box(n, method="uniform", seed=seed)
    lower, upper = np.asarray(domain.lower, float), np.asarray(domain.upper, float)
    picks = np.random.default_rng(seed).integers(0, 2, size=(n, len(lower))) == 1
    return domain.split(np.vstack([points, np.where(picks, upper, lower)]))


def inner_links_plant(
    pldi, robot, *, n_directions: int | None = None, samples: int = 256, residual: str = "block"
) -> UncertainPlant:
    """The ``inner-links`` LFT of the module text for ``robot`` (a :class:`~polyrob.model.inner.SetLoopRobot`).

    ``residual="real"`` (the ``inner-links-real`` model): the state columns'
    residual as one real scalar per entry instead of a full complex block
    (:func:`~polyrob.plant.models.inner_factors.factor_lft_plant`).

    Raises
    ------
    NotApplicable
        No robot-uncertainty set, not computed torque (:func:`applies`), not
        a task domain, or ``I - sum t_k G_k`` may be singular.
    """
    from polyrob.plant.models.inner_factors import factor_lft_plant

    f = set_factors(pldi, robot, n_directions=n_directions, samples=samples)
    scalars, q, on_payload, pay, Phi, centres = f.scalars, f.q, f.on_payload, f.pay, f.Phi, f.centres
    n = 2 * pldi.m
    ranges = RANGE_MARGIN * reach_of(f.coeff, on_payload, pay).max(axis=0)
    rest = Phi - np.einsum("jsk,kab->jsab", f.coeff, centres)  # R_j(x) = K_j(x) - sum_k coeff_jk(x) D_k
    spread = SPREAD_MARGIN * entry_bound(rest, on_payload, pay)
    # the acceleration columns: one norm-bounded block, shaped like the set where well posed (first: a refusal is cheap)
    block = inertia_block(f.G_exact, Phi[..., n:], on_payload, pay, f.kappa, ranges, centres, G_MARGIN)
    g_norm, margin = block.g_norm, block.margin
    if margin <= 0.0:
        lo, hi = inertia_range(f.G_exact[~on_payload], f.G_exact[on_payload], pay)
        raise NotApplicable(
            f"inner-links: the relative inertia error is too large for one LFT around the model: its bound "
            f"{g_norm:.3g} (M_hat^1/2 coordinates, over the task's positions) is not below the {margin + g_norm:.3g} "
            f"the centre leaves; the true robots' inertia ranges from {lo:.2g} to {hi:.2g} times the model's "
            "(eigenvalues of M_hat^-1 M, sampled), so the outer loop's gain varies that much"
        )
    block_residual = residual == "block"
    residual_norm = state_residual_norm_bound(rest[..., :n], on_payload, pay, spread[:, :n]) if block_residual else None
    # back to K's own coordinates; the residual stays weighted
    centres = weighted_factor(centres, np.linalg.inv(f.W), f.W)
    inertia = inertia_ratio(robot, scalars, q, _moved)
    names = tuple(f"t{k}" for k in range(len(ranges)))
    return factor_lft_plant(
        pldi,
        "inner-links" if residual == "block" else "inner-links-real",
        names,
        ranges,
        list(centres),
        spread,
        {"PLDI": pldi.enclosure, "factors": "sampled"},
        weighting=f.W,
        g_norm=g_norm,
        g_offset=block.offset,
        g_shape=block.shape,
        residual=residual,
        state_residual_norm=residual_norm,
        info={
            "set": robot.uncertainty.words(),
            "scalars": tuple(s.name for s in scalars),
            "scalar_half_ranges": np.array([s.half_range for s in scalars]),
            "state_directions": f.D,
            "direction_scale": f.scale,
            "samples": int(samples),  # uniform points, and as many corners of the task
            "spread_margin": SPREAD_MARGIN,
            "inertia_block": block.kind,
            "inertia_ball": block.ball,
            "inertia_ratio": inertia,
            **({"payload_sampling": payload_sampling_words(robot.uncertainty.payload)} if on_payload.any() else {}),
        },
    )


@dataclass(frozen=True)
class SetFactors:
    """The set's unit factors ``Phi`` ``(N, S, m, 3m)`` at the samples ``q`` (weighted by ``W``; ``G_exact``,
    ``kappa``: :func:`~polyrob.plant.models.inner_links_inertia.exactly_weighted`), the state columns' principal
    directions ``D`` (as factors: ``centres``) and each scalar's coordinates ``coeff`` ``(N, S, P)`` on them."""

    scalars: list
    q: np.ndarray
    Phi: np.ndarray
    W: np.ndarray
    G_exact: np.ndarray
    kappa: np.ndarray
    on_payload: np.ndarray
    pay: np.ndarray
    D: np.ndarray
    scale: float
    coeff: np.ndarray
    centres: np.ndarray


def set_factors(pldi, robot, *, n_directions: int | None = None, samples: int = 256) -> SetFactors:
    """The set's unit factors at the model's samples and their principal directions (:class:`SetFactors`).

    Raises
    ------
    NotApplicable
        No robot-uncertainty set, not computed torque (:func:`applies`), not
        a task domain, or no uncertain parameter.
    """
    from polyrob.domains.task import TaskDomain

    why = applies(robot)
    if why:
        raise NotApplicable(why)
    if not isinstance(pldi.domain, TaskDomain):
        raise NotApplicable("inner-links: a per-link set needs a task domain (accelerations), not a torque box")
    m, n = pldi.m, 2 * pldi.m
    P = DEFAULT_DIRECTIONS if n_directions is None else int(n_directions)
    scalars = set_scalars(robot)
    if not scalars:
        raise NotApplicable("inner-links: the set has no uncertain parameter")
    q, qdot, a = model_samples(pldi.domain, samples)
    Phi = unit_factors(robot, scalars, q, qdot, a)  # (N, S, m, 3m)
    moves = np.abs(Phi).reshape(len(scalars), -1).max(axis=1)
    keep = moves > NEGLIGIBLE * moves.max()  # a first moment at a joint's axis, a mass on a vertical first joint
    scalars, Phi = [s for s, k in zip(scalars, keep) if k], Phi[keep]
    N = len(scalars)
    P = min(P, N)
    # the payload's scalars range over its physical set (mass x the CoM ball/box), not their box: the box's
    # corners (no mass but a full second moment) are no rigid body and make the inertia indefinite
    on_payload = np.array([s.name.startswith("payload.") for s in scalars])
    pay = payload_set_points(robot.uncertainty.payload, scalars) if on_payload.any() else np.zeros((1, 0))
    # in M_hat^{1/2} coordinates at the task's centre: K -> W K diag(I, W^-1)
    W = residual_weighting(robot, pldi.domain)
    G_exact, kappa = exactly_weighted(robot, q, Phi[..., n:], W)
    Phi = weighted_factor(Phi, W, np.linalg.inv(W))
    # principal directions D_k of the state columns J_j(x) in matrix space, over the scalars and the samples
    # (an off-axis payload's stiffness turns with the wrist: one direction per parameter leaves that turn in
    # the residual); t_k(u, x) = sum_j u_j <J_j(x), D_k>; the acceleration columns G are one norm block (below)
    S = len(q)
    scale = np.sqrt(np.mean(Phi[..., :n] ** 2))
    scale = scale if scale > 0 else 1.0
    flat = Phi[..., :n].reshape(N, S, m * n) / scale
    D = np.linalg.svd(flat.reshape(N * S, m * n), full_matrices=False)[2][:P]  # (P, m n), orthonormal
    coeff = flat @ D.T  # (N, S, P): t_k = sum_j u_j coeff_jk(x)
    centres = np.zeros((P, m, 3 * m))
    centres[..., :n] = (scale * D).reshape(P, m, n)
    return SetFactors(scalars, q, Phi, W, G_exact, kappa, on_payload, pay, D, scale, coeff, centres)


def reach_of(coeff, on_payload, pay) -> np.ndarray:
    """``(S, P)``: the largest ``|t_k|`` at each sample over the set, ``coeff`` ``(N, S, P)`` (the payload on its physical set)."""
    reach = np.abs(coeff[~on_payload]).sum(axis=0)
    if on_payload.any():
        reach = reach + np.abs(np.einsum("pi,isk->psk", pay, coeff[on_payload])).max(axis=0)
    return reach


def entry_bound(rest, on_payload, pay) -> np.ndarray:
    """``|E| <= sum_j |R_j|`` over the box scalars plus the largest ``|sum_i u_i R_i|`` over the payload's physical
    set, entrywise, its largest value over the samples; ``rest`` ``(N, S, m, 3m)``."""
    worst = np.abs(rest[~on_payload]).sum(axis=0)
    if on_payload.any():
        payload_rest = np.abs(pay @ rest[on_payload].reshape(int(on_payload.sum()), -1)).max(axis=0)
        worst = worst + payload_rest.reshape(rest.shape[1:])
    return worst.max(axis=0)


def state_residual_norm_bound(rest, on_payload, pay, spread) -> float | None:
    """The state columns' residual block's norm bound ``rho <= 1`` in the weights the entry radii ``spread`` give it.

    The entry box (:func:`~polyrob.plant.models.axes.residual_of_radii`: a
    Frobenius covering, ``rho = 1``) takes each entry's largest value over the
    samples, which no single sample reaches.  At each sample ``x`` the
    residual ``E(u, x) = sum_j u_j R_j(x)`` in those weights is bounded for
    every ``u`` of the box by the dilation bound of
    :func:`~polyrob.plant.models.inner_links_inertia.residual_norm_bounds`
    (the payload's scalars at the points of its physical set; at most the
    triangle inequality's ``sum_j ||R_j(x)||``): sampled over the task like
    the entries, exact over the box scalars.  Its largest value over the
    samples times :data:`SPREAD_MARGIN`, capped at 1.  ``rest``:
    ``(N, S, m, 2m)`` (weighted); ``spread``: ``(m, 2m)``.
    """
    from polyrob.plant.models.axes import residual_of_radii

    _, _, gains = residual_of_radii(spread)
    rows, cols = gains["residual_rows"], gains["residual_cols"]
    if not len(rows):
        return None
    scaled = rest[:, :, rows][:, :, :, cols] / gains["W_l"][:, None] / gains["W_r"][None, :]  # (N, S, r, c)
    bound = residual_norm_bounds(scaled[~on_payload], scaled[on_payload], pay)
    return float(min(1.0, SPREAD_MARGIN * bound.max()))


def residual_weighting(robot, domain) -> np.ndarray:
    """``W = M_hat^{1/2}`` at the centre of the task domain (symmetric square root)."""
    centre = 0.5 * (np.asarray(domain.lower, float) + np.asarray(domain.upper, float))
    M = robot.model_robot.mass_matrix(centre[: robot.m])
    values, vectors = np.linalg.eigh(0.5 * (M + M.T))
    return (vectors * np.sqrt(values)) @ vectors.T


def weighted_factor(K, W, W_inv) -> np.ndarray:
    """``W K diag(I, W_inv)`` on the last two axes of ``K`` (``... x m x 3m``)."""
    m = W.shape[0]
    out = np.einsum("ab,...bc->...ac", W, K)
    out[..., 2 * m :] = np.einsum("...ab,bc->...ac", out[..., 2 * m :], W_inv)
    return out


def scalars_of_true(robot, true) -> np.ndarray:
    """The scalars ``u`` (per unit of their half range) of a drawn :class:`~polyrob.uncertainty_set.draw.TrueRobot`.

    Inside the set every ``|u_j| <= 1``; ``dpi = sum_j u_j half_j params_j`` reproduces its parameters.
    """
    from polyrob.uncertainty_set.links import link_names

    spec, base = robot.uncertainty, robot.uncertainty_robot
    explicit = {li.link: li for li in spec.links}
    values = {}
    for name, j in link_names(base).items():
        drawn = np.asarray(true.link_parameters[name], float)
        if name in explicit:
            centre = explicit[name].centre
            for k in range(10):
                values[f"{name}.{k}"] = drawn[k] - centre[k]
            continue
        theta = np.asarray(base.model.inertias[j].toDynamicParameters(), float)
        a = drawn[0] / theta[0]
        k = int(np.argmax(np.abs(theta[1:4])))
        b = drawn[1 + k] / theta[1 + k] if theta[1 + k] else 1.0
        ic, ic_drawn = _about_com(theta), _about_com(drawn)
        k6 = int(np.argmax(np.abs(ic)))
        d = ic_drawn[k6] / ic[k6]
        values.update({f"{name}.mass": a - 1, f"{name}.moment": b - 1, f"{name}.inertia": d - 1,
                       f"{name}.parallel": (b - a) ** 2 / a})  # fmt: skip
    if spec.payload is not None:
        values.update(payload_coordinates(spec.payload, true.payload_mass, true.payload_com))
    model_damping = np.asarray(robot.model_robot.damping, float)
    for k, joint in enumerate(base.joint_names):
        values[f"{joint}.viscous"] = true.viscous[k] - model_damping[k]
    return np.array([values[s.name] / s.half_range for s in set_scalars(robot)])


def set_witness(unc: UncertainPlant, robot, true, q, qdot, a) -> float:
    """The largest scaled residual of ``true`` at ``(q, qdot, a)`` with its own ``t_k(u, x)``: ``<= 1`` is membership.

    ``t_k = sum_j u_j <J_j(x), D_k> = <J(x), D_k>`` (the factor is linear in
    the scalars ``u``: its weighted state columns ``J(x)`` projected on the
    directions) must also lie within the directions' ranges, which the
    samples bound (and :data:`RANGE_MARGIN` widens); the larger of the two
    ratios is returned.
    """
    from polyrob.plant.models.factor_membership import reached_entries, scaled_residual_norm

    W = unc.info["residual_weighting"]
    m = W.shape[0]
    K_all = factor_of(robot, true.robot, q, qdot, a)
    J = weighted_factor(K_all, W, np.linalg.inv(W))[..., : 2 * m].reshape(len(q), -1) / unc.info["direction_scale"]
    t_all = J @ unc.info["state_directions"].T  # (points, P)
    worst = float(np.max(np.abs(t_all) / unc.info["theta_range"]))
    reached = reached_entries(unc)
    for K, t in zip(K_all, t_all):
        worst = max(worst, scaled_residual_norm(unc, K, t, 1e-9, reached))
    return worst
