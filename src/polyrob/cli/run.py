"""``polyrob run``: bounds -> synthesis -> analysis in one go, and the main job (no robot)."""

from __future__ import annotations

from polyrob.cli.analyze import (
    add_moving_argument,
    add_wcgain_argument,
    check_jerk_applies,
    moving_asked,
    moving_options,
    print_analysis,
)
from polyrob.cli.common import Output, alphas_from_args, exit_status, robot_from_args, scale_names
from polyrob.cli.options import (
    add_coulomb_argument,
    add_validation_arguments,
    coulomb_from_args,
    int_at_least,
    parse_frequencies,
    rate_conditions_from_args,
    sampling_from_args,
)
from polyrob.cli.plant import problem_from_args
from polyrob.cli.synth import (
    add_bandwidth_arguments,
    add_synthesis_arguments,
    check_output,
    max_bandwidth_design,
    options_from_args,
    print_design,
    print_input_check,
    print_limit,
    ruled_out,
    save_design,
)

__all__ = ["register", "MAIN_JOB", "main_job_defaults", "report_certificates", "controller_words"]


#: ``polyrob run`` with no robot: the main job.  The paper's arm (the bundled
#: URDF ``planar_2r``) on a task a treatment robot performs: around an elbow-bent
#: pose, +-0.5 rad, |qdot| <= 1 rad/s, |qddot| <= 2 rad/s^2, the torques
#: following from inverse dynamics (a task domain, docs/task_domains.md), at
#: the paper's own weights and bandwidths.  On the paper's full torque box the
#: Jacobians hold accelerations of hundreds of rad/s^2 that no planned motion
#: asks for, and no controller polyrob finds is certified there at the paper's
#: bandwidths (README).  The D-K iteration stops once its grid peak is below
#: 0.95; the reduced controller's certificate is decided afterwards, at every
#: frequency, as for any other run.
MAIN_JOB = {
    "robot": "planar_2r",
    "pose": "0,1.5708",
    "q_radius": "0.5",
    "qdot_max": "1",
    "qddot_max": "2",
    "target": 0.95,
}


def main_job_defaults(args, out) -> None:
    """``run`` without a robot: the main job (:data:`MAIN_JOB`), unless its options were given."""
    if args.robot is not None:
        return
    given = [
        k for k in ("pose", "q_radius", "qdot_max", "qddot_max", "q_range", "u_max", "domain") if getattr(args, k, None)
    ]
    for key, value in MAIN_JOB.items():
        if key in ("pose", "q_radius", "qdot_max", "qddot_max") and given:
            continue  # a domain was given: it replaces the main job's task
        if getattr(args, key, None) is None:
            setattr(args, key, value)
    task = (
        ""
        if given
        else (
            f" on the task around q = ({args.pose}) rad, +-{args.q_radius} rad, |qdot| <= {args.qdot_max} rad/s, "
            f"|qddot| <= {args.qddot_max} rad/s^2"
        )
    )
    out.line(
        f"main job (no robot given): {args.robot}, the paper's arm{task}, the paper's weights, full-order D-G-K "
        f"stopped at grid mu < {args.target:g}"
        + (f", reduced to order <= {args.reduce_max_order}" if args.reduce else "")
        + "; give a robot to pose your own problem"
    )


def _run_dir(args):
    """``run -o DIR`` (no ``.json`` suffix): a run directory with K.json, the PLDI and the report."""
    if not args.output or args.output.lower().endswith(".json"):
        check_output(args)
        return None
    from polyrob.cli.files import check_output_dir

    return check_output_dir(args.output, first_file="K.json")


