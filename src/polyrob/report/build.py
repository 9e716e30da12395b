"""Validate a controller on its problem and write the run's report.

* :func:`validate_controller` runs every validation stage on a problem (the
  :class:`polyrob.pipeline.Problem` of a run, or anything with ``robot``,
  ``pldi``, ``unc`` and ``P``) and a controller: Monte Carlo, nonlinear
  simulations (continuous and sampled), the discretisation and quantisation
  analysis and the μ curve.
* :func:`write_run_report` is what ``polyrob run ROBOT -o DIR`` calls at its
  end with the objects it has; it also saves ``pldi.json``/``pldi.npz``
  when they are not there yet, so that ``polyrob report DIR`` can rebuild.
* :func:`build_report` is ``polyrob report RUN_DIR``: it reads the run's files
  and writes the same report again.

Files of a run directory::

    K.json               controller file (polyrob.io.controller), its "certificate"
                         and "info" (the problem description: robot, domain,
                         weights, uncertainty model)
    pldi.json, pldi.npz  the PLDI (PLDI.save)
    certificate.json     optional: {"name": {...}} more certificates, e.g. the
                         time-varying one
    K_<name>.json        optional: more controllers for the comparison figure
    report.html, report.md, figures/*.png, validation.json    written here
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from polyrob.errors import PolyrobError
from polyrob.report.html import ReportFiles, write_report

__all__ = ["Validation", "validate_controller", "default_scenarios", "write_run_report", "build_report"]

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


#: Wall-clock seconds each default simulation of the report may take.
SIMULATION_BUDGET = 300.0


def default_scenarios(robot, domain, q0, *, rate: float | None = None):
    """References inside the domain: a small step (continuous and sampled) and a smooth move.

    Steps are 0.2 % of each joint's position range, alternating in sign; the
    smooth move is 5 % of the range in 3 s (minimum jerk), clipped to the box.
    Returns ``[(reference, kwargs), ...]`` for :func:`polyrob.validate.simulate.simulate`;
    each simulation may take :data:`SIMULATION_BUDGET` seconds of wall clock
    (a stiff loop that has not finished by then is reported as such).
    """
    from polyrob.validate.simulate import smooth_reference, step_reference

    span = np.asarray(domain.q_upper) - np.asarray(domain.q_lower)
    sign = np.where(np.arange(robot.m) % 2 == 0, 1.0, -1.0)
    q0 = np.asarray(q0, float)
    step = np.clip(q0 + 0.002 * span * sign, domain.q_lower, domain.q_upper)
    move = np.clip(q0 + 0.05 * span * sign, domain.q_lower, domain.q_upper)
    budget = {"time_budget": SIMULATION_BUDGET}
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
            "mu_discrete_grid": sd.mu_upper,
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
    return Validation(monte_carlo=mc_res, simulations=sims, discretization=disc, mu_curves=curves, notes=tuple(notes))


def _paper_reference(robot):
    """The paper's K* for comparison, for the paper's 2R arm and its URDF twin."""
    if robot.name in ("paper_2r", "planar_2r"):
        from polyrob.plant.generalized import paper_controller

        return {"paper K*": paper_controller()}
    return {}


def write_run_report(
    run_dir,
    problem,
    K,
    *,
    certificates: dict | None = None,
    controllers: dict | None = None,
    title: str | None = None,
    **options,
) -> ReportFiles:
    """The end of ``polyrob run ROBOT -o DIR``: validate ``K`` and write ``DIR/report.html``.

    Saves ``DIR/pldi.json`` (+ ``.npz``) when absent, so that
    :func:`build_report` can rebuild the report from the directory.
    ``options`` go to :func:`validate_controller`.
    """
    run = Path(run_dir)
    if not (run / "pldi.json").exists():
        problem.pldi.save(run / "pldi.json")
    val = validate_controller(problem, K, **options)
    comp = {**_paper_reference(problem.robot), **(controllers or {})}
    return write_report(
        run,
        title=title,
        robot_name=problem.robot.name,
        pldi=problem.pldi,
        unc=problem.unc,
        controller=K,
        controllers=comp,
        certificates=certificates,
        monte_carlo=val.monte_carlo,
        simulations=val.simulations,
        discretization=val.discretization,
        mu_curves=val.mu_curves,
        notes=val.notes,
    )


def _load_certificates(run: Path, doc: dict) -> dict:
    certs = {}
    if doc.get("certificate"):
        certs["constant-parameter μ (controller file)"] = doc["certificate"]
    extra = run / "certificate.json"
    if extra.exists():
        try:
            more = json.loads(extra.read_text())
        except ValueError as exc:
            raise PolyrobError(f"{extra}: not JSON ({exc})") from None
        if not isinstance(more, dict):
            raise PolyrobError(f"{extra}: expected a mapping of certificate name -> figures")
        certs.update(more)
    return certs


def build_report(run_dir, *, controller: str = "K.json", pldi: str = "pldi.json", **options) -> ReportFiles:
    """``polyrob report RUN_DIR``: rebuild the report from the files of a run directory.

    Reads ``K.json`` (controller, certificate, problem description in
    ``info``), ``pldi.json``, the optional ``certificate.json`` and
    ``K_*.json``, rebuilds the problem with :func:`polyrob.pipeline.build_problem`
    and calls :func:`write_run_report`.  ``options`` go to :func:`validate_controller`.
    """
    from polyrob.bounds.pldi import PLDI
    from polyrob.io.controller import load_controller, read_controller_file
    from polyrob.pipeline import build_problem

    run = Path(run_dir)
    if not run.is_dir():
        raise PolyrobError(f"{run}: no such run directory")
    for name in (controller, pldi):
        if not (run / name).exists():
            raise PolyrobError(
                f"{run}: no {name} (a run directory holds K.json and pldi.json: `polyrob run ROBOT -o DIR` writes them)"
            )
    doc = read_controller_file(run / controller)
    K = load_controller(run / controller)
    p = PLDI.load(run / pldi)
    info = doc.get("info") or {}
    unc_info = info.get("uncertainty") or {}
    problem = build_problem(
        p.robot,
        pldi=p,
        hyperparameters={k: tuple(v) for k, v in info["weights"].items()} if info.get("weights") else None,
        uncertainty=unc_info.get("requested", "box") if isinstance(unc_info, dict) else str(unc_info),
        merge_symmetric=bool(unc_info.get("merge_symmetric", False)) if isinstance(unc_info, dict) else False,
    )
    others = {f.stem[2:]: load_controller(f) for f in sorted(run.glob("K_*.json"))}
    return write_run_report(run, problem, K, certificates=_load_certificates(run, doc), controllers=others, **options)
