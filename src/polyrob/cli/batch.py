"""``polyrob batch``: the pipeline for many robots, locally in processes or on a Dask cluster.

Thin: the options become jobs and settings for :func:`polyrob.fleet.run_batch`,
whose rows are printed as a table (or, with ``--json``, its summary
document).  Exit status 0 when every robot ran, 1 when some robot failed
(its row says why), 2 for a user error, 130 on Ctrl-C.
"""

from __future__ import annotations

import json

from polyrob.cli.common import Output, add_output_flags
from polyrob.cli.options import (
    MODEL_CHOICES,
    add_robot_uncertainty_arguments,
    add_validation_arguments,
    int_at_least,
    nonnegative_float,
    number,
    parse_bound,
    parse_frequencies,
    parse_joint_values,
    parse_list,
    parse_pose,
    positive_float,
    rate_conditions_dict,
)
from polyrob.errors import ArgumentError

__all__ = ["register", "jobs_from_args", "settings_from_args", "with_robot_uncertainty"]


def _jobs_file(path: str) -> list:
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, ValueError) as exc:
        raise ArgumentError(f"--jobs {path}: cannot read a JSON list of jobs ({exc})") from None
    if not isinstance(doc, list):
        raise ArgumentError(f"--jobs {path}: give a JSON list of jobs (robot names or objects with 'robot')")
    return doc


def jobs_from_args(args) -> list:
    """Robot names / job mappings from the positional robots, ``--all-serial`` and ``--jobs``."""
    from polyrob.fleet.batch import serial_arms

    names = list(args.robots)
    if args.all_serial:
        names += [n for n in serial_arms() if n not in names]
    common = {
        "domain": args.domain,
        "q_range": parse_joint_values(args.q_range, "--q-range", ranges=True),
        "qdot_max": parse_joint_values(args.qdot_max, "--qdot-max", ranges=False),
        "u_max": parse_joint_values(args.u_max, "--u-max", ranges=False),
        "qdot_scale": args.qdot_scale,
        "u_scale": args.u_scale,
        "auto_weights": not args.paper_weights,
        "bandwidth_scale": args.bandwidth_scale,
        "uncertainty": args.uncertainty,
        "pose": parse_pose(args.pose),
        "q_radius": parse_bound(args.q_radius, "--q-radius"),
        "qddot_max": parse_joint_values(args.qddot_max, "--qddot-max", ranges=False),
        "inner": args.inner,
        "model_error": None if args.model_error is None else parse_percent(args.model_error),
        "payload_mass": args.payload_mass,
        "payload_com": args.payload_com,
        "torque_box": args.torque_box or None,
    }
    common = {k: v for k, v in common.items() if v is not None}
    jobs = [dict(common, robot=n) for n in names]
    if args.jobs:
        for item in _jobs_file(args.jobs):
            jobs.append(dict(common, robot=item) if isinstance(item, str) else dict(common, **item))
    if not jobs:
        raise ArgumentError("give robots (e.g. `polyrob batch planar_2r panda`), --all-serial or --jobs FILE")
    return jobs


def with_robot_uncertainty(args, jobs) -> list:
    """``--robot-uncertainty``/``--link-error``: checked against every job's robot, then given to every job.

    Each job carries the set with the ``inner-links`` model on its default
    task (computed torque); a set that job's model cannot hold fails that
    job's row with the measured reason, as ``synth`` refuses it.
    """
    if getattr(args, "robot_uncertainty", None) is None and getattr(args, "link_error", None) is None:
        return jobs
    from polyrob.cli.options import robot_uncertainty_from_args
    from polyrob.model.robots import load_robot

    out = []
    for job in jobs:
        if not isinstance(job.get("robot"), str):
            out.append(job)
            continue
        spec = robot_uncertainty_from_args(args, load_robot(job["robot"]))
        out.append(dict(job, robot_uncertainty=spec.to_dict()))
    return out


