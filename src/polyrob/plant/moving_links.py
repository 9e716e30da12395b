"""``inner-links-moving``: a per-link set's computed-torque loop split into what stays and what moves.

The ``inner-links`` model (:mod:`polyrob.plant.models.inner_links`) holds
every *frozen* robot of the set: at each state ``x`` a true robot is a
member with its own direction scalars ``t_k(u, x)`` and residuals.  A moving
arm keeps its parameters ``u`` (its links, its instrument) while its state
moves, and a certificate that lets every block vary at any rate pays for
variation that the parameters never have.  This model splits each true
robot's factor at the task's centre ``x_c``::

    K(u, x) = K_0 + sum_k t_k(u) K_k,c + E_c(u) + E_m(u, x)

* ``sum_k t_k(u) K_k,c``: by default (``exact=True``) the set's own link
  and joint scalars, ``t_k = u_k`` within ``±1`` and ``K_k,c = K_k(x_c)``
  their factors at the centre, each a real block repeated as often as its
  factor's rank (a wrist's mass moves two joints' loops, not six): the
  links' part of the factor at the centre is then *exact*, with no
  direction box and no residual.  With ``exact=False`` the ``inner-links``
  directions instead, ``t_k(u) = <J(u, x_c), D_k>`` within their reach
  there.  **Constant** while the robot moves;
* ``E_c(u)``: the rest of the factor at the centre (the instrument's part
  with ``exact``, whose physical set -- a mass times a centre-of-mass ball
  -- no box of its ten parameters holds without members that are no rigid
  body), the state columns' full block (its norm bound at ``x_c``) and the
  inertia block at ``q_c`` (shaped like the set): **constant** too, so μ's
  frequency-dependent scalings are valid for them.  With
  ``exact_payload`` the instrument's part is instead the exact LFT in its
  mass and centre of mass of :mod:`polyrob.plant.payload_lft` (four
  repeated reals; the centre of mass over the box that holds its set), and
  no constant full block is left;
* ``E_m(u, x) = K(u, x) - K(u, x_c)``: the motion, bounded entrywise over
  the task's samples (``SPREAD_MARGIN`` wider) and carried by two full
  blocks (state and acceleration columns), marked ``moving``: the only
  blocks that vary in time.

:func:`polyrob.analysis.lpv.constant.constant_parameter_certificate` merges
only the ``moving`` blocks with the performance channels (a constant
scaling), so the certificate covers every motion of the state at any rate
with the parameters constant, paying for time variation only on what the
motion moves.  The blocks overlap (``E_c`` and ``E_m`` on the same
entries), so membership is no test on a Jacobian alone: it needs the true
robot, whose ``t`` (its own parameters' values, :func:`scalar_values`, or
the directions' values of its factor) and ``E_c`` come from its factor at the centre and
``E_m`` from its factor at each state (:func:`motion_witness`), and the
coverage is measured that way on fresh true robots of the set at fresh
points of the task (:func:`motion_coverage`).  Over the task the enclosure
is sampled (the samples of ``inner-links``), over the parameters exact.

Why here and not in :mod:`polyrob.plant.models`: it is that package's
``inner-links`` model re-cut for the moving robot, built from the same
factors (:func:`~polyrob.plant.models.inner_links.set_factors`).
"""

from __future__ import annotations

import numpy as np

from polyrob.plant.lftplant import UncertainPlant

__all__ = ["moving_links_plant", "motion_witness", "motion_coverage", "scalar_units", "scalar_values", "task_centre"]


def task_centre(domain):
    """``(q, qdot, a)`` of the task box's centre, one point each ``(1, m)``."""
    lower, upper = np.asarray(domain.lower, float), np.asarray(domain.upper, float)
    return domain.split(((lower + upper) / 2)[None, :])


