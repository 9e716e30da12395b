"""``polyrob report`` (a run directory's report, rebuilt from its files) and ``polyrob export`` (C code)."""

from __future__ import annotations

from polyrob.cli.common import Output, add_output_flags
from polyrob.cli.options import add_validation_arguments, int_at_least, positive_float, rate_conditions_from_args
from polyrob.errors import ArgumentError

__all__ = ["register", "check_output_dir"]


def check_output_dir(path, option: str = "-o", first_file: str = "controller.json"):
    """A directory to write into: may exist; must not be a file, a virtual file system or read-only.

    ``first_file`` is a file the command writes there: the same place rules
    apply to it, and an error names it (``run`` writes ``K.json`` first).
    """
    from pathlib import Path

    from polyrob.io.paths import check_output_path

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ArgumentError(f"{option} {path}: is a file, not a directory")
    check_output_path(p / first_file, option)
    return p


def cmd_report(args) -> int:
    from polyrob.analysis.certificate import Status
    from polyrob.pipeline.rebuild import load_run
    from polyrob.report.build import write_run_report
    from polyrob.report.certificates import certificate_rows, frozen_status, headline

    at_rate = rate_conditions_from_args(args)  # its refusals before any work
    out = Output(args, stages=2)
    out.stage(f"report: reading {args.run_dir} and rebuilding its problem")
    run = load_run(args.run_dir, controller=args.controller, pldi=args.pldi)
    for note in run.notes:
        out.line(f"note: {note}")
    out.stage("validating the controller and writing the report")
    files = write_run_report(
        run.path,
        run.problem,
        run.controller,
        certificates=run.certificates,
        controllers=run.controllers,
        controller_file=args.controller,
        notes=run.notes,
        at_rate=at_rate,
        true_robots=args.true_robots,
    )
    status = frozen_status(run.certificates)
    doc = {
        "html": str(files.html),
        "markdown": str(files.markdown),
        "validation": str(files.validation),
        "figures": [str(f) for f in files.figures],
        "status": status,
        "certified": status is not None and Status(status).certified,
        "verdict": headline(run.certificates) or "verdict: none (no frozen-robot certificate in the files)",
        "certificates": [
            {"name": name, "status": st, "bound": bound, "covers": covers}
            for name, st, bound, covers in certificate_rows(run.certificates)
        ],
        "notes": list(run.notes),
    }
    out.document(doc)
    out.line(doc["verdict"])
    out.line(f"wrote {files.html}, {files.markdown}, {files.validation} and {len(files.figures)} figure(s)")
    return 0 if doc["certified"] else 1  # as every command ending with a verdict (docs/certificates.md)


def _export_pldi(args, info: dict):
    """Where the word-length check's problem comes from: ``(PLDI path or None, why none)``.

    ``--pldi``, else ``pldi.json`` beside the controller file (a run
    directory's); ``(None, None)``: bounded again over the domain the file
    records (a torque box without an inner layer: an inner layer's robot is
    not rebuilt from the file's words, a task domain's PLDI is not bounded here).
    """
    from pathlib import Path

    from polyrob.cli.plant import pldi_path
    from polyrob.validate.export_c import has_inner_layer

    beside = Path(args.controller).with_name("pldi.json")
    path = pldi_path(args) if args.pldi else (beside if beside.is_file() else None)
    if path is not None:
        return path, None
    domain = info.get("domain")
    if not info.get("robot") or not isinstance(domain, dict):
        return None, f"{args.controller} records no robot and domain (pass --pldi FILE)"
    if domain.get("kind") == "task" or has_inner_layer(info):
        return None, f"{args.controller} was made on a task domain or an inner layer: pass its PLDI with --pldi FILE"
    return None, None