def parse_percent(text: str) -> float:
    """``--model-error PCT`` -> the fraction a job takes."""
    p = number(text, "--model-error")
    if not 0.0 <= p < 100.0:
        raise ArgumentError(f"--model-error: give a percentage in [0, 100), got '{text}'")
    return p / 100.0


def settings_from_args(args) -> dict:
    """Keyword options of :func:`polyrob.fleet.run_batch` shared by every robot."""
    synthesis = {"structure": args.structure}
    if args.max_iter is not None:
        synthesis["max_iter"] = args.max_iter
    bound_options = {} if args.samples is None else {"samples": args.samples}
    if args.max_boxes is not None and not args.certify:
        raise ArgumentError("--max-boxes sets the interval-arithmetic proof: use it with --certify")
    if args.certify:  # each job proves its bounds (an arm's factor ranges over its task), on its own worker
        bound_options["certify"] = True
        if args.max_boxes is not None:
            bound_options["certify_options"] = {"max_boxes": args.max_boxes}
    return {
        "bound_options": bound_options,
        "synthesis": synthesis,
        "omega": parse_frequencies(args.omega),
        "search_bandwidth": args.max_bandwidth,
        "alphas": parse_list(args.alphas, "--alphas"),
        "search_time_limit": args.search_time_limit or None,
        "analyze": not args.no_analysis,
        "mc": args.mc,
        "validate": not args.no_validate,
        "validate_budget": args.validate_budget,
        "validate_move": args.validate_move,
        "true_robots": args.true_robots,
        "at_rate": rate_conditions_dict(args),
        "reduce_max_order": args.reduce_max_order or None,
        "moving": args.moving or args.tune_moving > 0,
        "tune_moving": args.tune_moving,
    }


def _fmt(value, spec: str = ".4g") -> str:
    return "-" if value is None else format(value, spec)


def cmd_batch(args) -> int:
    from polyrob.fleet import run_batch
    from polyrob.fleet.outputs import controller_words

    out = Output(args, stages=1)
    if args.output:
        from pathlib import Path

        from polyrob.io.paths import check_output_path

        check_output_path(Path(args.output) / "summary.json", "-o")
    jobs = jobs_from_args(args)
    jobs = with_robot_uncertainty(args, jobs)
    options = settings_from_args(args)
    if args.workers < 1:
        raise ArgumentError(f"-j must be >= 1, got {args.workers}")
    where = f"Dask scheduler {args.scheduler}" if args.scheduler else f"{args.workers} local worker(s)"
    out.stage(f"{len(jobs)} robot(s) on {where}")
    res = run_batch(
        jobs, workers=args.workers, scheduler=args.scheduler, out_dir=args.output, progress=not out.quiet, **options
    )
    doc = res.summary()
    if args.output:
        doc["files"] = res.files
    out.document(doc)
    out.line(
        f"{'robot':<22}{'joints':>7}{'layer':>17}{'params':>8}{'mu bound':>10}{'mu grid':>9}{'controller':>15}"
        f"{'rad/s':>8}{'alpha':>8}{'time s':>9}  result"
    )
    problem_lines = []
    for r in res.results:
        result = str(r.status) if r.ok else f"FAILED {r.error}: {r.message}"
        if r.ok and r.validation:
            result += f"; validation: {r.validation}"
        tuning = (r.details or {}).get("moving_tuning") if r.ok else None
        if tuning is not None:  # the rounds' merged-structure mu, or why the design was kept
            history = ", ".join(f"{h:.4g}" for h in tuning["history"]) if isinstance(tuning, dict) else None
            result += f"; tuned for the moving robot: merged mu {history}" if history else f"; {tuning}"
        if r.ok and r.moving:
            result += f"; {r.moving['verdict']}"
        if r.ok and r.validation_at_rate:
            result += f"; at the rate: {r.validation_at_rate['verdict']}"
        if r.ok and r.reason:
            result += f"; why: {r.reason}"
        controller = controller_words(r.row()) or "-"
        out.line(
            f"{r.name:<22}{_fmt(r.joints, 'd'):>7}{r.inner_layer or '-':>17}{_fmt(r.parameters, 'd'):>8}"
            f"{_fmt(r.mu_upper):>10}{_fmt(r.mu_upper_grid):>9}{controller:>15}{_fmt(r.bandwidth, '.3g'):>8}"
            f"{_fmt(r.alpha):>8}{r.seconds:>9.1f}  {result}"
        )
        if r.domain is not None:  # a row that failed after its problem was built says it too
            problem_lines.append(
                f"  {r.name}: domain {r.domain}; {r.inner}; reflected rotor inertia: {r.reflected_inertia}"
            )
    if problem_lines:
        out.line("problems (domain; inner layer and the set of true robots; reflected rotor inertia):")
        for line in problem_lines:
            out.line(line)
    out.line(
        f"{len(res.certified)} of {len(res.results)} certified, {len(res.failed)} failed, "
        f"{res.seconds:.1f} s on {res.executor}"
    )
    if args.output:
        out.line(f"wrote {res.files['summary']['markdown']} and one folder per robot in {args.output}")
    return 1 if res.failed else 0


