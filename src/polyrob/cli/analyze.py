"""``polyrob analyze``: nominal/robust stability and performance (μ) of a controller, and one verdict."""

from __future__ import annotations

import argparse

from polyrob.cli.common import (
    Output,
    add_domain_arguments,
    add_output_flags,
    add_robot_arguments,
    add_weight_arguments,
    exit_status,
    robot_from_args,
)
from polyrob.cli.options import (
    add_sampling_arguments,
    int_at_least,
    parse_frequencies,
    positive_float,
    sampling_from_args,
)
from polyrob.cli.plant import add_plant_arguments, bounds_words, problem_from_args
from polyrob.errors import ArgumentError, PolyrobError

__all__ = ["register", "print_analysis", "jerk_bound", "check_jerk_applies"]


def load_controller_args(text):
    """``(K, info, source)`` of ``--controller``: ``paper`` (K*), a JSON file or a MATLAB .mat."""
    from polyrob.io.controller import controller_from_mapping, read_controller_file
    from polyrob.plant.generalized import paper_controller

    if text == "paper":
        return paper_controller(), {}, "the paper's K*"
    doc = read_controller_file(text)
    return controller_from_mapping(doc, text), doc.get("info") or {}, text


def print_analysis(a, out) -> None:
    """The text report of a :class:`polyrob.pipeline.ControllerAnalysis` (shared with ``run``)."""
    from polyrob.analysis.certificate import nominal_performance_verdict

    rs, rp, s = a.robust_stability, a.robust_performance, a.sampling
    npf = a.nominal_performance
    out.line(f"nominal stability      {'yes' if rs.nominally_stable else 'NO'}")
    out.line(f"nominal performance    ||N_zw||inf = {npf:.4g}  ({nominal_performance_verdict(npf)})")
    for title, r in (("robust stability", rs), ("robust performance", rp)):
        if r.implied_by:  # read from the other certificate: no figures of its own to show
            out.line(
                f"{title:<22} {r.certificate.status}: mu <= {r.certificate.bound:.4g} at every frequency, implied by "
                f"the {r.implied_by} certificate (its own value: --stability-sweep)"
            )
            continue
        out.line(
            f"{title:<22} mu in [{r.mu_lower:.4g}, {r.mu_upper_grid:.4g}] (peak on the frequency grid) "
            f"at {r.critical_frequency:.4g} rad/s: {r.certificate.status}"
        )
        between = getattr(r.mu, "between", None)
        if between is not None:
            out.line(f"{'':<23}{between.sentence()}")
        notes = list(getattr(r.mu, "notes", ()))  # fallbacks of the sweep are shown, not hidden
        for note in notes[:2]:
            out.line(f"{'':<23}note: {note}")
        if len(notes) > 2:
            out.line(f"{'':<23}note: {len(notes) - 2} more solver notes (all of them with --json)")
    out.line(f"monte carlo            {s.random_stable:.1%} of {s.random} random parameter sets stable")
    if s.corners_stable is not None:
        out.line(f"corners                {s.corners_stable:.1%} of {s.corners} corners stable")
    out.line(f"worst sampled          max Re(pole) = {s.worst_abscissa:.4g}")
    if getattr(a, "true_robots", None) is not None:  # the set's own robots: how much of mu is the model's
        out.line(a.true_robots.words())
    if getattr(a, "worst_case", None) is not None:
        out.line(f"worst-case gain        {a.worst_case.sentence()}")
    mv = getattr(a, "moving", None)
    if mv is not None:  # the third verdict: the linearised robot moving within the domain's rates
        out.line(mv.verdict)
        if mv.computed:
            out.line(mv.details())
    tv = a.time_varying
    if tv is not None:  # side by side with the mu verdict, which ends the report
        from polyrob.analysis.time_varying.certificate import covers_nonlinear

        out.line(tv.verdict)
        constants = mv is not None and getattr(mv, "decided", None) is not None
        out.line(f"which covers the robot: {covers_nonlinear(tv.method, constants)}")
    cells = getattr(a, "frozen_cells", None)
    if cells is not None:  # the frozen robot cell by cell, where the whole task's model did not certify it
        out.line(cells.verdict)
        out.line(cells.words())
    sampled = getattr(a, "sampled", None)
    if sampled is not None:  # the loop as it runs: its certificate is the verdict
        out.line(sampled.line())
    out.line(a.verdict)
    out.line(a.certificate.details())
    if getattr(a, "true_robots", None) is not None and not a.certificate.certified:
        from polyrob.synthesis.true_robots import share_of_mu

        share = share_of_mu(a.true_robots.to_dict(), a.certificate.mu_lower)
        if share is not None:  # whose the failure is: the controller's or the model's (read, not a status)
            out.line(share)
    if a.instead:  # not certified: what it certifies instead, and what stands in the way
        out.line(a.instead)