def _export_problem(args, info: dict, path, out):
    """The problem the controller file records, on the PLDI ``path`` (``None``: bounded again)."""
    import polyrob
    from polyrob.bounds.pldi import PLDI
    from polyrob.domains.torque_box import Domain
    from polyrob.pipeline.rebuild import rebuild_problem

    if path is not None:
        out.stage(f"word-length check: the problem of {args.controller} on the PLDI {path}")
        return rebuild_problem(PLDI.load(path), info)
    out.stage(
        f"word-length check: bounding {info['robot']} over the domain {args.controller} records (--pldi reuses one)"
    )
    domain = Domain.from_dict(info["domain"], source=args.controller)
    return rebuild_problem(
        polyrob.bound_pldi(polyrob.load_robot(info["robot"]), domain, coverage=0, progress=out.progress), info
    )


def _exported_from(controller) -> dict:
    """The export's provenance and the controller file's (path, SHA-256, its own provenance or ``None``)."""
    from pathlib import Path

    from polyrob.provenance import Provenance, sha256_file

    made = Provenance.capture(function="polyrob.validate.export_c.export_controller").to_dict()
    path = Path(str(controller))
    if not path.is_file():  # `paper`: the paper's K*
        return {"provenance": made, "controller_file": {"path": str(controller)}}
    stored = Provenance.of_file(path)
    source = {"path": str(path.resolve()), "sha256": sha256_file(path)}
    return {"provenance": made, "controller_file": {**source, "provenance": stored and stored.to_dict()}}


def certificate_sampling(controller) -> dict | None:
    """The sampled loop a controller file's certificate is about, with that certificate's status, or ``None``.

    ``{"rate_hz", "delay_samples", "hold", "status"}``: ``synth --rate``
    records the loop (:mod:`polyrob.analysis.sampled_data`) whatever its
    verdict, so the status is read from the file's certificate
    (:class:`polyrob.analysis.certificate.Status`), never assumed here.  A
    file whose certificate is for the continuous-time loop, or ``paper``,
    records none.
    """
    from pathlib import Path

    from polyrob.analysis.certificate import Status
    from polyrob.io.controller import read_controller_file

    if not Path(str(controller)).is_file():
        return None
    record = read_controller_file(controller).get("certificate") or {}
    sampled = record.get("sampled")
    if not sampled or sampled.get("rate_hz") is None:
        return None
    status = record.get("status") or (record.get("certificate") or {}).get("status")
    status = Status(status).value if status in {s.value for s in Status} else "status not recorded"
    return {**{k: sampled.get(k) for k in ("rate_hz", "delay_samples", "hold")}, "status": status}


def export_rate(args, sampling: dict | None, warnings: list) -> float:
    """The rate to export at: ``--rate``, else the certificate's; a rate other than the certificate's is refused.

    A certificate of the sampled loop is about its own rate and delay only
    (a lower rate can lose it, a higher one changes the discrete controller
    it was decided for), so another ``--rate`` needs ``--force``.
    """
    if sampling is None:
        if args.rate is None:
            raise ArgumentError(
                f"--rate: {args.controller} records no sample rate in its certificate (it is for the "
                "continuous-time loop); give --rate HZ, or certify the sampled loop with `polyrob synth ... --rate HZ`"
            )
        return args.rate
    rate = float(sampling["rate_hz"])
    if args.rate is None or args.rate == rate:
        return rate
    line = (
        f"--rate {args.rate:g}: the certificate of {args.controller} ({sampling['status']}) is for the loop sampled "
        f"at {rate:g} Hz ({delay_words(sampling, rate)}), not at {args.rate:g} Hz"
    )
    if not args.force:
        raise ArgumentError(
            f"{line}; give --rate {rate:g}, or certify again with `polyrob synth ... --rate {args.rate:g}` "
            "(--force writes it anyway, with a warning)"
        )
    warnings.append(f"{line}; written anyway (--force): the certificate is not about this loop")
    return args.rate


def delay_words(sampling: dict | None, rate: float) -> str:
    """The header's computation-delay line: the delay of the file's certificate (with its status), or none."""
    if sampling is None:
        return (
            "none in the certificate (it is for the continuous-time loop): u[k] is computed from e[k] and applied "
            "at once; the export's own rate checks assume no delay"
        )
    d, at = int(sampling.get("delay_samples") or 0), float(sampling["rate_hz"])
    if d == 0:
        return f"none: the certificate ({sampling['status']}, sampled at {at:g} Hz) assumes u[k] applied at sample k"
    samples = "one sample" if d == 1 else f"{d} samples"
    return (
        f"{samples} ({d / rate * 1e3:.4g} ms), the delay of the certificate ({sampling['status']}) at {at:g} Hz: "
        f"u[k], computed from e[k], is applied at sample k+{d} and held (zero-order hold) until the next"
    )