def cmd_run(args) -> int:
    """bounds -> synthesis -> analysis in one go, each artefact written as soon as it exists.

    With ``-o``, the PLDI is saved once bounded (a run directory), and the
    controller file with its certificate as soon as the synthesis' controller
    is certified, before the analysis: a run stopped later (SIGTERM, Ctrl-C,
    a shared machine's limit) keeps what was certified.  Each file is written
    atomically (a temporary file, then a rename) and rewritten with the
    analysis' figures at the end.
    """
    from polyrob.pipeline import analyze_controller, design_controller, frequency_grid, friction_statement, pldi_report

    omega_spec = parse_frequencies(args.omega)
    sampling = sampling_from_args(args)
    if args.max_bandwidth:  # option errors before any work
        scale_names(args.scale_only), alphas_from_args(args.alphas)
    run_dir = _run_dir(args)
    at_rate = rate_conditions_from_args(args) if run_dir is not None else None  # its refusals before any work
    coulomb = coulomb_from_args(args)
    moving_opts = moving_options(args)  # its refusals before any work
    stages = ["bounds", "largest bandwidth" if args.max_bandwidth else "synthesis", "analysis"]
    out = Output(args, stages=len(stages) + (run_dir is not None), job=stages + ["validation"] * (run_dir is not None))
    main_job_defaults(args, out)
    options = options_from_args(args, out)
    robot = robot_from_args(args)
    if coulomb is not None:  # one level or one per joint: refused before any work
        from polyrob.synthesis.integral import coulomb_levels

        coulomb_levels(robot, coulomb)
    problem = problem_from_args(robot, args, out)
    check_jerk_applies(args, problem)
    pldi = problem.pldi
    out.line(
        f"{len(pldi.entries)} varying entries ({pldi.enclosure}), {problem.unc.n_params} real parameters "
        f"({problem.model} model)"
    )
    out.line(pldi.table())
    if run_dir is not None and not (run_dir / "pldi.json").exists():
        pldi.save(run_dir / "pldi.json")  # kept if the run stops later; the report reads it
    limit = print_limit(problem, out)
    input_check = print_input_check(problem, out)
    early = {"robot": robot.name, "problem": problem.description(), "performance_limit": limit}
    if not args.max_bandwidth and ruled_out(early, args, out):
        return 1
    if args.max_bandwidth:  # a synthesis per factor; the analysis below is on the certified factor's weights
        design, problem, extra = max_bandwidth_design(problem, args, out, options)
        early["problem"].update(extra)
        if args.reduce and args.structure == "full":
            from polyrob.pipeline.design import reduce_design

            design = reduce_design(problem, design, args.reduce_max_order)
    else:
        out.stage(f"synthesis ({args.structure}" + (", then order reduction" if args.reduce else "") + ")")
        design = design_controller(problem, reduce=args.reduce, reduce_max_order=args.reduce_max_order, **options)
    print_design(design, out)
    controller_path = run_dir / "K.json" if run_dir is not None else args.output
    if controller_path:  # the certified controller first: a stop during the analysis keeps it
        save_design(design, problem, args, out, path=controller_path)
        out.line(f"certificate of the controller: {design.certificate.verdict}")
    out.stage(
        f"analysis: mu sweeps (robust stability, robust performance), {args.mc} Monte Carlo parameter sets"
        + (", time-varying certificate" if args.time_varying else "")
    )
    omega = frequency_grid(*omega_spec) if omega_spec else None
    a = analyze_controller(
        problem,
        design.controller,
        omega=omega,
        mc=args.mc,
        seed=0,
        progress=out.progress,
        time_varying=args.time_varying,
        stability="sweep" if args.stability_sweep else "implied",
        moving=moving_asked(args),
        moving_options=moving_opts,
        limit=None if args.max_bandwidth else limit,  # the limit printed above is factor 1's
        certificate=design.certificate,  # decided again, not swept again, when it is of the same loop and grid
        sampled_loop=sampling,  # --rate HZ: the sampled loop's certificate is the verdict
        worst_case=args.wcgain,
    )
    print_analysis(a, out)
    design = design.certified_by(a.certificate)  # the analysis' certificate is the design's: one call, one verdict
    doc = {
        "robot": robot.name,
        "problem": early["problem"],
        "bounds": pldi_report(pldi, robot.joint_names),
        "performance_limit": limit,
        "input_definiteness": input_check,
        "synthesis": design.summary(),
        "analysis": a.summary(),
        "covers": a.covers,
        "verdict": a.verdict,
    }
    friction = friction_statement(problem, design.controller, coulomb)
    if friction is not None:  # beside the covers line: what Coulomb friction does to the error
        doc["friction"] = friction
        out.line(friction["words"])
    extra = {"robust_stability": a.robust_stability.summary(), "robust_performance": a.robust_performance.summary()}
    if run_dir is not None:
        from polyrob.report.build import write_run_report

        doc["output"] = save_design(design, problem, args, out, certificate_extra=extra, path=controller_path)
        out.stage(f"validation and report into {run_dir} (nonlinear simulations, discretisation)")
        files = write_run_report(
            run_dir,
            problem,
            design.controller,
            certificates=report_certificates(a),
            controller_file="K.json",
            controller_words=controller_words(design),
            notes=(a.instead,) if a.instead else (),
            at_rate=at_rate,
            true_robots=args.true_robots,
        )
        doc["report"] = str(files.html)
        out.line(f"wrote {files.html}")
    elif args.output:
        doc["output"] = save_design(design, problem, args, out, certificate_extra=extra)
    out.document(doc)
    return exit_status(a.certificate)