def moving_links_plant(
    pldi,
    robot,
    *,
    n_directions: int | None = None,
    samples: int = 256,
    exact: bool = True,
    motion_balls: bool = True,
    exact_payload: bool = False,
) -> UncertainPlant:
    """The ``inner-links-moving`` LFT of the module text for ``robot`` (a :class:`~polyrob.model.inner.SetLoopRobot`).

    ``exact``: the link and joint scalars themselves at the centre (else
    the ``inner-links`` directions); ``motion_balls``: the motion blocks'
    balls shrunk to the motion's norm bound (else their entry boxes'); both
    as the module text says, the alternatives kept for comparison
    (``benchmarks/moving_links_models.py``).  ``exact_payload`` (with
    ``exact``): the instrument's part at the centre as the exact LFT in its
    mass and centre of mass of :mod:`polyrob.plant.payload_lft` (its
    centre of mass over the box that holds its ball), else in the constant
    state and inertia blocks.

    The inertia block at the centre is shaped like the set there; whether
    ``I - G`` stays invertible with the motion's acceleration block on top
    is left to μ, whose bound at every frequency (``ω = ∞`` included)
    proves the loop well posed for every member.

    Raises
    ------
    NotApplicable
        What :func:`~polyrob.plant.models.inner_links.set_factors` refuses.
    """
    from polyrob.plant.models import inner_links as links
    from polyrob.plant.models.inner_factors import factor_lft_plant
    from polyrob.plant.models.inner_links_inertia import exactly_weighted, inertia_block

    f = links.set_factors(pldi, robot, n_directions=n_directions, samples=samples)
    payload = None
    m, n, N = pldi.m, 2 * pldi.m, len(f.scalars)
    centre = task_centre(pldi.domain)
    raw = links.unit_factors(robot, f.scalars, *centre)  # (N, 1, m, 3m)
    G_exact, kappa = exactly_weighted(robot, centre[0], raw[..., n:], f.W)
    at_centre = links.weighted_factor(raw, f.W, np.linalg.inv(f.W))
    if exact:  # each link's and joint's scalar its own real block, its factor at the centre exact
        own = ~f.on_payload
        names = tuple(s.name for s, o in zip(f.scalars, own) if o)
        ranges, centres = np.ones(len(names)), at_centre[own, 0]
        rest = np.where(own[:, None, None, None], 0.0, at_centre)  # the payload's part: the blocks
        flat = np.zeros((1, m, 3 * m))  # the inertia block's own well-posedness at its centre; μ at ω = ∞ the rest
        if exact_payload and not own.all():  # ... or the payload's exact LFT instead
            payload, rest, block = _payload_at_centre(robot, f, raw), np.zeros_like(rest), None
        else:
            block = None if own.all() else inertia_block(
                np.where(own[:, None, None, None], 0.0, G_exact), rest[..., n:], f.on_payload, f.pay, kappa,
                np.zeros(1), flat, links.G_MARGIN)  # fmt: skip
    else:
        coeff = at_centre[..., :n].reshape(N, 1, m * n) / f.scale @ f.D.T  # (N, 1, P): t_k(u) = sum_j u_j coeff_jk
        ranges = links.RANGE_MARGIN * links.reach_of(coeff, f.on_payload, f.pay)[0]
        names, centres = tuple(f"t{k}" for k in range(len(ranges))), f.centres
        rest = at_centre - np.einsum("jsk,kab->jsab", coeff, f.centres)
        block = inertia_block(G_exact, at_centre[..., n:], f.on_payload, f.pay, kappa, ranges, f.centres,
                              links.G_MARGIN)  # fmt: skip
    spread = links.SPREAD_MARGIN * links.entry_bound(rest, f.on_payload, f.pay)
    norm = links.state_residual_norm_bound(rest[..., :n], f.on_payload, f.pay, spread[:, :n]) if spread.any() else None
    moved = f.Phi - at_centre
    motion = links.SPREAD_MARGIN * links.entry_bound(moved, f.on_payload, f.pay)
    # the entry box of each motion block holds norms no sample reaches: its norm bound over the set at each
    # sample (as the centre's state block has it) shrinks its ball
    rho = [links.state_residual_norm_bound(moved[..., c], f.on_payload, f.pay, motion[:, c]) or 1.0
           for c in (slice(0, n), slice(n, None))] if motion_balls else [1.0, 1.0]  # fmt: skip
    return factor_lft_plant(
        pldi,
        "inner-links-moving",
        tuple(name.replace(".", "_") for name in names),  # signal names take no dot
        ranges,
        list(links.weighted_factor(centres, np.linalg.inv(f.W), f.W)),
        spread,
        {"PLDI": pldi.enclosure, "factors": "sampled"},
        weighting=f.W,
        g_norm=0.0 if block is None else block.g_norm,
        g_offset=0.0 if block is None else block.offset,
        g_shape=None if block is None else block.shape,
        state_residual_norm=norm,
        motion_spread=motion,
        low_rank=exact,
        motion_norms=tuple(rho),
        payload=payload,
        info={
            "payload_lft": payload,
            "exact_scalars": names if exact else (),
            "exact_units": scalar_units(robot) if exact else (),
            "set": robot.uncertainty.words(),
            "scalars": tuple(s.name for s in f.scalars),
            "state_directions": f.D,
            "direction_scale": f.scale,
            "samples": int(samples),
            "spread_margin": links.SPREAD_MARGIN,
            "inertia_block": ("none (no payload)" if payload is None else "none (the payload's exact LFT)")
            if block is None
            else block.kind,
            "inertia_ball": 0.0 if block is None else block.ball,
            "motion_norm": float(np.linalg.norm(motion)),
            "motion_ball": tuple(float(r) for r in rho),
            "centre": tuple(np.asarray(x, float)[0] for x in centre),
        },
    )