def cmd_analyze(args) -> int:
    from polyrob.analysis.sampled_data import sampling_words
    from polyrob.pipeline import analyze_controller, check_controller_problem, frequency_grid

    omega_spec = parse_frequencies(args.omega)
    sampling = sampling_from_args(args)
    moving_opts = moving_options(args)  # its refusals before any work (and before the job's progress line)
    check_frozen_cells_apply(args)
    out = Output(args, stages=2, job=["bounds", "analysis"])  # minutes on an arm: one line for the whole job
    K, info, source = load_controller_args(args.controller)
    robot = robot_from_args(args)
    from polyrob.pipeline.matching import check_controller_size

    check_controller_size(K, robot, source)  # its size first: a file of another size is not for this robot
    from polyrob.provenance import Provenance, differences

    stored, mismatches = Provenance.of_file(args.controller), []

    def check(known):  # robot, domain and weights are known before the bounding step
        if stored is not None:  # what differs from what the file was made for, one line each
            uncertainty = {"requested": args.uncertainty, "merge_symmetric": bool(args.merge_symmetric)}
            now = Provenance.capture(robot=robot, description={**known, "uncertainty": uncertainty})
            for line in differences(stored, now):
                mismatches.append(f"{source}: {line}")
                out.line(mismatches[-1])
        check_controller_problem(info, known, source)

    problem = problem_from_args(robot, args, out, check=check if info or stored else None)
    check_jerk_applies(args, problem)
    check_frozen_cells_apply(args, problem)
    if info:
        check_controller_problem(info, problem, source)
    omega = frequency_grid(*omega_spec) if omega_spec else None
    out.stage(
        f"analysis of {source}: mu sweeps (robust stability, robust performance), {args.mc} Monte Carlo parameter sets"
        + (", time-varying certificate" if args.time_varying else "")
        + (f", the loop {sampling_words(sampling)}" if sampling is not None else "")
    )
    a = analyze_controller(
        problem,
        K,
        omega=omega,
        mc=args.mc,
        seed=args.seed,
        progress=out.progress,
        time_varying=args.time_varying,
        moving=moving_asked(args),
        moving_options=moving_opts,
        sampled_loop=sampling,
        worst_case=args.wcgain,
        frozen_cells=args.frozen_cells,
        cells_dir=cells_dir_of(args) if args.frozen_cells else None,
    )
    report = {
        "robot": robot.name,
        "controller": source,
        "enclosure": problem.pldi.enclosure,
        "uncertainty": problem.model,
        "parameters": int(problem.unc.n_params),
        "problem_compared": bool(info),
        "provenance_differences": mismatches,
        **a.summary(),
    }
    out.document(report)
    out.line(
        f"robot {robot.name}: {problem.unc.n_params} real parameters ({bounds_words(problem)}, "
        f"{problem.model} model), controller order {a.order}"
    )
    if not info and source != "the paper's K*":
        out.line(f"note: {source} does not record the problem it was made for: not compared")
    print_analysis(a, out)
    return exit_status(a.certificate)


def add_moving_argument(p) -> None:
    """``--moving/--no-moving`` (``analyze`` and ``run``)."""
    p.add_argument(
        "--moving",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="the moving-robot certificate (rate-bounded LPV analysis on the robot's state, rates from the "
        "domain); default: computed only for small closed loops (docs/certificates.md)",
    )
    add_moving_harmonics_argument(p)
    add_jerk_argument(p)


def add_wcgain_argument(p) -> None:
    """``--wcgain`` (``analyze`` and ``run``)."""
    p.add_argument(
        "--wcgain",
        action="store_true",
        help="also bound the worst-case weighted gain over the whole uncertainty set (MATLAB's wcgain): every "
        "member stable and its gain below the upper bound, proved at every frequency (a bisection on the "
        "performance level, then one more certificate sweep; docs/certificates.md)",
    )


