"""The PLDI: every Jacobian the robot can have inside the domain, bounded.

:func:`bound_pldi` takes a robot and a :class:`~polyrob.domains.torque_box.Domain` and
returns a :class:`PLDI`: the nominal pair ``(A0, B0)`` at an equilibrium, the
interval of every entry of ``A`` and ``B`` (the paper's eq. 9 table), the
witnesses where each bound is attained, and a polytope (half-spaces, and
vertices where the dimension allows) that holds every Jacobian found.

How the bounds are found (``enclosure = "sampled"``):

1. position coordinates the dynamics do not depend on are detected and dropped;
2. the remaining positions are sampled with a scrambled Sobol' design plus the
   corners of their box; for each position the extremes over the
   velocity/torque box are computed exactly, or attained and nearly always
   exact beyond four joints (:mod:`polyrob.bounds.extremes`), on the first
   true robot of an inner loop's several (the same arm, masses a few %
   apart: their peaks lie at the same positions; every true robot is taken
   from step 4 on); the first samples also check that ``M(q)`` is positive
   definite;
3. a dense uniform screen of the whole domain (one Jacobian per point) adds
   starts near narrow peaks the design straddles;
4. each extreme is searched by L-BFGS-B over positions, velocities and torques
   from the highest peaks of the sampled landscape and the best screened
   points, then from the other directions' witnesses where these are higher
   (the entries share their sharp peaks, near singular mass matrices), then
   from a second screen drawn around all witnesses; fresh designs verify the
   result (every true robot; a position whose cheap upper bound cannot beat
   a support value is not maximised); the widening all this brought is reported;
5. the support values along ``+-e_i`` (the intervals) and along the principal
   directions of the Jacobian cloud give the polytope's half-spaces;
   linear programs (HiGHS) give its bounding box, an interior point and,
   in up to :data:`VERTEX_MAX_DIM` reduced dimensions, its vertices;
6. fresh random points of the domain check the coverage (it must be 1.0).

What to do is a :class:`~polyrob.bounds.options.BoundOptions` (its
:class:`~polyrob.bounds.options.SearchEffort` the effort of steps 2-4), or
its fields as flat keywords.

With ``certify=True`` the intervals are replaced by a guaranteed enclosure
computed by interval arithmetic (:mod:`polyrob.bounds.certified.enclosure`); ``enclosure`` is
then ``"certified"``, and every entry whose certified interval has a non-zero
width is a varying entry (whatever the samples say), so that the uncertain
plant built from the PLDI covers the whole proved box.

The parallel steps run on one :class:`~polyrob.bounds.parallel.WorkerPool`
(spawned processes) per call; Ctrl-C stops them at once.

Examples
--------
>>> from polyrob import load_robot, Domain, bound_pldi
>>> robot = load_robot("planar_2r")
>>> pldi = bound_pldi(robot, Domain.from_robot(robot, u_max=0.0), samples=256, coverage=500, progress=False)
>>> pldi.enclosure, pldi.coverage
('sampled', 1.0)
>>> lo, hi = pldi.interval("b31")
>>> round(lo, 4), round(hi, 4)
(0.0286, 0.0312)
"""

from __future__ import annotations

import sys
import time

import numpy as np

from polyrob.bounds import search
from polyrob.bounds.options import BoundOptions, SearchEffort
from polyrob.bounds.parallel import WorkerPool, available_cores
from polyrob.bounds.pldi_result import PLDI, entry_name
from polyrob.bounds.polytope import COVERAGE_RTOL, VERTEX_MAX_DIM, Polytope, build_polytope, principal_directions
from polyrob.bounds.supports import support_values
from polyrob.domains.torque_box import Domain
from polyrob.errors import ArgumentError, BoundsError, CertificationError
from polyrob.progress import report as job_report
from polyrob.progress import span

__all__ = [
    "PLDI",
    "BoundOptions",
    "SearchEffort",
    "Polytope",
    "bound_pldi",
    "coverage_fraction",
    "entry_name",
    "VERTEX_MAX_DIM",
    "PRINCIPAL_DIRECTIONS",
]