def _payload_at_centre(robot, f, raw):
    """The payload's part of the factor at the task's centre as its exact LFT (:func:`~polyrob.plant.payload_lft.payload_lft`).

    ``raw`` ``(N, 1, m, 3m)``: every scalar's factor per unit at the centre,
    the payload's scalars marked by ``f.on_payload``.
    """
    from polyrob.plant.payload_lft import payload_lft
    from polyrob.uncertainty_set.payload_body import payload_coordinates

    body = robot.uncertainty.payload
    on = [s for s, o in zip(f.scalars, f.on_payload) if o]
    per_unit = raw[f.on_payload, 0]

    def value(mass, com):
        coords = payload_coordinates(body, mass, com)
        return np.tensordot(np.array([coords[s.name] / s.half_range for s in on]), per_unit, axes=1)

    return payload_lft(value, body)


def motion_witness(unc: UncertainPlant, robot, true, q, qdot, a) -> np.ndarray:
    """Per point ``(q, qdot, a)``, the largest scaled part of the drawn robot ``true`` in the model: ``<= 1`` is membership.

    ``robot`` is the set's loop, ``true`` one robot of the set (a
    :class:`~polyrob.uncertainty_set.draw.TrueRobot`); its scalars (its own
    parameters' values, :func:`scalar_values`, or the directions' values of
    its factor at the task's centre) and ``E_c`` come from its factor at the task's centre
    (``unc.info["centre"]``), the same at every point; ``E_m`` is its factor
    at the point less that at the centre.  Each must lie in its blocks'
    balls (``t`` within the ranges); an entry no block of its kind reaches
    must match to ``1e-9`` of the factor's size.
    """
    from polyrob.plant.models.inner_links import factor_of, weighted_factor

    m, info = len(unc.info["centre"][0]), unc.info
    W = info["residual_weighting"]
    true_robot = true.robot
    K_c = factor_of(robot, true_robot, *(x[None, :] for x in info["centre"]))[0]
    if info.get("exact_scalars"):  # the robot's own scalars, from its parameters
        t = scalar_values(info["exact_units"], info["exact_scalars"], robot, true)
        r = np.asarray(info["theta_range"], float)
        t = np.where(np.abs(t) <= r * (1 + 1e-9), np.clip(t, -r, r), t)  # a vertex's round-off
    else:
        J = weighted_factor(K_c[None], W, np.linalg.inv(W))[0, :, : 2 * m].ravel() / info["direction_scale"]
        t = info["state_directions"] @ J
    E_c = K_c - info["K_offset"] - np.tensordot(t, info["K_centres"], axes=1)
    ranges = np.asarray(info["theta_range"], float)
    over = np.divide(np.abs(t), ranges, out=np.where(np.abs(t) > 0, np.inf, 0.0), where=ranges > 0)
    payload = info.get("payload_lft")
    if payload is not None:  # its exact part (its offset is in K_offset already) and its scalars within ±1
        E_c = E_c - (payload.value(true.payload_mass, true.payload_com) - payload.offset)
        over = np.r_[over, np.abs(payload.units(true.payload_mass, true.payload_com)) / (1 + 1e-9)]
    size = 1.0 + float(np.abs(K_c).max())
    fixed = max([float(over.max(initial=0.0))] + _norms(unc, E_c, False, size))
    return np.array([max([fixed] + _norms(unc, K - K_c, True, size)) for K in factor_of(robot, true_robot, q, qdot, a)])


