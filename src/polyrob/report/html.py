"""The run report: ``report.html`` and ``report.md`` with figures, tables and verdicts.

:func:`write_report` takes the objects a run already has (each optional) and
writes, under ``run_dir``::

    report.html        self-contained page (no external CSS, scripts or URLs)
    report.md          the same content in Markdown
    figures/*.png      the figures the pages show (relative links)
    validation.json    the validation figures as plain data

The page opens with the verdict -- the status of the frozen-robot
certificate, as :mod:`polyrob.analysis.certificate` decided it -- and one
table with a row per certificate (frozen robot; arbitrarily fast variation
when it was computed): its status, its bound and what it covers (the scope's
sentence).  A certificate is a
:class:`~polyrob.analysis.certificate.Certificate`, a time-varying
certificate (its robust-performance certificate is shown), or the record
:func:`polyrob.report.certificates.certificate_record` makes of one (what a run directory stores).  A
figure that was not computed is left out or named in words: no table cell
reads ``nan`` or ``None``.  Every write is atomic.
"""

from __future__ import annotations

import datetime
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyrob.analysis.certificate import Status
from polyrob.errors import ArgumentError
from polyrob.io.atomic import atomic_write, json_default
from polyrob.report import plots
from polyrob.report.certificates import (
    certificate_record,
    certificate_rows,
    certificate_sweep,
    frozen_status,
    headline,
    headline_name,
    is_decided,
    lower_bound_words,
    plain_words,
)
from polyrob.report.numbers import zero_round_off
from polyrob.report.page import Page, cell, is_missing

__all__ = ["ReportFiles", "ReportOptions", "write_report", "deployment_line"]


@dataclass(frozen=True)
class ReportFiles:
    """Paths written by :func:`write_report`."""

    html: Path
    markdown: Path
    validation: Path
    figures: tuple


def _certificates(doc, certificates, problem_summary=None, deployment: str | None = None) -> dict:
    """The verdict, deployment, the problem and the certificate table at the top; returns the records shown."""
    records = {str(k): certificate_record(v) for k, v in (certificates or {}).items()}
    undecided = [k for k, r in records.items() if not is_decided(r)]
    if undecided:
        raise ArgumentError(f"certificates {undecided} have no decided status (a Certificate, or its summary())")
    status = frozen_status(records)
    if status is None:
        doc.para("verdict: none (no frozen-robot certificate was given)", bad=True, ident="verdict")
    else:
        doc.para(headline(records), bad=not Status(status).certified, ident="verdict")
        shown = headline_name(records)
        others = [f"{name}: {st}" for name, st, _, _ in certificate_rows(records) if name != shown]
        if others:
            doc.para("Other certificates (table below): " + "; ".join(others) + ".")
    if deployment:
        doc.para(deployment, bad=deployment_blocked(deployment), ident="deployment")
    if problem_summary:  # what was certified, for what motion, with what controller
        doc.table(["problem", "as posed"], [(k, str(v)) for k, v in problem_summary.items()], ident="problem", left=(0, 1))
    doc.heading("Certificates")
    if not records:
        doc.para("No certificate was given.")
        return records
    rows = [
        (name, st, plain_words(records[name]), cell(bound, "no finite bound"), lower_bound_words(records[name]), covers)
        for name, st, bound, covers in certificate_rows(records)
    ]
    bad = [k for k, row in enumerate(rows) if not Status(row[1]).certified]
    header = ["certificate", "status", "in plain words", "bound", "lower bound", "what it covers"]
    doc.table(
        header, rows, bad_rows=bad, ident="certificates", left=(0, 1, 2, 4, 5),
        classes={1: "status", 2: "text", 4: "text", 5: "text"},
    )  # fmt: skip
    for name, rec in records.items():
        if rec.get("verdict"):
            doc.para(f"{name}: {rec['verdict']}")
    return records


#: Coefficient words a controller fits in: the widths of common fixed-point datapaths.
_WORDS_BITS = (16, 32)