#: Principal directions of the Jacobian cloud searched besides +-e_i.
PRINCIPAL_DIRECTIONS = 12
#: With ``workers=None``, robots whose dynamics depend on at most this many
#: positions are bounded in one process: starting workers costs more than
#: it saves there.
SERIAL_MAX_ACTIVE_POSITIONS = 2


def _nominal(robot, domain: Domain, nominal):
    m = robot.m
    if isinstance(nominal, str) and nominal == "equilibrium":
        # a task domain's reference pose, else q = 0 clipped into the box
        q0 = np.array(getattr(domain, "pose", np.clip(np.zeros(m), domain.q_lower, domain.q_upper)), float)
        qd0 = np.zeros(m)
        # u0 holds the arm still: the gravity torque g(q0) = -M(q0) qddot(q0, 0, 0)
        u0 = -robot.mass_matrix(q0) @ robot.acceleration(q0, qd0, np.zeros(m))
        u0[np.abs(u0) < 1e-12] = 0.0
        return {"q": q0, "qdot": qd0, "u": u0}
    if isinstance(nominal, str) and nominal == "midpoint":
        return None
    if isinstance(nominal, dict):
        return {k: np.asarray(nominal.get(k, np.zeros(m)), float) for k in ("q", "qdot", "u")}
    raise BoundsError(f"unknown nominal '{nominal}': use 'equilibrium', 'midpoint' or a dict with q, qdot, u")


