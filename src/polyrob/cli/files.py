"""``polyrob report`` (a run directory's report, rebuilt from its files) and ``polyrob export`` (C code)."""

from __future__ import annotations

from polyrob.cli.common import Output, add_output_flags
from polyrob.cli.options import int_at_least, positive_float
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
    directory's); ``(None, None)``: bounded again over the domain the file records.
    """
    from pathlib import Path

    from polyrob.cli.plant import pldi_path

    beside = Path(args.controller).with_name("pldi.json")
    path = pldi_path(args) if args.pldi else (beside if beside.is_file() else None)
    if path is None and (not info.get("robot") or not isinstance(info.get("domain"), dict)):
        return None, f"{args.controller} records no robot and domain (pass --pldi FILE)"
    return path, None


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


def cmd_export(args) -> int:
    import sys

    from polyrob.cli.analyze import load_controller_args
    from polyrob.errors import PolyrobError
    from polyrob.validate.export_c import check_export_word_length, export_controller

    out_dir = check_output_dir(args.output)
    K, info, _ = load_controller_args(args.controller)
    path, why = _export_pldi(args, info) if args.word_length is not None else (None, "no --word-length")
    checking = why is None
    out = Output(args, stages=3 if checking else 1)
    check_doc, warning = None, None
    if args.word_length is not None and not checking:
        warning = f"{args.word_length}-bit coefficients not checked: {why}"
        check_doc = {"checked": False, "why": why}
    if checking:  # the report's word-length analysis, on the controller written here
        problem = _export_problem(args, info, path, out)
        out.stage(f"word-length check: {args.word_length} bits at {args.rate:g} Hz (μ of the discretised loop)")
        check = check_export_word_length(
            problem.P, K, args.rate, args.word_length, method=args.method, prewarp=args.prewarp
        )
        check_doc = {"checked": True, **check.summary()}
        if not check.ok:
            if not args.force:
                raise PolyrobError(f"export refused: {check.line()}; --force writes it anyway")
            warning = f"{check.line()}; written anyway (--force)"
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
        extra=_exported_from(args.controller),  # the C's JSON names the controller file it came from
    )
    doc = res.summary()
    if info.get("inner"):
        doc["inner"] = info["inner"]
    if check_doc is not None:
        doc["word_length_check"] = check_doc
    out.document(doc)
    out.line(f"wrote {res.header}, {res.source} and {res.json}")
    if info.get("inner") and not str(info["inner"]).startswith("inner layer: none"):
        out.line(f"the controller's output is an inner layer's input v; at run time: {info['inner']}")
    if warning:  # on stderr, also with --json and --quiet
        print(f"polyrob: warning: {warning}", file=sys.stderr, flush=True)
    return 0


def register(sub) -> None:
    p = sub.add_parser("report", help="rebuild a run directory's report (HTML + Markdown) from its files")
    p.add_argument("run_dir", help="directory written by `polyrob run ROBOT -o DIR`")
    p.add_argument("--controller", default="K.json", help="controller file inside the directory")
    p.add_argument("--pldi", default="pldi.json", help="PLDI file inside the directory")
    add_output_flags(p)
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("export", help="discretise a controller and write it as C (second-order sections)")
    p.add_argument("controller", help="controller file (JSON or MATLAB .mat)")
    p.add_argument("--rate", type=positive_float, required=True, help="sample rate in Hz")
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
        help="write coefficients of a --word-length that the check finds too short (with a warning)",
    )
    p.add_argument("-o", "--output", required=True, help="directory for the C and JSON files")
    add_output_flags(p)
    p.set_defaults(func=cmd_export)
