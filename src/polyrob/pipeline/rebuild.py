"""A run directory read back: its problem, controllers and certificates, for ``polyrob report DIR``.

``polyrob run ROBOT -o DIR`` writes the files below; :func:`load_run` reads
them and rebuilds the robust-control problem they were made for
(:func:`polyrob.pipeline.build_problem` on the saved PLDI, with the weights
and the uncertainty model the controller file records).  The report
(:func:`polyrob.report.build.write_run_report`) then takes these objects and
renders them; it rebuilds nothing itself.

Files of a run directory::

    K.json               controller file (polyrob.io.controller): its "certificate"
                         record (with the decided frozen-robot certificate) and its
                         "info" (robot, domain, weights, uncertainty model)
    pldi.json, pldi.npz  the PLDI (PLDI.save)
    certificate.json     the certificates the report showed, as decided, for the
                         controller file they are of (written and read by
                         polyrob.report.build: save_run_certificates, read_run_certificates)
    K_<name>.json        optional: more controllers for the comparison figure
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from polyrob.errors import ArgumentError

__all__ = ["RunDirectory", "load_run", "rebuild_problem"]


@dataclass(frozen=True, eq=False)
class RunDirectory:
    """What :func:`load_run` read from a run directory.

    Attributes
    ----------
    path : Path
        The run directory read.
    problem : Problem
        Rebuilt on the saved PLDI with the controller file's weights and model.
    controller : LTI
    controllers : dict
        ``{name: K}`` of the ``K_<name>.json`` files.
    certificates : dict
        ``{name: record}`` as decided (``Certificate.summary()`` plus ``covers``),
        frozen robot first; or a :class:`~polyrob.analysis.certificate.Certificate`
        decided again when the files held none.
    notes : tuple of str
        What was not read, or decided again, and why.
    """

    path: Path
    problem: object
    controller: object
    controllers: dict
    certificates: dict
    notes: tuple = ()


def rebuild_problem(pldi, info: dict | None):
    """The :class:`~polyrob.pipeline.Problem` a controller file's ``info`` describes, on ``pldi``.

    Raises
    ------
    ControllerFileError
        The rebuilt problem differs from the one the file records (robot,
        domain, weights, model).
    """
    from polyrob.pipeline.matching import check_controller_problem
    from polyrob.pipeline.problem import build_problem

    info = info or {}
    unc = info.get("uncertainty") or {}
    weights = info.get("weights")
    problem = build_problem(
        pldi.robot,
        pldi=pldi,
        hyperparameters={k: tuple(v) for k, v in weights.items()} if weights else None,
        uncertainty=unc.get("requested", "box") if isinstance(unc, dict) else str(unc),
        merge_symmetric=bool(unc.get("merge_symmetric", False)) if isinstance(unc, dict) else False,
    )
    check_controller_problem(info, problem, "the run's controller file")
    return problem


def load_run(
    run_dir, *, controller: str = "K.json", pldi: str = "pldi.json", certify_missing: bool = True
) -> RunDirectory:
    """Read a run directory written by ``polyrob run ROBOT -o DIR`` and rebuild its problem.

    Parameters
    ----------
    run_dir : path
    controller, pldi : str
        File names inside the directory.
    certify_missing : bool
        When the files hold no decided frozen-robot certificate (a controller
        file from before certificates were stored), decide it again
        (:func:`polyrob.analysis.certificate.certify_loop`, the analysis' own
        call); otherwise the report has no verdict.
    """
    from polyrob.bounds.pldi import PLDI
    from polyrob.io.controller import load_controller, read_controller_file
    from polyrob.report.build import read_run_certificates
    from polyrob.report.certificates import FROZEN_ROW, is_decided, is_frozen

    run = Path(run_dir)
    if not run.is_dir():
        raise ArgumentError(f"{run}: no such run directory")
    for name in (controller, pldi):
        if not (run / name).exists():
            raise ArgumentError(
                f"{run}: no {name} (a run directory holds K.json and pldi.json: `polyrob run ROBOT -o DIR` writes them)"
            )
    doc = read_controller_file(run / controller)
    K = load_controller(run / controller)
    problem = rebuild_problem(PLDI.load(run / pldi), doc.get("info"))
    certs, notes = read_run_certificates(run, controller)
    if not any(is_frozen(c) for c in certs.values()):
        record = (doc.get("certificate") or {}).get("certificate")
        if is_decided(record) and is_frozen(record):
            certs = {FROZEN_ROW: record, **certs}
        elif certify_missing:
            from polyrob.analysis.certificate import certify_loop

            certs = {FROZEN_ROW: certify_loop(problem.P, K, scope=problem.scope()), **certs}
            notes.append(f"{controller} holds no decided certificate: the frozen robot's was decided again now")
        else:
            notes.append(f"{controller} holds no decided certificate: no verdict")
    others = {f.stem[2:]: load_controller(f) for f in sorted(run.glob("K_*.json")) if f.name != controller}
    # a rebuilt run keeps its notes once (those saved with its certificates are made again too)
    return RunDirectory(run, problem, K, others, certs, tuple(dict.fromkeys(notes)))