def add_frozen_cells_argument(p) -> None:
    """``--frozen-cells N`` (``analyze``)."""
    p.add_argument(
        "--frozen-cells",
        type=int_at_least(1),
        default=None,
        metavar="N",
        help="when the whole task's model does not certify the frozen robot: cut the task's positions into at most "
        "N cells, each with its own model (the links exact at its centre), and certify their union (a per-link "
        "robot-uncertainty set on a task; minutes per cell; docs/certificates.md)",
    )
    p.add_argument(
        "--cells-dir",
        default=None,
        metavar="DIR",
        help="--frozen-cells: where each finished cell's certificate is kept (a run stopped goes on from there "
        "when run again, for the same controller, set, task and polyrob); default $POLYROB_CACHE_DIR/frozen_cells "
        "or ~/.cache/polyrob/frozen_cells; 'none' keeps nothing",
    )


def cells_dir_of(args):
    """The folder ``--cells-dir`` names (its default: the cache's ``frozen_cells``), or ``None`` for 'none'."""
    from polyrob.io.paths import cache_dir

    folder = getattr(args, "cells_dir", None)
    if folder is None:
        return cache_dir("frozen_cells")
    return None if folder.strip().lower() == "none" else folder


def check_frozen_cells_apply(args, problem=None) -> None:
    """``--frozen-cells`` needs a per-link set's model on a task domain and the continuous loop: refused otherwise
    (before any work when no set is given; the model once the problem is built)."""
    if getattr(args, "frozen_cells", None) is None:
        if getattr(args, "cells_dir", None) is not None:
            raise ArgumentError("--cells-dir keeps the cells of --frozen-cells: add --frozen-cells N or drop it")
        return
    stated = getattr(args, "robot_uncertainty", None) is not None or getattr(args, "link_error", None) is not None
    if not stated or (problem is not None and not str(problem.model).startswith("inner-links")):
        model = "no robot-uncertainty set" if problem is None else f"the {problem.model!r} model"
        raise ArgumentError(
            f"--frozen-cells: cells carry a per-link robot-uncertainty set on a task (this problem has {model}): "
            "add --robot-uncertainty FILE|default or --link-error P, or drop --frozen-cells"
        )
    if sampling_from_args(args) is not None:
        raise ArgumentError("--frozen-cells certifies the continuous loop: drop --rate or --frozen-cells")


def add_jerk_argument(p) -> None:
    """``--qdddot-max`` (``analyze``, ``run`` and ``synth``)."""
    p.add_argument(
        "--qdddot-max",
        type=jerk_bound,
        default=None,
        metavar="JERK",
        help="a task domain's jerk bound >= 0 (rad/s^3), e.g. 13.5 or 13.5,20: the rate of the accelerations in "
        "the moving-robot certificate; default: the peak jerk of the task's fastest minimum-jerk move, "
        "(27/8) qddot_max^2 / qdot_max (docs/certificates.md)",
    )


def jerk_bound(text: str):
    """``--qdddot-max``: one number or one per joint, each finite and >= 0 (an argparse type: one line, exit 2)."""
    import math

    from polyrob.cli.options import number

    values = []
    for item in [s for s in str(text).split(",") if s.strip()] or [""]:
        try:
            v = number(item, "--qdddot-max")
        except PolyrobError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("--qdddot-max: ")) from None
        if not math.isfinite(v) or v < 0:
            raise argparse.ArgumentTypeError(f"a jerk bound must be finite and >= 0 (rad/s^3), got '{item.strip()}'")
        values.append(v)
    return values[0] if len(values) == 1 else values


jerk_bound.__name__ = "jerk bound"