def register(sub) -> None:
    p = sub.add_parser("batch", help="bounds -> synthesis -> analysis for many robots, locally or on a Dask cluster")
    p.add_argument("robots", nargs="*", help="robot names or URDF paths")
    p.add_argument(
        "--all-serial", action="store_true", help="every serial arm polyrob knows (polyrob.fleet.SERIAL_ARMS)"
    )
    p.add_argument("--jobs", default=None, help="JSON list of jobs: robot names or objects of polyrob.fleet.Job fields")
    p.add_argument("-j", "--workers", type=int_at_least(1), default=1, help="local worker processes")
    p.add_argument(
        "--scheduler", default=None, help="Dask scheduler address (tcp://HOST:8786) instead of local workers"
    )
    p.add_argument(
        "-o",
        "--output",
        default=None,
        help="folder: per robot a controller file and certificate, summary.json and summary.md",
    )
    g = p.add_argument_group("domain (every robot)")
    g.add_argument("--domain", default=None, help="a named domain of the robots or a domain file")
    g.add_argument("--q-range", default=None, help="position range, e.g. -pi:pi")
    g.add_argument("--qdot-max", default=None, help="velocity bound >= 0")
    g.add_argument("--u-max", default=None, help="torque bound >= 0")
    g.add_argument("--qdot-scale", type=nonnegative_float, default=1.0, help="scale the velocity box")
    g.add_argument("--u-scale", type=nonnegative_float, default=1.0, help="scale the torque box")
    t = p.add_argument_group(
        "task and inner layer (every robot; without any domain option an arm of 3+ joints gets its default "
        "task: +-0.2 rad around its reference pose, |qdot| <= 0.5, |qddot| <= 2, computed torque, links +-10 %%, payload 0-1 %% of the link mass)"
    )
    t.add_argument("--pose", default=None, help="reference pose: an SRDF pose name or q1,q2,...")
    t.add_argument("--q-radius", default=None, help="positions within pose +- RADIUS")
    t.add_argument("--qddot-max", default=None, help="acceleration bound >= 0 (rad/s^2)")
    t.add_argument("--inner", default=None, choices=("none", "gravity", "computed-torque"), help="inner layer")
    t.add_argument("--model-error", default=None, help="PCT: true link masses/inertias = model's x (1 -+ PCT/100)")
    t.add_argument("--payload-mass", default=None, help="payload at the tool flange, kg: LO:HI or M")
    t.add_argument("--payload-com", default=None, help="payload COM offset box in the flange frame, m")
    add_robot_uncertainty_arguments(t)
    t.add_argument(
        "--torque-box", action="store_true", help="the URDF torque box without an inner layer for every robot"
    )
    g = p.add_argument_group("weights and model")
    g.add_argument(
        "--paper-weights",
        action="store_true",
        help="the paper's weights (default: automatic, from the joint count and the domain)",
    )
    g.add_argument("--bandwidth-scale", type=positive_float, default=1.0, help="multiply both bandwidths")
    g.add_argument(
        "--max-bandwidth",
        action="store_true",
        help="search the largest bandwidth factor with certified mu < 1 (a synthesis per factor)",
    )
    g.add_argument("--alphas", default=None, help="--max-bandwidth: comma-separated factors to scan")
    g.add_argument(
        "--search-time-limit",
        type=nonnegative_float,
        default=0.0,
        metavar="SECONDS",
        help="--max-bandwidth: a safety net: no new factor of a robot's search starts after this many seconds, "
        "and the row says so (default 0: none; the search is bounded by its factors and its bisection)",
    )
    g.add_argument(
        "--uncertainty",
        default="auto",
        choices=MODEL_CHOICES,
        help="uncertainty model",
    )
    g = p.add_argument_group("work per robot")
    g.add_argument("--samples", type=int_at_least(2), default=None, help="bounds: Sobol' positions")
    g.add_argument(
        "--certify",
        action="store_true",
        help="prove the bounds each model rests on by interval arithmetic (as synth --certify): an arm's "
        "computed-torque factor ranges over its task, to the work limit, or a torque box's intervals (up to 3 "
        "joints); minutes per arm, and a robot whose proof bounds nothing by then fails its row",
    )
    g.add_argument(
        "--max-boxes",
        type=int_at_least(1),
        default=None,
        help="--certify: boxes each proof evaluates before it stops (a count of work, not seconds)",
    )
    g.add_argument("--structure", default="full", help="controller structure (full, tfN, pid, ss:N)")
    g.add_argument("--max-iter", type=int_at_least(1), default=None, help="D-K iterations")
    g.add_argument("--omega", default=None, help="frequency grid LO:HI:N (rad/s) of synthesis and analysis")
    g.add_argument("--mc", type=int_at_least(1), default=200, help="Monte Carlo parameter sets in the analysis")
    g.add_argument("--no-analysis", action="store_true", help="skip the mu analysis after the synthesis")
    g.add_argument("--no-validate", action="store_true", help="skip the nonlinear closed-loop step")
    g.add_argument(
        "--moving",
        action="store_true",
        help="also each controller's moving-robot certificate (the masses constant, the state at any rate; "
        "minutes per arm, docs/certificates.md): a column of the rows, and a row is certified only when mu and, "
        "once computed, this certificate both are; with --max-bandwidth on an inner-gain model a factor counts "
        "only when its controller has it too",
    )
    g.add_argument(
        "--tune-moving",
        type=int_at_least(0),
        default=0,
        metavar="ROUNDS",
        help="tune each controller's per-joint PID on the moving-robot certificate's structure for up to ROUNDS "
        "rounds before its certificates (as synth --tune-moving; minutes a round on an arm); implies --moving",
    )
    g.add_argument(
        "--reduce-max-order",
        type=int_at_least(0),
        default=20,
        help="reduce a certified full-order controller to at most this order while mu < 1 (0: no reduction)",
    )
    g.add_argument(
        "--validate-move",
        type=nonnegative_float,
        default=2.0,
        help="seconds of the minimum-jerk move the closed-loop check follows (0: a step; default 2)",
    )
    g.add_argument(
        "--validate-budget",
        type=positive_float,
        default=None,
        help="a safety net: wall-clock seconds the closed-loop simulation may take, named in the row when it "
        "fires (default none: the simulation is bounded by its number of dynamics evaluations)",
    )
    add_validation_arguments(p)
    add_output_flags(p)
    p.set_defaults(func=cmd_batch)
