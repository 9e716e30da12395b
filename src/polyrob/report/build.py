"""Validate a controller on its problem and write the run's report.

* :func:`validate_controller` runs every validation stage on a problem (the
  :class:`polyrob.pipeline.Problem` of a run, or anything with ``robot``,
  ``pldi``, ``unc`` and ``P``) and a controller: Monte Carlo, nonlinear
  simulations (continuous and sampled), the discretisation and quantisation
  analysis and the μ curve.
* :func:`write_run_report` is what ``polyrob run ROBOT -o DIR`` calls at its
  end with the objects it has, and what ``polyrob report DIR`` calls with the
  objects :func:`polyrob.pipeline.rebuild.load_run` rebuilt from the files.
  It also saves ``pldi.json``/``pldi.npz`` when they are not there yet, and
  the certificates it shows (:func:`save_run_certificates`), so that the
  report rebuilt from the directory shows the same ones.

The report takes objects and renders them: it rebuilds no problem (that is
:mod:`polyrob.pipeline.rebuild`).  Files of a run directory: see
:mod:`polyrob.pipeline.rebuild`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyrob.errors import ControllerFileError
from polyrob.io.atomic import atomic_write, json_default
from polyrob.report.certificates import certificate_record, is_decided
from polyrob.report.html import ReportFiles, ReportOptions, write_report

__all__ = [
    "Validation",
    "validate_controller",
    "default_scenarios",
    "write_run_report",
    "save_run_certificates",
    "read_run_certificates",
    "RUN_CERTIFICATES",
]

#: The certificates a run's report showed, as decided (read back by ``polyrob report DIR``).
RUN_CERTIFICATES = "certificate.json"
RUN_CERTIFICATES_FORMAT = "polyrob.run-certificates/1"

#: Frequencies (rad/s) of the discretisation checks: coarse on purpose, a design check.
DISCRETE_GRID = np.logspace(-3, 3.5, 25)


@dataclass(frozen=True, eq=False)
class Validation:
    """Everything :func:`validate_controller` computed (each part optional)."""

    monte_carlo: object = None
    simulations: tuple = ()
    discretization: dict | None = None
    mu_curves: dict | None = None
    notes: tuple = ()
    info: dict = field(default_factory=dict)
    at_rate: object = None


#: Dynamics evaluations each default simulation of the report may make (a count of work, not seconds:
#: the report is the same on an idle and on a loaded machine).
SIMULATION_EVALUATIONS = 10_000_000


def default_scenarios(robot, domain, q0, *, rate: float | None = None):
    """References inside the domain: a small step (continuous and sampled) and a smooth move.

    Steps are 0.2 % of each joint's position range, alternating in sign; the
    smooth move is 5 % of the range in 3 s (minimum jerk), clipped to the box.
    Returns ``[(reference, kwargs), ...]`` for :func:`polyrob.validate.simulate.simulate`;
    each simulation may make :data:`SIMULATION_EVALUATIONS` evaluations of the
    dynamics (a stiff loop that has not finished by then is reported as such).
    """
    from polyrob.validate.simulate import smooth_reference, step_reference

    span = np.asarray(domain.q_upper) - np.asarray(domain.q_lower)
    sign = np.where(np.arange(robot.m) % 2 == 0, 1.0, -1.0)
    q0 = np.asarray(q0, float)
    step = np.clip(q0 + 0.002 * span * sign, domain.q_lower, domain.q_upper)
    move = np.clip(q0 + 0.05 * span * sign, domain.q_lower, domain.q_upper)
    budget = {"max_evaluations": SIMULATION_EVALUATIONS}
    out = [(step_reference(step), {"t_final": 10.0, **budget})]
    if rate:
        out.append((step_reference(step), {"t_final": 10.0, "rate": float(rate), **budget}))
    out.append((smooth_reference(move, 3.0), {"t_final": 8.0, **budget}))
    return out


def validate_controller(
    problem,
    K,
    *,
    rate: float | None = 1000.0,
    mc: int | str = 20,
    seed: int = 0,
    scenarios=None,
    word_lengths=(8, 40),
    search_rate: bool = True,
    mu_omega=None,
    discrete_omega=None,
    at_rate=None,
    true_robots: int = 20,
) -> Validation:
    """Monte Carlo, nonlinear simulations, discretisation/quantisation and μ of ``K`` on ``problem``.

    Parameters
    ----------
    problem : Problem
        Needs ``robot``, ``pldi``, ``unc`` and ``P`` attributes.
    K : LTI
        Continuous controller.
    rate : float or None
        Sample rate (Hz) of the sampled simulation and of the discretisation
        analysis; ``None`` skips both.
    mc : int or "corners"
    scenarios : list, optional
        ``[(reference, simulate-kwargs), ...]``; default :func:`default_scenarios`.
    word_lengths : (int, int)
        Range of the word-length search.
    search_rate : bool
        Also search the lowest sample rate keeping μ within 5 %.
    mu_omega : array_like, optional
        Grid of the μ curve (default 60 points, 1e-3 .. 1e4 rad/s).
    discrete_omega : array_like, optional
        Grid of the discretisation checks (default :data:`DISCRETE_GRID`).
    at_rate : RealLoopConditions, optional
        Also run :func:`polyrob.validate.at_rate.runs.validate_at_rate` under these conditions on
        ``true_robots`` robots drawn from the set (``None``: not run).
    true_robots : int
    """
    from polyrob.analysis.mu.bounds import mu_bounds
    from polyrob.plant.generalized import lft
    from polyrob.validate.discretize import continuous_mu, min_sample_rate, sampled_data_mu
    from polyrob.validate.monte_carlo import monte_carlo
    from polyrob.validate.quantize import min_word_length, quantize, sos_realization
    from polyrob.validate.simulate import simulate

    robot, pldi, P = problem.robot, problem.pldi, problem.P
    notes = []
    mc_res = monte_carlo(P, K, n=mc, seed=seed)
    point = pldi.nominal_point
    q0 = (
        np.asarray(point["q"], float) if point else np.clip(np.zeros(robot.m), pldi.domain.q_lower, pldi.domain.q_upper)
    )
    scenarios = default_scenarios(robot, pldi.domain, q0, rate=rate) if scenarios is None else scenarios
    sims = tuple(simulate(robot, K, pldi, ref, q0=q0, **kw) for ref, kw in scenarios)

    w = np.logspace(-3, 4, 60) if mu_omega is None else np.asarray(mu_omega, float)
    mu = mu_bounds(lft(P, K), P.block_structure_rp, w, refine_peak=False, progress=False)
    curves = {"robust performance (continuous)": (mu.omega, mu.upper, mu.lower)}
    notes.append(
        "μ curves are bounds at the grid frequencies (peak on the grid); the certificate's own figure "
        "is in the table above."
    )

    disc = None
    dgrid = DISCRETE_GRID if discrete_omega is None else np.asarray(discrete_omega, float)
    if rate:
        mu_c = continuous_mu(P, K, dgrid)
        sd = sampled_data_mu(P, K, rate, omega=dgrid)
        curves[f"discretised loop @ {rate:.4g} Hz"] = (sd.omega, sd.upper, sd.lower)
        disc = {
            "rate_hz": rate,
            "method": sd.method,
            "prewarp_rad_s": sd.prewarp,
            "discrete_loop_stable": sd.stable,
            "spectral_radius": sd.spectral_radius,
            "mu_continuous_grid": mu_c,
            "mu_discrete_grid": sd.mu_upper_grid,
            "mu_threshold (continuous + 5 %)": 1.05 * mu_c,
        }
        if search_rate:
            mr = min_sample_rate(
                P,
                K,
                mu_continuous=mu_c,
                omega=dgrid,
                rel_tol=0.1,
                rate_bounds=(max(1.0, rate / 1000.0), max(rate, 10.0) * 10.0),
            )
            disc["min_rate_hz"] = mr.rate
            disc["mu_at_min_rate"] = mr.mu
        sos = sos_realization(sd.controller)
        wl = min_word_length(P, sos, threshold=1.05 * mu_c, lengths=word_lengths, omega=dgrid)
        disc["min_word_length_bits"] = wl.word_length
        disc["mu_at_min_word_length"] = wl.mu
        disc["sections"] = sos.n_sections
        if wl.word_length is None:
            q = quantize(sos, word_lengths[1])
            rho = float(np.abs(np.linalg.eigvals(np.asarray(q.to_ss().A))).max()) if q.n_sections else 0.0
            notes.append(
                f"no word length up to {word_lengths[1]} bits keeps the discretised loop stable with μ "
                f"within 5 % (controller spectral radius at {word_lengths[1]} bits: {rho:.12g})"
            )
        notes.append(
            "μ of the discretised loop (plant by zero-order hold) checks the sample rate and the word "
            "length; it is not a certificate of the sampled-data system."
        )
    real = None
    if at_rate is not None:
        from polyrob.validate.at_rate.runs import validate_at_rate

        real = validate_at_rate(robot, K, pldi, conditions=at_rate, true_robots=true_robots, seed=seed)
    return Validation(
        monte_carlo=mc_res, simulations=sims, discretization=disc, mu_curves=curves, notes=tuple(notes), at_rate=real
    )


def _paper_reference(problem) -> dict:
    """The paper's K* for comparison, only on the paper's problem: ``paper_2r`` on the paper's domain.

    On any other robot or domain K* was not designed for the plant shown, so
    comparing with it says nothing.
    """
    from polyrob.model.analytic import PAPER_DOMAIN

    robot, domain = problem.robot, getattr(problem, "domain", None) or problem.pldi.domain
    if robot.name != "paper_2r":
        return {}
    try:
        same = all(
            np.allclose(getattr(domain, f"{group}_lower"), np.asarray(PAPER_DOMAIN[group])[:, 0])
            and np.allclose(getattr(domain, f"{group}_upper"), np.asarray(PAPER_DOMAIN[group])[:, 1])
            for group in ("q", "qdot", "u")
        )
    except (AttributeError, ValueError):  # a task domain: no torque box, not the paper's
        return {}
    if not same:
        return {}
    from polyrob.plant.generalized import paper_controller

    return {"paper K*": paper_controller()}


def save_run_certificates(run_dir, certificates: dict, controller: str = "K.json", notes=(), provenance=None) -> Path:
    """Write ``run_dir/certificate.json``: the records of ``certificates`` for the controller file ``controller``.

    ``{"format": RUN_CERTIFICATES_FORMAT, "controller": "K.json", "certificates": {name: record},
    "notes": [...]}``, records as :func:`~polyrob.report.certificates.certificate_record` makes them;
    ``notes`` (e.g. what the controller certifies instead) are shown again when the report is rebuilt;
    ``"provenance"``: ``provenance`` (a :class:`~polyrob.provenance.Provenance`; default: captured here).
    """
    from polyrob.provenance import Provenance

    path = Path(run_dir) / RUN_CERTIFICATES
    provenance = provenance or Provenance.capture(function="polyrob.report.build.save_run_certificates")
    doc = {
        "format": RUN_CERTIFICATES_FORMAT,
        "controller": str(controller),
        "certificates": {str(k): _strict(certificate_record(v)) for k, v in certificates.items()},
        "notes": list(dict.fromkeys(str(n) for n in notes)),
        "provenance": provenance.to_dict(),
    }
    atomic_write(path, lambda f: f.write(json.dumps(doc, indent=1, default=json_default, allow_nan=False)))
    return path


def _strict(x):
    """Plain JSON: a NaN or infinite figure (not computed, no finite bound) is ``null``."""
    if isinstance(x, dict):
        return {k: _strict(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_strict(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if np.isfinite(x) else None
    return x


def read_run_certificates(run_dir, controller: str = "K.json") -> tuple[dict, list]:
    """The decided certificate records of ``run_dir/certificate.json`` for ``controller``, and notes.

    Records saved for another controller file are not used (they certify
    another controller).  A hand-written ``{name: record}`` mapping is read
    too; a record without a decided ``status`` is left out, with a note.
    """
    path = Path(run_dir) / RUN_CERTIFICATES
    if not path.exists():
        return {}, []
    try:
        doc = json.loads(path.read_text())
    except ValueError as exc:
        raise ControllerFileError(f"{path}: not JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ControllerFileError(f"{path}: expected a mapping of certificate name -> record")
    if doc.get("format") == RUN_CERTIFICATES_FORMAT:
        if doc.get("controller") != controller:
            return {}, [f"{path.name} holds the certificates of {doc.get('controller')}, not of {controller}: not used"]
        saved_notes = [str(n) for n in doc.get("notes") or [] if isinstance(n, str)]
        doc = doc.get("certificates") or {}
    else:
        saved_notes = []
    certs, notes = {}, saved_notes
    for name, record in doc.items():
        if is_decided(record):
            certs[str(name)] = record
        else:
            notes.append(f"{path.name}: '{name}' has no decided status (one of the four of polyrob.analysis.certificate): not shown")
    return certs, notes


def problem_summary(problem, K, controller_words: str | None = None) -> dict:
    """The lines at the top of a report: the robot, the domain and what it means for motion, the weights, the controller."""
    import control

    robot, domain = problem.robot, problem.domain
    inertia = getattr(robot, "reflected_inertia", None)
    if getattr(domain, "kind", "") == "task":
        motion = (
            "the certificate applies while positions, velocities and accelerations stay inside these bounds "
            "(torques from inverse dynamics)"
        )
    else:
        motion = "the certificate applies while positions, velocities and torques stay inside these bounds"
    hp = problem.hyperparameters
    weights = ", ".join(f"{k} {tuple(float(x) for x in hp[k])}" for k in ("omega_b", "omega_bt") if k in hp)
    return {
        "robot": f"{robot.name} ({robot.m} joints" + (f"; reflected inertia: {inertia}" if inertia else "") + ")",
        "domain": f"{domain.name}: {motion}",
        "performance weights": f"W_S, W_T of the paper's shape; bandwidths (rad/s) {weights}",
        "uncertainty model": f"{problem.model}, {problem.unc.n_params} real parameters, PLDI {problem.pldi.enclosure}",
        "controller": controller_words or f"order {control.ss(K).nstates}",
    }


def write_run_report(
    run_dir,
    problem,
    K,
    *,
    certificates: dict | None = None,
    controllers: dict | None = None,
    title: str | None = None,
    controller_file: str = "K.json",
    notes=(),
    controller_words: str | None = None,
    **options,
) -> ReportFiles:
    """Validate ``K`` on ``problem`` and write ``DIR/report.html`` (the end of ``polyrob run ROBOT -o DIR``).

    Parameters
    ----------
    run_dir : path
    problem : Problem
        Needs ``robot``, ``pldi``, ``unc`` and ``P``.
    K : LTI
    certificates : dict, optional
        ``{name: Certificate, TimeVaryingCertificate or record}`` (see
        :func:`polyrob.report.html.write_report`); saved to
        ``DIR/certificate.json`` for ``controller_file`` once the report is written.
    controllers : dict, optional
        More controllers for the comparison figure (the paper's K* is added on the paper's problem only).
    controller_file : str
        The controller file in ``DIR`` the certificates are of.
    notes : sequence of str
        Remarks printed under the certificates (e.g. what a rebuild could not read).
    controller_words : str, optional
        How the controller was made (structure, orders); default its order.
    **options
        Passed to :func:`validate_controller`.

    ``DIR/pldi.json`` (+ ``.npz``) is saved when absent, so that
    :func:`polyrob.pipeline.rebuild.load_run` can rebuild the problem.
    """
    run = Path(run_dir)
    if not (run / "pldi.json").exists():
        problem.pldi.save(run / "pldi.json")
    val = validate_controller(problem, K, **options)
    made, provenance = _provenance(run, problem, controller_file)
    comp = {**_paper_reference(problem), **(controllers or {})}
    options = ReportOptions(
        title=title,
        robot_name=problem.robot.name,
        pldi=problem.pldi,
        unc=problem.unc,
        controller=K,
        controllers=comp,
        certificates=dict(certificates or {}),
        monte_carlo=val.monte_carlo,
        simulations=tuple(val.simulations),
        discretization=val.discretization,
        mu_curves=val.mu_curves,
        notes=tuple(notes) + tuple(val.notes),
        problem_summary=problem_summary(problem, K, controller_words),
        provenance=provenance,
        rate_validation=None if val.at_rate is None else val.at_rate.summary(),
    )
    files = write_report(run, options)
    if certificates:
        save_run_certificates(run, certificates, controller_file, notes, provenance=made)
    return files


def _provenance(run: Path, problem, controller_file: str):
    """The report's own provenance, and ``{column: Provenance}`` with the controller file's when it records one."""
    from polyrob.provenance import Provenance

    made = Provenance.capture(
        robot=problem.robot, description=problem.description(), function="polyrob.report.build.write_run_report"
    )
    columns = {"this report": made}
    stored = Provenance.of_file(run / controller_file)
    if stored is not None:
        columns[f"the controller file {controller_file}"] = stored
    return made, columns