def controller_words(design) -> str:
    """How the run's controller was made, for the report's first lines."""
    r = design.result
    if design.reduced is not None:
        return (
            f"full-order D-G-K (order {design.reduced.full_order}), reduced by balanced truncation to order "
            f"{design.reduced.order}"
        )
    return f"{r.structure}, order {r.order}"


def report_certificates(analysis) -> dict:
    """The three certificates a run report shows, as decided: frozen robot (mu), arbitrarily fast, moving robot.

    A certificate that was not computed is shown as NOT_CERTIFIED with its reason
    (:func:`polyrob.analysis.certificate.gain_certificate` with nothing checked), not left out.
    """
    from polyrob.analysis.certificate import ARBITRARY, Scope, gain_certificate
    from polyrob.report.certificates import FROZEN_ROW, MOVING_ROW, TIME_VARYING_ROW

    def not_computed(variation, why):
        scope = Scope(kind="robust performance", variation=variation, frequencies="")
        return gain_certificate(scope, stable=False, checked=False, why=f"not computed: {why}")

    certs = {FROZEN_ROW: analysis.certificate}
    tv = analysis.time_varying
    if tv is not None:
        certs[f"{TIME_VARYING_ROW} ({tv.method})"] = tv
    else:
        certs[TIME_VARYING_ROW] = not_computed(ARBITRARY, "not asked for (--no-time-varying)")
    mv = getattr(analysis, "moving", None)
    if mv is not None and mv.computed:
        certs[f"{MOVING_ROW} ({_short_rates(mv.rate_words)})"] = mv
    else:
        why = mv.notes[0] if mv is not None and mv.notes else "not asked for"
        cert = not_computed("the robot moving with the domain's rates", why)
        if mv is not None and mv.lower:  # the gain found along the task's motions is shown even without a bound
            from polyrob.report.certificates import certificate_record

            cert = {**certificate_record(cert), "moving": mv.summary()}
        certs[f"{MOVING_ROW} (the domain's rates)"] = cert
    return certs


def _short_rates(words: str) -> str:
    """The rate words of a row name, cut at the first ``;`` (the whole text is in the row's covers)."""
    return words.split(";")[0] if len(words) <= 120 else "the task's rates"


def register(sub) -> None:
    p = sub.add_parser(
        "run",
        help="bounds -> synthesis -> analysis in one go (no robot: the main job, the paper's arm certified)",
    )
    add_synthesis_arguments(p)
    add_bandwidth_arguments(p)
    p.add_argument(
        "--full-order", dest="reduce", action="store_false", help="keep the full-order controller (no reduction)"
    )
    # run reduces by default (a controller an engineer can implement); no robot: the main job (MAIN_JOB)
    p.set_defaults(reduce=True, robot=None)
    p.add_argument("--mc", type=int_at_least(1), default=200, help="Monte Carlo parameter sets in the analysis")
    p.add_argument(
        "--no-time-varying",
        dest="time_varying",
        action="store_false",
        help="skip the time-varying certificate of the analysis (the one that covers the moving robot)",
    )
    p.add_argument("--omega", default=None, help="analysis frequency grid LO:HI:N in rad/s (default automatic)")
    add_moving_argument(p)
    add_wcgain_argument(p)
    add_validation_arguments(p)
    add_coulomb_argument(p)
    p.add_argument(
        "--stability-sweep",
        action="store_true",
        help="sweep robust-stability mu even when the robust-performance certificate already bounds it "
        "(its value, not only a bound; `analyze` always sweeps)",
    )
    for a in p._actions:
        if a.dest == "output":  # run: a directory unless the name ends in .json
            a.help = (
                "FILE.json: the controller, its certificate and its problem; DIR: a run directory with "
                "K.json, pldi.json/.npz and the validation report (report.html)"
            )
    p.set_defaults(func=cmd_run)