def bound_pldi(robot, domain: Domain | None = None, *, options: BoundOptions | None = None, **keywords) -> PLDI:
    """Bound the Jacobians of ``robot`` over ``domain``: a :class:`PLDI`.

    Parameters
    ----------
    robot : Manipulator
    domain : Domain or TaskDomain, optional
        Defaults to ``Domain.from_robot(robot)``.  Over a
        :class:`~polyrob.domains.task.TaskDomain` the search moves in
        ``(q, qdot, qddot)`` and evaluates the Jacobians at the torques of
        the inverse dynamics; the witnesses are given as ``(q, qdot, u)``.
    options : BoundOptions, optional
        The search's effort (:class:`~polyrob.bounds.options.SearchEffort`:
        ``samples``, ``refine``, ``verify_rounds``, ``starts_per_direction``,
        ``screen``, ``screen_starts``, ``seed``), the nominal pair, the
        coverage check, ``certify`` (the intervals proved by interval
        arithmetic) and its ``certify_options``, ``describe_polytope``,
        ``workers`` (default: one for robots whose dynamics depend on at
        most :data:`SERIAL_MAX_ACTIVE_POSITIONS` positions, else every
        available core) and ``progress``.
    **keywords
        Any of those fields, flat (:meth:`BoundOptions.build`): e.g.
        ``bound_pldi(robot, samples=256, coverage=0)``.

    Raises
    ------
    ArgumentError
        A negative or zero count, an unknown option.
    BoundsError
        The domain is not the robot's, ``M(q)`` is not positive definite at a
        sampled position, or the polytope's linear programs fail.
    CertificationError
        With ``certify=True``, when no guaranteed enclosure can be produced.
    """
    t_start = time.perf_counter()
    opts = BoundOptions.build(options, **keywords)
    if domain is None:
        domain = Domain.from_robot(robot)
    if tuple(domain.joint_names) != tuple(robot.joint_names):
        raise BoundsError(f"the domain's joints {domain.joint_names} are not the robot's {robot.joint_names}")
    progress = sys.stderr.isatty() if opts.progress is None else opts.progress
    with span(0.0, 0.8 if opts.certify else 0.0):  # a proof takes most of the stage; the sampling the rest
        factors = (
            _proved_factors(robot, domain, opts, progress) if opts.certify and _factor_task(robot, domain) else None
        )
        # first: it gives up at once
        proved = _certified(robot, domain, opts, progress) if opts.certify and factors is None else None
    problem = search.Problem(robot, domain)
    rng = np.random.default_rng(opts.seed)
    cloud, index, varying = _varying_entries(problem, proved, opts.seed)
    dropped = search.dropped_positions(problem, rng)
    active_q = robot.m - len(dropped)
    effort = opts.search.sized(active_q)
    q = search.position_design(problem, effort.samples, dropped, effort.seed)
    workers = opts.workers or (1 if active_q <= SERIAL_MAX_ACTIVE_POSITIONS else available_cores())
    directions, scale, axes = _search_directions(cloud, len(index))
    with WorkerPool(problem, workers) as pool, span(0.8 if opts.certify else 0.0, 1.0):
        values, witnesses, sampled_width, stages, rounds, t_sample, t_refine = support_values(
            problem, q, directions, index, dropped, pool, progress, effort
        )
        fallback = pool.fallback
    k = len(index)
    upper, lower = values[:k], -values[k : 2 * k]
    refinement = np.where(sampled_width > 0, (upper - lower) / np.where(sampled_width > 0, sampled_width, 1) - 1.0, 0.0)
    polytope = build_polytope(directions, values, 2 * k, cloud, scale, axes, rng, describe=opts.describe_polytope)
    notes = [] if fallback is None else [fallback]
    if factors is not None:
        matrices, cert_info = _interval_matrices(robot, domain, index, lower, upper, opts.seed), factors
        at_limit = (
            ""
            if factors["done"] >= 1.0
            else f", at the work limit: {100 * factors['done']:.1f} % of its refinement done"
        )
        notes.append(
            "the factor ranges of the inner loop are proved by interval arithmetic over the task box "
            f"({factors['boxes']} boxes{at_limit}); the A, B intervals themselves are sampled"
        )
    elif proved is None:
        matrices, cert_info = _interval_matrices(robot, domain, index, lower, upper, opts.seed), None
    else:
        matrices, cert_info = _proved_matrices(problem, proved, index, lower, upper), proved[4]
        notes.append("the polytope's half-spaces are sampled supports; the intervals are certified")
    A_lower, A_upper, B_lower, B_upper = matrices
    point = _nominal(robot, domain, opts.nominal)
    if point is None:
        A0, B0 = 0.5 * (A_lower + A_upper), 0.5 * (B_lower + B_upper)
    else:
        A0, B0 = robot.jacobians(point["q"], point["qdot"], point["u"])
        point = {key: v.tolist() for key, v in point.items()}

    result = PLDI(
        robot_name=robot.name,
        robot_source=robot.source,
        source_robot=robot,
        domain=domain,
        nominal_point=point,
        A0=A0,
        B0=B0,
        A_lower=A_lower,
        A_upper=A_upper,
        B_lower=B_lower,
        B_upper=B_upper,
        entries=tuple(entry_name("AB"[mt], r, c, 2 * robot.m) for mt, r, c in index),
        entry_index=index,
        witness_lower=domain.points(witnesses[k : 2 * k]) if k else witnesses[k : 2 * k],
        witness_upper=domain.points(witnesses[:k]) if k else witnesses[:k],
        polytope=polytope,
        enclosure="sampled" if proved is None else "certified",
        coverage=float("nan"),
        coverage_points=0,
        refinement=refinement,
        dropped_q=dropped,
        info={
            "samples": int(len(q)),
            "workers": int(workers),
            "seconds_sampling": round(t_sample, 3),
            "seconds_refining": round(t_refine, 3),
            "seconds_stages": {key: round(v, 3) for key, v in stages.items()},
            "seconds_total": None,
            "max_refinement": float(refinement.max()) if k else 0.0,
            "verification_rounds": rounds,
            "certify": cert_info,
            "notes": notes,
        },
        robot_locked=tuple(getattr(robot, "locked", ())),
    )
    if opts.coverage:
        frac = coverage_fraction(result, robot, opts.coverage, seed=opts.seed + 1)
        object.__setattr__(result, "coverage", frac)
        object.__setattr__(result, "coverage_points", int(opts.coverage))
    result.info["seconds_total"] = round(time.perf_counter() - t_start, 3)
    return result


def _varying_entries(problem, proved, seed: int):
    """``(cloud, index, varying)``: the pilot cloud of the varying entries, their index and mask.

    Every entry the proof lets vary is a parameter of the plant, even when
    the pilot samples saw it constant.
    """
    pilot_vals, varying = search.pilot(problem, seed)
    if proved is not None:
        c_lo = problem.entries_from(proved[0][None], proved[2][None])[0]
        c_hi = problem.entries_from(proved[1][None], proved[3][None])[0]
        varying = varying | (c_hi > c_lo)
    return pilot_vals[:, varying], problem.all_index[varying], varying