def cmd_export(args) -> int:
    import sys

    from polyrob.cli.analyze import load_controller_args
    from polyrob.validate.discretize import discretize
    from polyrob.validate.export_c import (
        Signals,
        check_export_rate,
        check_export_word_length,
        export_controller,
        has_inner_layer,
        lowest_rate_of_controller,
        nominal_plant,
        output_limits,
    )
    from polyrob.validate.quantize import (
        check_accuracy,
        quantize,
        round_to_float,
        smallest_accurate_word_length,
        sos_realization,
    )

    out_dir = check_output_dir(args.output)
    K, info, _ = load_controller_args(args.controller)
    warnings = []
    sampling = certificate_sampling(args.controller)
    args.rate = export_rate(args, sampling, warnings)

    # the rate: refused below the lowest rate for this controller (--allow-low-rate writes it, with a warning)
    low = lowest_rate_of_controller(K, nominal_plant(info, K))
    lowest = low.rate
    rate_words = f"its lowest rate is {lowest:.4g} Hz ({low.basis})"
    if args.rate < lowest:
        if not args.allow_low_rate:
            raise ArgumentError(
                f"--rate {args.rate:g}: too low for {args.controller}: {rate_words}; give --rate {lowest:.4g} or more "
                "(--allow-low-rate writes it anyway, with a warning)"
            )
        warnings.append(
            f"--rate {args.rate:g} Hz is too low for this controller: {rate_words}; written anyway (--allow-low-rate)"
        )

    # the realisation in the stated arithmetic: poles and DC gains against the exact discrete controller
    form = args.realization
    other = "delta" if form == "shift" else "shift"
    dc = discretize(K, args.rate, method=args.method, prewarp=args.prewarp)

    def accuracy_of(exact):
        rounded = exact if args.word_length is None else quantize(exact, args.word_length)
        rounded = round_to_float(rounded) if args.real == "float" else rounded
        return check_accuracy(exact, rounded)

    sos, sos_other = sos_realization(dc, form=form), sos_realization(dc, form=other)
    accuracy = accuracy_of(sos)
    smallest = smallest_accurate_word_length(sos)
    smallest_other = smallest_accurate_word_length(sos_other)
    keep = (
        f"the smallest fixed-point word length that keeps them is {smallest} bits (--word-length {smallest})"
        if smallest is not None
        else "no fixed-point word length up to 53 bits keeps them"
    )
    keep_both = f"{keep} in {form} sections; in {other} sections " + (
        f"{smallest_other} bits" if smallest_other is not None else "none up to 53 bits"
    )
    if not accuracy.ok:
        fix = keep_both if args.real == "double" else "--real double keeps them"
        if form == "shift" and accuracy_of(sos_other).ok:
            fix = f"--realization delta keeps it in {accuracy.arithmetic}; {fix}"
        line = (
            f"{accuracy.arithmetic} coefficients do not keep the controller's poles (1 % of their distance to "
            f"z = 1) and DC gains (0.1 %): {accuracy.problem}; {fix}"
        )
        if not args.force:
            raise ArgumentError(f"export refused: {line}; --force writes it anyway")
        warnings.append(f"{line}; written anyway (--force)")

    path, why = _export_pldi(args, info) if args.word_length is not None else (None, "no --word-length")
    checking = why is None
    out = Output(args, stages=3 if checking else 1)
    check_doc = None
    if args.word_length is not None and not checking:
        warnings.append(f"{args.word_length}-bit coefficients not checked against the loop's μ: {why}")
        check_doc = {"checked": False, "why": why}
    if checking:  # the report's word-length analysis, on the controller written here
        problem = _export_problem(args, info, path, out)
        rate_check, _ = check_export_rate(
            problem.P, K, args.rate, method=args.method, prewarp=args.prewarp, search=not args.allow_low_rate
        )
        check_doc = {"rate": {"ok": rate_check.ok, "mu": rate_check.mu, "lowest_rate_hz": rate_check.lowest}}
        if not rate_check.ok:
            if not args.allow_low_rate:
                raise ArgumentError(
                    f"--rate {args.rate:g}: too low for {args.controller}: {rate_check.line()} "
                    "(--allow-low-rate writes it anyway, with a warning)"
                )
            warnings.append(
                f"--rate {args.rate:g} Hz is too low: {rate_check.line()}; written anyway (--allow-low-rate)"
            )
        out.stage(f"word-length check: {args.word_length} bits at {args.rate:g} Hz (μ of the discretised loop)")
        check = None
        if rate_check.ok:  # at a rate that already loses μ, no word length can keep it
            check = check_export_word_length(
                problem.P, K, args.rate, args.word_length, method=args.method, prewarp=args.prewarp, form=form
            )
            check_doc = {"checked": True, **check.summary(), **check_doc}
        else:
            check_doc = {"checked": False, "why": "the rate already loses μ (--allow-low-rate)", **check_doc}
        if check is not None and not check.ok:
            words = check.line()
            if form == "shift":  # one μ evaluation more: does the delta form keep the loop at this word length?
                in_delta = check_export_word_length(
                    problem.P,
                    K,
                    args.rate,
                    args.word_length,
                    method=args.method,
                    prewarp=args.prewarp,
                    longest=args.word_length,
                    form="delta",
                )
                if in_delta.ok:
                    words += f"; --realization delta keeps it in {args.word_length}-bit fixed point"
            if not args.force:
                raise ArgumentError(f"export refused: {words}; --force writes it anyway")
            warnings.append(f"{words}; written anyway (--force)")
    lower, upper, limit_source = output_limits(info, K.noutputs)
    checked = [f"the rate: {args.rate:g} Hz, {'at or above' if args.rate >= lowest else 'BELOW'} {rate_words}"]
    in_form = keep if form == "shift" else f"{keep} in delta sections"
    checked.append(f"the coefficients' poles and DC gains: {'kept' if accuracy.ok else 'NOT kept'}; {in_form}")
    if check_doc and "rate" in check_doc:
        rate_ok = check_doc["rate"]["ok"]
        checked.append(f"μ of the discretised loop at this rate: {'kept' if rate_ok else 'NOT kept'} within 5 %")
    if check_doc and check_doc.get("checked"):
        checked.append(
            f"μ of the discretised loop with these coefficients: {'kept' if check_doc['ok'] else 'NOT kept'}"
        )
    signals = Signals(
        delay=delay_words(sampling, args.rate),
        inner=info.get("inner"),
        lower=lower,
        upper=upper,
        limit_source=limit_source,
        checked="; ".join(checked),
        warnings=tuple(warnings),
        realisation=(
            f"{args.method} at {args.rate:g} Hz"
            + (f" pre-warped at {args.prewarp:g} rad/s" if args.prewarp else "")
            + (
                ", second-order sections per entry (transposed direct form II), integrators in first-order "
                "sections of their own"
                if form == "shift"
                else ", delta-operator second-order sections per entry (d = (z - 1)/T, transposed direct form II), "
                "integrators exactly at d = 0"
            )
        ),
    )
    out.stage(
        f"export: {args.controller} at {args.rate:g} Hz ({args.method}"
        + (f", {args.word_length}-bit coefficients" if args.word_length else "")
        + f") into {out_dir}"
    )
    res = export_controller(
        K,
        args.rate,
        out_dir,
        word_length=args.word_length,
        method=args.method,
        prewarp=args.prewarp,
        real=args.real,
        name=args.name,
        inner=info.get("inner"),
        signals=signals,
        form=form,
        extra={
            **_exported_from(args.controller),  # the C's JSON names the controller file it came from
            "signals": {
                "input": "e[j] = r[j] - q[j], the tracking error of joint j, rad",
                "output": (
                    "v[i], the acceleration command of joint i (the inner layer's input), rad/s^2"
                    if has_inner_layer(info)
                    else "the torque deviation of joint i from the equilibrium torque, N m"
                ),
                "output_limits": {"lower": lower, "upper": upper, "source": limit_source},
                "anti_windup": "conditional integration: an output's section states hold while it saturates",
            },
            "lowest_rate_hz": lowest,
            "certificate_sampling": sampling,
            "smallest_word_length": smallest,
            "smallest_word_length_by_form": {form: smallest, other: smallest_other},
            "accuracy": accuracy.summary(),
            "warnings": list(warnings),
        },
    )
    doc = res.summary()
    doc["lowest_rate_hz"] = lowest
    doc["certificate_sampling"] = sampling
    doc["smallest_word_length"] = smallest
    doc["smallest_word_length_by_form"] = {form: smallest, other: smallest_other}
    doc["accuracy"] = accuracy.summary()
    doc["output_limits"] = {"lower": lower, "upper": upper, "source": limit_source}
    if info.get("inner"):
        doc["inner"] = info["inner"]
    if check_doc is not None:
        doc["word_length_check"] = check_doc
    out.document(doc)
    out.line(f"wrote {res.header}, {res.source} and {res.json}")
    out.line(f"coefficients: {keep_both} (poles within 1 % of their distance to z = 1, DC gains within 0.1 %)")
    if has_inner_layer(info):
        out.line(f"the controller's output is an inner layer's input v (rad/s^2); at run time: {info['inner']}")
    for w in warnings:  # on stderr, also with --json and --quiet
        print(f"polyrob: warning: {w}", file=sys.stderr, flush=True)
    return 0