def add_moving_harmonics_argument(p) -> None:
    """``--moving-harmonics N`` (``analyze``, ``run`` and ``synth``)."""
    p.add_argument(
        "--moving-harmonics",
        type=int_at_least(1),
        default=None,
        help="the rate-bounded search with bounded accelerations, X(rho) on cos k q, sin k q (k <= N) times "
        "(1, qdot), on a 9 x 3 grid: N = 2 proves paper_2r's tf3 loop at x 4 on the grid "
        "(docs/certificates.md); implies --moving",
    )
    p.add_argument(
        "--moving-cells",
        action="store_true",
        help="prove the moving robot's Lyapunov matrix between the grid points too, on cells covering the state "
        "box, or a task's box of positions, velocities and accelerations (an analytic robot such as paper_2r, or a "
        "URDF robot of up to 3 joints; the verdict then covers the whole box).  The search is asked for "
        "room between its points: margin maximised at level 0.95, q2 every pi/8 with --moving-harmonics, the half "
        "box of an even loop; with --moving-harmonics 2 paper_2r's tf3 loop at x 4 is proved between its points in minutes "
        "(docs/certificates.md); implies --moving",
    )
    p.add_argument(
        "--moving-level",
        type=positive_float,
        default=None,
        help=f"with --moving-cells: the level at which the search maximises the LMIs' margin (default "
        f"{MOVING_CELLS_LEVEL}); below the bound wanted, so that X has room between its grid points",
    )
    p.add_argument(
        "--moving-cells-level",
        type=positive_float,
        default=None,
        help="with --moving-cells: the level the cells prove (default: the search's level when the grid's bound is "
        "below it, else halfway from that bound to 1); the verdict's bound when they hold",
    )


#: The level at which ``--moving-cells`` asks the search to maximise the LMIs' margin (the cells then check
#: halfway from the grid's bound to 1).
MOVING_CELLS_LEVEL = 0.95


def check_jerk_applies(args, problem) -> None:
    """Refuse ``--qdddot-max`` on a problem whose moving-robot certificate does not use a jerk bound."""
    from polyrob.analysis.lpv.constant import check_jerk

    check_jerk(problem, getattr(args, "qdddot_max", None))


def moving_asked(args) -> bool | None:
    """``--moving`` / ``--no-moving`` / neither (``None``); ``--moving-harmonics`` and ``--moving-cells`` ask for it."""
    return True if getattr(args, "moving_harmonics", None) or getattr(args, "moving_cells", False) else args.moving


def moving_options(args) -> dict | None:
    """The moving-robot search's options from ``--moving-harmonics``, ``--moving-cells`` (``None``: the default)."""
    n = getattr(args, "moving_harmonics", None)
    for flag in ("moving_level", "moving_cells_level"):
        if getattr(args, flag, None) is not None and not getattr(args, "moving_cells", False):
            from polyrob.errors import ArgumentError

            raise ArgumentError(
                f"--{flag.replace('_', '-')} sets a level of --moving-cells: add --moving-cells, or drop it"
            )
    out = {} if n is None else {"velocities": "bounded", "harmonics": int(n), "points": (9, 3)}
    if getattr(args, "qdddot_max", None) is not None:
        out["jerk"] = args.qdddot_max  # a task domain's (polyrob.analysis.lpv.task); refused on another domain
    if getattr(args, "moving_cells", False):
        # cells need an X with room between the points: its margin maximised at a level, q2 every pi/8 (the
        # half box of an even loop holds as many points as the whole one at (9, 3)); docs/certificates.md
        level = getattr(args, "moving_level", None) or MOVING_CELLS_LEVEL
        out.update(cells=True, progress=True, level=level, symmetric="auto")
        if getattr(args, "moving_cells_level", None) is not None:
            out["cell_level"] = args.moving_cells_level
        if n is not None:
            out["points"] = (17, 3)
    return out or None


def register(sub) -> None:
    p = sub.add_parser("analyze", help="nominal/robust stability and performance (mu) of a controller")
    add_robot_arguments(p)
    add_domain_arguments(p)
    add_weight_arguments(p)
    p.add_argument(
        "--controller",
        required=True,
        help="controller file (JSON ss/tf, see polyrob.io.controller, or a MATLAB .mat with A, B, C, D) "
        "or 'paper' for the paper's K*",
    )
    add_plant_arguments(p)
    p.add_argument("--mc", type=int_at_least(1), default=500, help="Monte Carlo parameter sets")
    p.add_argument("--omega", default=None, help="frequency grid LO:HI:N in rad/s (log spaced; default automatic)")
    p.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo sets")
    p.add_argument(
        "--no-time-varying",
        dest="time_varying",
        action="store_false",
        help="skip the time-varying certificate (quadratic stability/performance on the PLDI's vertices, "
        "or the constant-D small gain), the one that covers the moving robot",
    )
    add_moving_argument(p)
    add_wcgain_argument(p)
    add_frozen_cells_argument(p)
    add_sampling_arguments(p)
    add_output_flags(p)
    p.set_defaults(func=cmd_analyze)