def _search_directions(cloud, k: int):
    """``(directions, scale, axes)``: ``±e_i`` and ``±`` the cloud's principal directions (in units of its spread)."""
    spread = cloud.max(axis=0) - cloud.min(axis=0)
    # entries constant over the cloud (certified ones may be) take no part in
    # the principal directions: a tiny scale would blow their rounding up
    moving = spread > 1e-12 * np.maximum(1.0, np.abs(cloud).max(axis=0, initial=0.0))
    scale = np.where(moving, spread, 1.0)
    axes = np.zeros((k, 0))
    if moving.any():
        sub = principal_directions(cloud[:, moving], scale[moving])
        axes = np.zeros((k, sub.shape[1]))
        axes[moving] = sub
    pcs = axes[:, :PRINCIPAL_DIRECTIONS].T
    directions = np.vstack([np.eye(k), -np.eye(k), pcs / scale, -pcs / scale]) if k else np.zeros((0, 0))
    return directions, scale, axes


def _interval_matrices(robot, domain, index, lower, upper, seed: int):
    """``(A_lower, A_upper, B_lower, B_upper)``: the sampled intervals, constant entries from any point of the domain."""
    A_any, B_any = robot.jacobians_batch(*domain.sample(1, method="uniform", seed=seed))
    A_lower, A_upper, B_lower, B_upper = A_any[0].copy(), A_any[0].copy(), B_any[0].copy(), B_any[0].copy()
    for (mat, r, c), lo_, hi_ in zip(index, lower, upper):
        (A_lower if mat == 0 else B_lower)[r, c] = lo_
        (A_upper if mat == 0 else B_upper)[r, c] = hi_
    return A_lower, A_upper, B_lower, B_upper


def _proved_matrices(problem, proved, index, lower, upper):
    """The certified ``(A_lower, A_upper, B_lower, B_upper)``, checked to hold every sampled Jacobian."""
    A_lower, A_upper, B_lower, B_upper, _ = proved
    lower_c = problem.entries_from(A_lower[None], B_lower[None], index)[0]
    upper_c = problem.entries_from(A_upper[None], B_upper[None], index)[0]
    if np.any(lower_c > lower + COVERAGE_RTOL * (1 + np.abs(lower))) or np.any(
        upper_c < upper - COVERAGE_RTOL * (1 + np.abs(upper))
    ):
        raise CertificationError("internal error: a sampled Jacobian lies outside the certified bounds")
    return A_lower, A_upper, B_lower, B_upper


def coverage_fraction(pldi: PLDI, robot, n: int, *, seed=None) -> float:
    """Fraction of ``n`` fresh uniform points whose Jacobians lie in the intervals and polytope.

    For an inner loop (:mod:`polyrob.model.inner`) every point is checked on each of its
    true robots (``robot.variants()``): a point counts when all its Jacobians are inside.
    """
    problem = search.Problem(robot, pldi.domain)
    inside = np.ones(n, bool)
    for variant, domain in zip(problem.variants, problem.domains):
        A, B = variant.jacobians_batch(*domain.sample(n, method="uniform", seed=seed))
        inside &= pldi.contains(A, B)
        if len(pldi.entries):
            inside &= pldi.polytope.contains(pldi.entry_values(A, B))
    return float(inside.mean())


def _factor_task(robot, domain) -> bool:
    """Whether the proof is of an inner loop's factor ranges: a computed-torque loop over a task domain."""
    return getattr(domain, "kind", "box") != "box" and getattr(robot, "inner", None) == "computed-torque"