def register(sub) -> None:
    p = sub.add_parser("report", help="rebuild a run directory's report (HTML + Markdown) from its files")
    p.add_argument("run_dir", help="directory written by `polyrob run ROBOT -o DIR`")
    p.add_argument("--controller", default="K.json", help="controller file inside the directory")
    p.add_argument("--pldi", default="pldi.json", help="PLDI file inside the directory")
    add_validation_arguments(p, true_robots=0)  # a rebuilt report re-runs it only when asked (minutes)
    add_output_flags(p)
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("export", help="discretise a controller and write it as C (second-order sections)")
    p.add_argument("controller", help="controller file (JSON or MATLAB .mat)")
    p.add_argument(
        "--rate",
        type=positive_float,
        default=None,
        help="sample rate in Hz (default: the rate of the controller file's certificate, from "
        "`synth --rate`; another rate is refused unless --force)",
    )
    p.add_argument(
        "--word-length",
        type=int_at_least(2),
        default=None,
        help="round the coefficients to this many bits of fixed point (default: floating point); refused "
        "when the discretised loop then loses stability or its μ (the report's word-length analysis)",
    )
    p.add_argument("--method", default="tustin", choices=["tustin", "zoh"], help="discretisation")
    p.add_argument("--prewarp", type=positive_float, default=None, help="Tustin pre-warping frequency (rad/s)")
    p.add_argument("--real", default="double", choices=["double", "float"], help="C type of the signals")
    p.add_argument(
        "--realization",
        default="shift",
        choices=["shift", "delta"],
        help="the sections' operator: shift (z^-1, the default) or delta ((z - 1)/T: keeps slow poles and "
        "integral gains in short words, see docs/howto/export.md)",
    )
    p.add_argument("--name", default="controller", help="base name of the .h/.c/.json files")
    p.add_argument(
        "--pldi",
        default=None,
        help="PLDI of the word-length check (default: pldi.json beside the controller file, "
        "else bounded again over the domain the file records)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="write coefficients that the checks find too short (--word-length, --real float), or at a --rate "
        "other than its certificate's, with a warning",
    )
    p.add_argument(
        "--allow-low-rate",
        action="store_true",
        help="write a controller at a --rate below its lowest rate (with a warning in the header and on stderr)",
    )
    p.add_argument("-o", "--output", required=True, help="directory for the C and JSON files")
    add_output_flags(p)
    p.set_defaults(func=cmd_export)