def deployment_line(discretization: dict | None) -> str | None:
    """``Deployment: ...``: the sample rate and the coefficient word length in plain words (``None``: not analysed).

    >>> print(deployment_line({"rate_hz": 1000.0, "discrete_loop_stable": True, "min_rate_hz": 19.11,
    ...                        "mu_continuous_grid": 0.9352, "mu_discrete_grid": 0.9352,
    ...                        "min_word_length_bits": 39, "sections": 16}))
    Deployment: run the controller at 1000 Hz: sampled there the loop is stable, mu 0.9352 on the grid (continuous 0.9352); the lowest rate keeping mu within 5 % of it: 19.11 Hz; BLOCKER: its 16 second-order sections need 39-bit fixed-point coefficients, more than a 32-bit word: run it in double-precision floating point (64-bit), or check a shorter word on the target.
    """
    d = discretization or {}
    rate = d.get("rate_hz")
    if is_missing(rate):
        return None
    parts = []
    mu_c, mu_d = d.get("mu_continuous_grid"), d.get("mu_discrete_grid")
    lowest = d.get("min_rate_hz")
    lowest = "" if is_missing(lowest) else f"; the lowest rate keeping mu within 5 % of it: {lowest:.4g} Hz"
    if d.get("discrete_loop_stable") is False:
        parts.append(f"BLOCKER: sampled at {rate:.4g} Hz the discretised loop is unstable: sample faster{lowest}")
    elif not (is_missing(mu_c) or is_missing(mu_d)) and mu_d > 1.05 * mu_c:
        parts.append(
            f"BLOCKER: sampled at {rate:.4g} Hz mu rises to {mu_d:.4g} (continuous {mu_c:.4g}, more than 5 %): "
            f"sample faster{lowest}"
        )
    else:
        mu = "" if is_missing(mu_d) else f", mu {mu_d:.4g} on the grid" + (
            "" if is_missing(mu_c) else f" (continuous {mu_c:.4g})"
        )
        parts.append(f"run the controller at {rate:.4g} Hz: sampled there the loop is stable{mu}{lowest}")
    if "min_word_length_bits" in d:
        bits, sections = d.get("min_word_length_bits"), d.get("sections")
        what = f"its {sections} second-order sections" if not is_missing(sections) else "the controller"
        if is_missing(bits):
            parts.append(
                f"BLOCKER: no fixed-point word length searched keeps {what} stable with mu within 5 %: "
                "run it in double-precision floating point (64-bit) and check it on the target"
            )
        elif bits > _WORDS_BITS[-1]:
            parts.append(
                f"BLOCKER: {what} need {bits}-bit fixed-point coefficients, more than a {_WORDS_BITS[-1]}-bit word: "
                "run it in double-precision floating point (64-bit), or check a shorter word on the target"
            )
        else:
            word = next(w for w in _WORDS_BITS if bits <= w)
            parts.append(f"{what} need {bits}-bit fixed-point coefficients: they fit a {word}-bit word")
    return "Deployment: " + "; ".join(parts) + "."


def deployment_blocked(line: str | None) -> bool:
    """Whether the deployment line names a blocker."""
    return bool(line) and "BLOCKER" in line


#: Words for a discretisation figure that no rate or word length reached.
_NOT_FOUND = {
    "min_rate_hz": "not found",
    "mu_at_min_rate": "not found",
    "min_word_length_bits": "not found (see the note)",
    "mu_at_min_word_length": "not found",
    "prewarp_rad_s": "not pre-warped",
}


@dataclass(frozen=True, eq=False)
class ReportOptions:
    """What a report shows; every part is optional (a part not given is left out or named in words).

    Attributes
    ----------
    title, robot_name : str
    pldi : PLDI, optional
        Its interval table (the paper's eq. 9) goes into the report.
    unc : UncertainPlant, optional
        For the Bode magnitude of the PLDI's plants (paper Fig. 3).
    controller : LTI, optional
        The run's controller (shown in the controller comparison).
    controllers : dict
        More controllers to compare, ``{name: K}`` (paper Fig. 5; the paper's
        K* only on the paper's problem, see :mod:`polyrob.report.build`).
    certificates : dict
        ``{name: certificate}``: a :class:`~polyrob.analysis.certificate.Certificate`,
        a ``TimeVaryingCertificate`` or a stored record
        (:func:`~polyrob.report.certificates.certificate_record`), e.g.
        ``{FROZEN_ROW: analysis.certificate, TIME_VARYING_ROW: analysis.time_varying}``;
        the page opens with the frozen-robot certificate, named.  A record
        without a decided status is refused (``ArgumentError``).
    monte_carlo : MonteCarloResult, optional
        S and T against the weight shapes (paper Fig. 4) and step responses.
    simulations : tuple of SimulationResult
        Nonlinear closed-loop runs; one that left the domain is shown in red.
    discretization : dict, optional
        Plain figures of the discretisation/quantisation analysis; the sample
        rate and word length are called out on the first screen ("Deployment:").
    mu_curves : dict, optional
        ``{name: (omega, upper, lower)}`` for the μ plot, after the sweep each
        certificate was decided on (its whole grid, ω = 0 included when swept).
    notes : tuple of str
        Extra remarks (fallbacks, approximations) printed under the summary.
    problem_summary : dict, optional
        ``{"robot": ..., "domain": ..., "controller": ...}``: the lines under
        the certificates (what was certified, for what motion, with what).
    provenance : dict, optional
        ``{column title: Provenance}``: the "Provenance" section and the footer
        (:func:`polyrob.report.provenance.add_provenance`).
    rate_validation : dict, optional
        A :meth:`~polyrob.validate.at_rate.runs.RateValidation.summary`: the section
        "Validation at the rate" (:mod:`polyrob.report.at_rate`) and ``validation.json["at_rate"]``.
    """

    title: str | None = None
    robot_name: str = ""
    pldi: object = None
    unc: object = None
    controller: object = None
    controllers: dict = field(default_factory=dict)
    certificates: dict = field(default_factory=dict)
    monte_carlo: object = None
    simulations: tuple = ()
    discretization: dict | None = None
    mu_curves: dict | None = None
    notes: tuple = ()
    problem_summary: dict | None = None
    provenance: dict | None = None
    rate_validation: dict | None = None