def scalar_units(robot) -> tuple:
    """The set's link and joint scalars as the model keeps them for :func:`scalar_values`: per scalar its name,
    body, joint, the range's middle (viscous friction) and its change of the ten parameters per unit."""
    from polyrob.plant.models.inner_links import set_scalars

    middle = {f.joint: 0.5 * (f.viscous[0] + f.viscous[1]) for f in robot.uncertainty.friction}
    joints = robot.uncertainty_robot.joint_names
    return tuple(
        {"name": s.name, "body": s.body, "joint": s.joint, "half": s.half_range,
         "middle": middle[joints[s.joint]] if s.joint >= 0 else 0.0, "unit": s.half_range * np.asarray(s.params)}
        for s in set_scalars(robot)
        if not s.name.startswith("payload.")
    )  # fmt: skip


def scalar_values(units, names, robot, true) -> np.ndarray:
    """The values of the scalars ``names`` (per unit of their half range, :func:`scalar_units`) of a drawn robot.

    A link's scalars span its drawn parameters' change from the model's
    (the set's box is built so), solved for by least squares on that link's
    ten parameters with all its scalars (the model drops those that do not
    move the loop); a joint's viscous scalar is its drawn coefficient less
    the range's middle.  ``robot``: the set's loop (its model's links: the
    URDF's, or an interval's centre, as the inner layer computes with).
    """
    from polyrob.uncertainty_set.links import link_names

    bodies = {j: name for name, j in link_names(robot.uncertainty_robot).items()}
    explicit = {li.link: np.asarray(li.centre, float) for li in robot.uncertainty.links}  # the model's own links
    values, by_body = {}, {}
    for s in units:
        if s["joint"] >= 0:
            values[s["name"]] = (float(true.viscous[s["joint"]]) - s["middle"]) / s["half"]
        else:
            by_body.setdefault(s["body"], []).append(s)
    for body, group in by_body.items():
        nominal = explicit.get(bodies[body])
        if nominal is None:
            nominal = np.asarray(robot.uncertainty_robot.model.inertias[body].toDynamicParameters(), float)
        change = np.asarray(true.link_parameters[bodies[body]], float) - nominal
        solved = np.linalg.lstsq(np.column_stack([s["unit"] for s in group]), change, rcond=None)[0]
        values.update({s["name"]: float(u) for s, u in zip(group, solved)})
    return np.array([values[name] for name in names])


def _norms(unc, E, moving: bool, size: float) -> list[float]:
    """The scaled norms of ``E`` in the blocks whose ``moving`` flag is ``moving``, and its mismatch off them
    relative to ``1e-9 size`` (the factor's)."""
    from polyrob.plant.models.factor_membership import scaled_residuals

    reached = np.zeros(E.shape, bool)
    for b in unc.info["residual_blocks"]:
        if bool(b.get("moving", False)) is moving:
            reached[np.ix_(b["rows"], b["cols"])] = True
    mismatch = np.abs(E[~reached]).max(initial=0.0) / (1e-9 * size)
    return [mismatch] + [float(np.linalg.norm(S, 2)) for S in scaled_residuals(unc, E, moving)]


def motion_coverage(unc: UncertainPlant, robot, domain, n: int = 2000, *, points: int = 10, seed: int = 12345) -> float:
    """The fraction of ``n`` (true robot, point) pairs that :func:`motion_witness` finds members.

    ``n // points`` true robots drawn anew from ``robot``'s set, half inside
    it at uniform points of ``domain``, half at its vertices at random
    corners of the task (:data:`~polyrob.uncertainty_set.draw.EXTREME_SHARE`,
    as :func:`polyrob.plant.coverage.coverage_fraction` draws them).
    """
    from polyrob.uncertainty_set.draw import EXTREME_SHARE, at_vertices, draw_true_robot

    rng = np.random.default_rng([seed, 38])
    robots = max(1, int(n) // points)
    inside = robots - at_vertices(robots, EXTREME_SHARE)
    lower, upper = np.asarray(domain.lower, float), np.asarray(domain.upper, float)
    found = []
    for k in range(robots):
        true = draw_true_robot(robot.uncertainty_robot, robot.uncertainty, rng, extreme=k >= inside)  # as robot.drawn
        if k < inside:
            x = domain.sample_box(points, method="uniform", seed=int(rng.integers(2**31)))
        else:
            x = np.where(rng.integers(0, 2, size=(points, len(lower))) == 1, upper, lower)
        found.append(motion_witness(unc, robot, true, *domain.split(x)) <= 1.0)
    return float(np.concatenate(found).mean())