def _proved_factors(robot, domain, opts: BoundOptions, progress: bool) -> dict:
    """The proved ranges of the inner loop's factors (:mod:`polyrob.bounds.certified.factors`), as ``info["certify"]``.

    Progress is the proof's fraction of its work (the open volume closed,
    weighted by the entries still open, or the share of its work limit,
    whichever is further), with tqdm's ETA.  At the work
    limit the ranges are those proved by then (``partial``, the default): every
    one proved, the sides not yet closed wider than the tolerance; ``done`` and
    ``tightness`` (proved over attained widths) say how far, and ``covers``
    says it in words.
    """
    from polyrob.bounds.certified import factors as factor_module
    from polyrob.io.paths import cache_dir

    options = dict(opts.certify_options or {})
    if getattr(robot, "uncertainty", None) is not None:  # before the proof: "no factor to prove" would mislead
        raise CertificationError(
            "proved factor ranges cover the common-factor model (inner-gain: one link factor, the payload mass); "
            "a per-link robot-uncertainty set's models rest on factors sampled over the task: drop --certify, "
            "or state the error as --model-error"
        )
    loops = factor_module.factor_directions(robot)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(
            total=1000,
            desc="prove factor ranges",
            unit="‰",
            bar_format="{l_bar}{bar}| {n_fmt}‰ [{elapsed}<{remaining}]",
        )

    def report(done, boxes, eta):
        job_report(done, 1.0)  # the whole job's line (polyrob.progress), a terminal's bar or not
        if bar is not None:
            bar.update(max(0, int(1000 * done) - bar.n))
            bar.set_postfix(boxes=boxes, refresh=False)

    try:
        enc = factor_module.prove_factor_ranges(
            loops,
            domain,
            rel_tol=options.get("rel_tol", factor_module.REL_TOL),
            max_boxes=options.get("max_boxes", factor_module.MAX_BOXES),
            time_limit=options.get("time_limit"),
            progress=report,
            seed=opts.seed,
            workers=opts.workers or available_cores(),  # the batches of boxes shared among them
            checkpoint_dir=options.get("checkpoint_dir", cache_dir("proofs")),  # None: keep nothing
            partial=options.get("partial", True),
        )
    finally:
        if bar is not None:
            bar.close()
    tight = enc.tightness()
    limit = (
        ""
        if enc.done >= 1.0
        else f" at the work limit ({100 * enc.done:.1f} % of the refinement done; widths up to "
        f"{tight['max']:.3g}x the values attained, median {tight['median']:.3g})"
    )
    return {
        "factors": {
            name: {"lower": enc.lower[k].tolist(), "upper": enc.upper[k].tolist()} for k, name in enumerate(enc.names)
        },
        "boxes": int(enc.boxes),
        "seconds": round(float(enc.seconds), 3),
        "resumed_boxes": int(enc.resumed_boxes),
        "checkpoint": enc.checkpoint,
        "done": float(enc.done),
        "tightness": tight,
        "covers": f"the inner loop's factor ranges over the task box, proved{limit}; the A, B intervals sampled",
    }


def _certified(robot, domain: Domain, opts: BoundOptions, progress: bool):
    """The certified ``(A_lo, A_hi, B_lo, B_hi, info)`` of ``robot`` over a torque box (interval arithmetic)."""
    from polyrob.bounds.certified import enclosure as certify_module

    if getattr(domain, "kind", "box") != "box":
        raise CertificationError(
            "certified bounds cover a torque box only: a task domain's torques come from inverse dynamics, "
            "which the interval arithmetic does not enclose; drop --certify (its bounds are sampled)"
        )
    model = getattr(robot, "model", None)
    if model is None:
        raise CertificationError(
            f"{robot.name}: certified bounds need a URDF robot (interval evaluation of its rigid-body "
            "dynamics); analytic models get sampled bounds only: drop --certify"
        )
    # 1e-5 of each width: tight enough for the paper's printed digits, ~1 s on a 2R
    given = dict(opts.certify_options or {})
    if given.pop("checkpoint_dir", None) is not None:
        raise ArgumentError(
            "--proof-dir keeps an arm's factor proof over its task; a torque box's proof keeps no state: drop it"
        )
    given.pop("partial", None)  # a torque box's proof closes within its tolerance or gives up: no partial ranges
    options = {"rel_tol": 1e-5, **given}
    enc = certify_module.certified_jacobian_bounds(
        model,
        robot.damping,
        domain.q_lower,
        domain.q_upper,
        domain.qdot_lower,
        domain.qdot_upper,
        domain.u_lower,
        domain.u_upper,
        progress=progress,
        **options,
    )
    info = {"boxes": int(enc.n_boxes), "seconds": round(float(enc.seconds), 3)}
    return enc.A_lo, enc.A_hi, enc.B_lo, enc.B_hi, info