def write_report(run_dir, options: ReportOptions = ReportOptions()) -> ReportFiles:
    """Write ``report.html``, ``report.md``, ``figures/`` and ``validation.json`` into ``run_dir``.

    Parameters
    ----------
    run_dir : path
    options : ReportOptions
        What the report shows.

    Returns
    -------
    ReportFiles
    """
    if not isinstance(options, ReportOptions):
        raise ArgumentError(f"write_report takes a ReportOptions, got {type(options).__name__}")
    o = options
    title, robot_name, pldi, unc = o.title, o.robot_name, o.pldi, o.unc
    controller, controllers, certificates, monte_carlo = o.controller, o.controllers, o.certificates, o.monte_carlo
    simulations, discretization, mu_curves, notes = o.simulations, o.discretization, o.mu_curves, o.notes
    problem_summary = o.problem_summary
    run = Path(run_dir)
    figdir = run / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    title = title or f"polyrob report: {robot_name}"
    doc = Page(title)
    figures = []
    validation = {"robot": robot_name}

    def fig(name, make, caption):
        path = make(figdir / name)
        figures.append(path)
        doc.figure(f"figures/{name}", caption)

    deployment = deployment_line(discretization)
    records = _certificates(doc, certificates, problem_summary, deployment)
    validation["certificates"] = records
    if deployment:
        validation["deployment"] = deployment
    if problem_summary:
        validation["problem"] = {k: str(v) for k, v in problem_summary.items()}
    kinds = getattr(getattr(pldi, "robot", None), "joint_kinds", None)
    doc.para(f"Generated {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC by polyrob.")
    for note in notes:
        doc.para(str(note))
    def simulation_section(sims, heading, name):
        if not sims:
            return
        doc.heading(heading)
        left = [s for s in sims if not s.stayed_in_domain]
        if left:
            doc.para(
                f"{len(left)} of {len(sims)} simulations left the domain of the PLDI: the certificate does "
                "not apply to those trajectories.",
                bad=True,
            )
        else:
            doc.para(f"All {len(sims)} simulations stayed in the domain of the PLDI.")
        rows, bad = [], []
        for k, s in enumerate(sims):
            label = s.controller + (f" @ {s.rate:.4g} Hz" if s.rate else "")
            target = "" if s.reference.target is None else np.round(np.asarray(s.reference.target), 4).tolist()
            for mt in s.metrics:
                rows.append(
                    (
                        f"#{k + 1} {s.reference.kind} {target} ({label})",
                        mt.joint,
                        cell(mt.rise_time, "not reached"),
                        cell(mt.overshoot, "no step"),
                        cell(mt.settling_time, "not settled"),
                        mt.steady_state_error,
                        mt.peak_torque,
                        cell(mt.effort_limit, "no limit"),
                        "no" if s.left_domain else "yes",
                    )
                )
                if s.left_domain:
                    bad.append(len(rows) - 1)
        doc.table(
            [
                "simulation",
                "joint",
                "rise time (s)",
                "overshoot (%)",
                "settling (s)",
                "steady-state error",
                "peak torque",
                "effort limit",
                "in domain",
            ],
            rows,
            bad_rows=bad,
        )
        for k, s in enumerate(sims):
            doc.para(f"#{k + 1}: {s.verdict()}", bad=s.left_domain or not s.success)
        fig(
            name,
            lambda p: plots.plot_tracking(sims, p, joint_names=[m.joint for m in sims[0].metrics], kinds=kinds),
            "Nonlinear closed loop: positions and references, torques against the effort limits "
            "(red: after leaving the domain)",
        )
        validation.setdefault("simulations", []).extend(s.summary() for s in sims)



    # ------------------------------------------------------------------ the problem
    if pldi is not None:
        doc.heading("PLDI: bounds of the Jacobians over the domain")
        checked = pldi.coverage_points and not is_missing(pldi.coverage)
        coverage = f"coverage {pldi.coverage:.4g} of {pldi.coverage_points} fresh points; " if checked else ""
        doc.para(f"Enclosure: {pldi.enclosure}; {coverage}domain '{pldi.domain.name}'.")
        doc.table(
            ["entry", "lower", "upper", "nominal"],
            [
                (n, *figures)
                for n, figures in zip(
                    pldi.entries, zero_round_off(np.column_stack([pldi.lower, pldi.upper, pldi.nominal])).tolist()
                )
            ],
        )
    if unc is not None:
        fig(
            "pldi_bode.png",
            lambda p: plots.plot_pldi_bode(unc, p, kinds=kinds),
            "Bode magnitude of sampled and corner plants of the uncertain plant, and the nominal (paper Fig. 3)",
        )
    if monte_carlo is not None:
        doc.heading("Monte Carlo over the uncertain plant")
        s = monte_carlo.summary()
        doc.table(
            ["figure", "value"],
            [(k, v) for k, v in s.items() if not isinstance(v, dict)]
            + [(f"max |{k}| · |W_{k}| over samples", v) for k, v in s["weight_ratio"].items()],
        )
        doc.para("Sampled plants illustrate; they certify nothing about the plants between them.")
        fig(
            "sensitivities.png",
            lambda p: plots.plot_sensitivities(monte_carlo, p),
            "S and T of the sampled plants (grey), the nominal (black) and 1/|W_S|, 1/|W_T| (red) (paper Fig. 4)",
        )
        fig(
            "steps.png",
            lambda p: plots.plot_steps(monte_carlo, p, kinds=kinds),
            "Unit-step responses of the sampled linear loops",
        )
        validation["monte_carlo"] = s
    comp = dict(controllers or {})
    if controller is not None:
        comp = {"this run": controller, **comp}
    if comp:
        doc.heading("Controllers")
        fig(
            "controllers.png",
            lambda p: plots.plot_controllers(comp, p, kinds=kinds),
            "Magnitude of each controller entry"
            + (" against the paper's K* (paper Fig. 5)" if any("paper" in str(k) for k in comp) else ""),
        )
    curves = {f"certificate: {k}": sw for k, sw in ((k, certificate_sweep(r)) for k, r in records.items()) if sw}
    curves.update(mu_curves or {})
    if curves:
        doc.heading("μ over frequency")
        zero = any(np.any(np.asarray(c[0]) == 0) for c in curves.values())
        fig(
            "mu.png",
            lambda p: plots.plot_mu(curves, p),
            "μ upper (solid) and lower (dashed) bounds over each grid, from its lowest frequency"
            + ("; the value at ω = 0 is the point at the left edge" if zero else ""),
        )

    # ------------------------------------------------------------------ validation, then the appendix
    sims = list(simulations)
    along = [s for s in sims if s.reference.kind != "step"]
    steps = [s for s in sims if s.reference.kind == "step"]
    simulation_section(
        along, "Nonlinear closed loop along a trajectory (the robot's own dynamics)", "tracking.png"
    )
    if o.rate_validation:
        from polyrob.report.at_rate import add_rate_validation

        add_rate_validation(doc, o.rate_validation)
        validation["at_rate"] = o.rate_validation
    if steps:
        doc.heading("Appendix")
        doc.para(
            "Raw figures: small steps (a step asks for unbounded acceleration, so it may leave a domain "
            "that bounds accelerations or torques), the discretisation and quantisation analysis."
        )
    simulation_section(steps, "Appendix: steps on the nonlinear robot", "tracking_steps.png")
    if discretization:
        doc.heading("Appendix: discretisation and quantisation")
        doc.table(
            ["figure", "value"],
            [
                (k, cell(v, _NOT_FOUND.get(k, "not computed")))
                for k, v in discretization.items()
                if not isinstance(v, (dict, list)) or len(v) <= 6
            ],
        )
        validation["discretization"] = discretization


    if o.provenance:
        from polyrob.report.provenance import add_provenance

        add_provenance(doc, o.provenance)
        validation["provenance"] = {k: p.to_dict() for k, p in o.provenance.items()}
    page, md = doc.text()
    h, m = run / "report.html", run / "report.md"
    v = run / "validation.json"
    atomic_write(h, lambda f: f.write(page))
    atomic_write(m, lambda f: f.write(md))
    atomic_write(v, lambda f: f.write(json.dumps(validation, indent=1, default=json_default)))
    return ReportFiles(html=h, markdown=m, validation=v, figures=tuple(figures))
