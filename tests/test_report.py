"""The report: every file the HTML references exists, every PNG is a valid image, the certificates are shown as decided.

The run report opens with the frozen-robot certificate's status and one table
of the certificates (status, bound, what it covers); ``polyrob report DIR``
rebuilds it from the run's files with the same rows.
"""

from __future__ import annotations

import functools
import json
import re
from pathlib import Path

import numpy as np
import pytest

import polyrob
from polyrob.analysis.certificate import ARBITRARY, Certificate, Scope, Status
from polyrob.io.controller import load_controller, save_controller
from polyrob.report.certificates import FROZEN_ROW, MOVING_ROW, TIME_VARYING_ROW
from polyrob.report.html import ReportOptions, write_report
from polyrob.validate.monte_carlo import monte_carlo
from polyrob.validate.simulate import simulate, step_reference

FIXTURE = Path(__file__).parent / "fixtures" / "validate_planar_2r_K.json"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@functools.cache
def _paper():
    from polyrob.plant.weights import paper_weights

    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    unc = polyrob.uncertain_plant(pldi)
    return pldi, unc, polyrob.generalized_plant(unc, *paper_weights())


def _check_links(run: Path, page: str, pattern: str):
    refs = re.findall(pattern, page)
    assert refs, "the page references no figure"
    from PIL import Image

    for ref in refs:
        assert not re.match(r"^[a-z]+://", ref), f"external reference {ref}"
        path = run / ref
        assert path.is_file(), f"{ref} does not exist"
        data = path.read_bytes()
        assert data[:8] == PNG_SIGNATURE
        with Image.open(path) as im:
            im.verify()
        with Image.open(path) as im:
            assert im.size[0] > 100 and im.size[1] > 100
    return refs


def _verdict(page: str) -> str:
    """The status of the verdict at the top (the first paragraph after the title), which names its certificate."""
    m = re.search(r"</h1>\s*<p id='verdict'[^>]*>Frozen robot, robust (?:performance|stability): ([A-Z_]+)\b", page)
    assert m, "no verdict naming the frozen-robot certificate at the top of the page"
    return m.group(1)


def _cells(html_row: str) -> list[str]:
    import html

    return [html.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", html_row)]


def _certificate_rows(page: str) -> list[list[str]]:
    table = re.search(r"<table id='certificates'>(.*?)</table>", page, re.S)
    assert table, "no certificate table"
    return [_cells(row) for row in re.findall(r"<tr[^>]*>(.*?)</tr>", table.group(1)) if "<td" in row]


def _check_cells(page: str):
    """No table cell is empty, nan or None: a figure that was not computed is named in words."""
    for cell in _cells(page):
        assert cell.strip(), "an empty table cell"
        assert not re.search(r"\b(nan|none|null)\b", cell, re.I), f"table cell {cell!r}"


def test_report_references_existing_valid_pngs(tmp_path):
    pldi, unc, P = _paper()
    K = polyrob.paper_controller()
    mc = monte_carlo(P, K, n=3, seed=0, omega=np.logspace(-2, 3, 60))
    robot = polyrob.load_robot("planar_2r")
    dom = polyrob.Domain.from_robot(robot)
    inside = simulate(robot, K, dom, step_reference([0.005, -0.002]), t_final=4.0)
    outside = simulate(robot, K, dom, step_reference([0.2, -0.1]), t_final=1.0)
    w = np.logspace(-2, 2, 5)
    options = ReportOptions(
        robot_name="paper_2r",
        pldi=pldi,
        unc=unc,
        controller=K,
        controllers={"other": 0.5 * K},
        monte_carlo=mc,
        simulations=(inside, outside),
        certificates={
            FROZEN_ROW: Certificate(
                Status.NOT_CERTIFIED, 2.43, 2.43, 2.3, None, Scope(frequencies="the grid"), ("mu not below 1",)
            ),
            "time-varying (quadratic)": Certificate(
                Status.NOT_CERTIFIED, float("inf"), float("nan"), float("nan"), None, Scope(), ("no common P",)
            ).summary(),
        },
        discretization={"rate_hz": 1000.0, "min_word_length_bits": 24, "spectral_radius": 0.99999997},
        mu_curves={"robust performance": (w, 2 * np.ones(5), 1.9 * np.ones(5))},
    )
    files = write_report(tmp_path, options)
    page = files.html.read_text()
    refs = _check_links(tmp_path, page, r"<img src='([^']+)'")
    assert set(refs) == {f"figures/{p.name}" for p in files.figures}
    # steps are raw figures: their simulations go to the appendix, after the paper's figures
    names = [Path(r).name for r in refs]
    assert {"pldi_bode.png", "sensitivities.png", "controllers.png", "mu.png", "tracking_steps.png"} <= set(names)
    assert names.index("mu.png") < names.index("tracking_steps.png") and "tracking.png" not in names
    _check_links(tmp_path, files.markdown.read_text(), r"!\[[^\]]*\]\(([^)]+)\)")
    # self-contained: no scripts, stylesheets or remote resources
    assert "<script" not in page and "http" not in page.replace("http-equiv", "")
    # the verdicts: the run that left the domain in red, the certificates, the PLDI table, the 0.99999997
    assert "class='bad'" in page and "LEFT THE DOMAIN" in page
    assert "time-varying (quadratic)" in page and "b42" in page and "0.99999997" in page
    assert _verdict(page) == "NOT_CERTIFIED" and "no finite bound" in page
    # the PLDI was bounded without a coverage check: no "coverage nan of 0 fresh points"
    assert pldi.coverage_points == 0 and "fresh points" not in page and "coverage nan" not in page
    _check_cells(page)
    val = json.loads(files.validation.read_text())
    assert [s["stayed_in_domain"] for s in val["simulations"]] == [True, False]
    # rewriting replaces the files atomically: no temporary files left
    write_report(tmp_path, ReportOptions(robot_name="paper_2r", simulations=(inside,)))
    assert not list(tmp_path.rglob("*.tmp"))


def _fixture_problem(pldi):
    from polyrob.pipeline import build_problem

    info = json.loads(FIXTURE.read_text())["info"]
    h = {k: tuple(v) for k, v in info["weights"].items()}
    return build_problem(pldi.robot, pldi=pldi, hyperparameters=h, uncertainty="box")


@functools.cache
def _run():
    """The fixture's planar_2r controller analysed as `polyrob run` does (small grid, few samples)."""
    from polyrob.pipeline import analyze_controller

    pldi = polyrob.bound_pldi(polyrob.load_robot("planar_2r"), samples=256, coverage=200, progress=False)
    problem = _fixture_problem(pldi)
    K = load_controller(FIXTURE)
    a = analyze_controller(problem, K, omega=np.logspace(-2, 2, 8), mc=3, progress=False)
    assert a.time_varying is not None
    return problem, K, a


def _write_run_files(run: Path, problem, K, a) -> None:
    """What `polyrob run -o DIR` writes before its report: K.json with the decided certificate and the problem."""
    record = json.loads(FIXTURE.read_text())["certificate"]
    record.update(certificate=a.certificate.summary(), status=a.certificate.status.value)
    save_controller(K, run / "K.json", certificate=record, info=problem.description())
    save_controller(polyrob.paper_controller(), run / "K_fixed.json")


#: Validation options that keep the report fast (the figures are still drawn).
FAST = {"mc": 3, "mu_omega": np.logspace(-2, 2, 8), "search_rate": False, "word_lengths": (30, 34)}


def test_run_report_shows_the_certificates_and_rebuilds_them(tmp_path, monkeypatch, capsys):
    """`polyrob run -o DIR`'s report, then `polyrob report DIR`: same verdict, same certificate rows."""
    import polyrob.report.build as build
    from polyrob.cli import main
    from polyrob.cli.run import report_certificates
    from polyrob.validate.simulate import step_reference

    problem, K, a = _run()
    tv = a.time_varying
    _write_run_files(tmp_path, problem, K, a)
    q0 = np.asarray(problem.pldi.nominal_point["q"], float)
    files = build.write_run_report(
        tmp_path,
        problem,
        K,
        certificates=report_certificates(a),  # what cmd_run passes
        rate=100.0,
        scenarios=[(step_reference(q0 + 0.002), {"t_final": 3.0})],
        discrete_omega=np.logspace(-2, 2, 4),
        **FAST,
    )
    page = files.html.read_text()
    # the verdict at the top is the frozen-robot certificate's status, as decided
    assert _verdict(page) == a.certificate.status.value
    rows = _certificate_rows(page)
    shown = report_certificates(a)  # three rows: frozen, arbitrarily fast, moving (not computed: said so)
    assert [r[0] for r in rows] == list(shown) and len(rows) == 3
    assert [r[0] for r in rows[:2]] == [FROZEN_ROW, f"{TIME_VARYING_ROW} ({tv.method})"]
    assert rows[2][0].startswith(MOVING_ROW)
    assert [r[1] for r in rows[:2]] == [a.certificate.status.value, tv.certificate.status.value]
    assert [r[5] for r in rows[:2]] == [a.certificate.scope.sentence(), tv.certificate.scope.sentence()]
    assert float(rows[0][3]) == pytest.approx(a.certificate.bound, rel=1e-4)
    assert rows[1][3] == (f"{tv.gamma:.5g}" if np.isfinite(tv.gamma) else "no finite bound")
    words = "(mu itself is at least this: no bound of this kind goes below)"
    assert rows[0][4] == f"mu >= {a.certificate.mu_lower:.4g} {words}"
    assert rows[1][4] == "not computed"
    # every row in plain words: what its status says about which robot
    assert rows[0][2].startswith(("Proved: every frozen robot", "Not proved", "Disproved"))
    assert "varying arbitrarily fast" in rows[1][2]
    assert a.certificate.status.value in [s.value for s in Status]
    _check_links(tmp_path, page, r"<img src='([^']+)'")
    _check_links(tmp_path, files.markdown.read_text(), r"!\[[^\]]*\]\(([^)]+)\)")
    _check_cells(page)
    assert "Appendix: discretisation and quantisation" in page and "coverage 1 of 200 fresh points" in page
    val = json.loads(files.validation.read_text())
    assert val["certificates"][FROZEN_ROW]["status"] == a.certificate.status.value
    assert val["discretization"]["rate_hz"] == 100.0
    stored = json.loads((tmp_path / "certificate.json").read_text())  # plain JSON: no NaN
    assert stored["controller"] == "K.json" and list(stored["certificates"]) == [r[0] for r in rows]
    # the μ figure shows the certificate's own sweep, ω = 0 included (real parameters)
    assert stored["certificates"][FROZEN_ROW]["sweep"]["omega"] == a.certificate.mu.omega.tolist()
    assert a.certificate.mu.omega[0] == 0 and "the value at ω = 0 is the point at the left edge" in page

    # `polyrob report DIR`: the problem rebuilt from the files (pipeline), the same certificate rows
    fast = functools.partial(build.validate_controller, rate=None, scenarios=[], **FAST)
    monkeypatch.setattr(build, "validate_controller", fast)
    assert main(["report", str(tmp_path), "--json", "--quiet"]) == (0 if a.certificate.certified else 1)
    doc = json.loads(capsys.readouterr().out)
    again = files.html.read_text()
    assert _verdict(again) == _verdict(page) and doc["status"] == a.certificate.status.value
    assert _certificate_rows(again) == rows
    assert [c["status"] for c in doc["certificates"]] == [r[1] for r in rows] and not doc["notes"]
    _check_links(tmp_path, again, r"<img src='([^']+)'")
    _check_cells(again)


def test_load_run_rebuilds_the_problem(tmp_path, monkeypatch):
    """pipeline.rebuild: the problem of K.json's info on pldi.json; a file without a decided certificate."""
    import polyrob.analysis.certificate as certificate
    from polyrob.pipeline.rebuild import load_run

    robot = polyrob.load_robot("planar_2r")
    pldi = polyrob.bound_pldi(robot, samples=256, coverage=0, progress=False)
    pldi.save(tmp_path / "pldi.json")
    doc = json.loads(FIXTURE.read_text())
    save_controller(load_controller(FIXTURE), tmp_path / "K.json", certificate=doc["certificate"], info=doc["info"])
    save_controller(polyrob.paper_controller(), tmp_path / "K_fixed.json")
    (tmp_path / "certificate.json").write_text(json.dumps({"time-varying": {"feasible": False}}))

    run = load_run(tmp_path, certify_missing=False)
    assert run.problem.hyperparameters == _fixture_problem(pldi).hyperparameters and run.problem.model == "box"
    assert set(run.controllers) == {"fixed"} and run.certificates == {}
    assert any("'time-varying' has no decided status" in n for n in run.notes)
    assert any("no decided certificate" in n for n in run.notes)

    # decided again, by the analysis' own call (on a small grid here)
    monkeypatch.setattr(
        certificate, "certify_loop", functools.partial(certificate.certify_loop, omega=np.logspace(-2, 2, 5))
    )
    run = load_run(tmp_path)
    assert list(run.certificates) == [FROZEN_ROW] and run.certificates[FROZEN_ROW].status is Status.VIOLATED
    assert any("decided again" in n for n in run.notes)

    # a controller made for another problem (here: another domain) is refused
    domain = json.loads(json.dumps(doc["info"]["domain"]))
    domain["qdot"]["joint1"] = [-2.0, 2.0]
    info = dict(doc["info"], domain=domain)
    save_controller(load_controller(FIXTURE), tmp_path / "K.json", info=info)
    with pytest.raises(polyrob.PolyrobError, match="another problem"):
        load_run(tmp_path, certify_missing=False)


def test_load_run_needs_the_run_files(tmp_path):
    from polyrob.pipeline.rebuild import load_run

    with pytest.raises(polyrob.PolyrobError, match="K.json"):
        load_run(tmp_path)


def test_certificates_of_another_controller_are_not_used(tmp_path):
    from polyrob.report.build import read_run_certificates, save_run_certificates

    cert = Certificate(Status.CERTIFIED, 0.8, 0.79, 0.7, None, Scope(frequencies="every frequency"))
    save_run_certificates(tmp_path, {FROZEN_ROW: cert}, "K.json")
    certs, notes = read_run_certificates(tmp_path, "K.json")
    assert list(certs) == [FROZEN_ROW] and certs[FROZEN_ROW]["status"] == "CERTIFIED" and not notes
    certs, notes = read_run_certificates(tmp_path, "K_other.json")
    assert certs == {} and "not of K_other.json" in notes[0]
    with pytest.raises(polyrob.PolyrobError, match="no decided status"):
        write_report(tmp_path, ReportOptions(certificates={"mu": {"peak_mu_upper": 2.43}}))


def test_what_a_run_certifies_instead_survives_a_rebuild(tmp_path):
    """The run's line of what it certifies instead is saved beside its certificates and read back once."""
    from polyrob.report.build import read_run_certificates, save_run_certificates

    cert = Certificate(Status.VIOLATED, 2.1, 2.1, 2.0, None, Scope(frequencies="every frequency"))
    line = "instead: robust performance at level 2.14 for 47 % of the parameter ranges; in the way: ..."
    save_run_certificates(tmp_path, {FROZEN_ROW: cert}, "K.json", notes=(line, line))
    certs, notes = read_run_certificates(tmp_path, "K.json")
    assert certs[FROZEN_ROW]["status"] == "VIOLATED" and notes == [line]


def test_cli_report_json_is_one_document(tmp_path, monkeypatch, capsys):
    """`polyrob report RUN_DIR --json` prints one JSON document naming the files it wrote."""
    from types import SimpleNamespace

    import polyrob.pipeline.rebuild as rebuild
    import polyrob.report.build as build
    from polyrob.cli import main

    cert = Certificate(Status.GRID_ONLY, 0.9, 0.9, 0.8, None, Scope(frequencies="the grid"), ("not checked",))

    def fake_load_run(run_dir, **_):  # the rebuild and the report are tested above; here the CLI's output
        return SimpleNamespace(
            path=Path(run_dir), problem=None, controller=None, controllers={}, certificates={FROZEN_ROW: cert}, notes=()
        )

    def fake_write_run_report(run_dir, *_, **__):
        run_dir = Path(run_dir)
        return SimpleNamespace(
            html=run_dir / "report.html",
            markdown=run_dir / "report.md",
            validation=run_dir / "validation.json",
            figures=[run_dir / "figures" / "mu.png"],
        )

    monkeypatch.setattr(rebuild, "load_run", fake_load_run)
    monkeypatch.setattr(build, "write_run_report", fake_write_run_report)
    assert main(["report", str(tmp_path), "--json", "--quiet"]) == 1  # exit 0 only for CERTIFIED
    doc = json.loads(capsys.readouterr().out)
    assert doc["html"] == str(tmp_path / "report.html") and doc["figures"] == [str(tmp_path / "figures" / "mu.png")]
    assert doc["status"] == "GRID_ONLY" and doc["certified"] is False
    assert doc["verdict"] == (
        "Frozen robot, robust performance: GRID_ONLY, mu < 1 on the frequency grid only (peak 0.9), "
        "not proved between its points"
    )
    assert doc["certificates"][0]["status"] == "GRID_ONLY"


def test_certificate_sweep_is_stored_and_plotted(tmp_path):
    """A certificate's μ sweep (with ω = 0) goes into its record, survives certificate.json, and into mu.png."""
    from types import SimpleNamespace

    from polyrob.report.build import read_run_certificates, save_run_certificates
    from polyrob.report.certificates import certificate_record, certificate_sweep

    w = np.array([0.0, 0.1, 1.0, 10.0])
    mu = SimpleNamespace(omega=w, upper=np.array([1.5, 1.2, np.inf, 0.5]), lower=np.array([1.4, 1.1, 0.9, 0.4]))
    cert = Certificate(Status.VIOLATED, 1.5, 1.5, 1.4, None, Scope(frequencies="the grid"), ("mu >= 1",), mu)
    assert certificate_record(cert)["sweep"]["omega"] == w.tolist()
    save_run_certificates(tmp_path, {FROZEN_ROW: cert})
    certs, _ = read_run_certificates(tmp_path)
    back = certificate_sweep(certs[FROZEN_ROW])
    assert np.array_equal(back[0], w) and np.isnan(back[1][2]) and back[1][0] == 1.5  # inf stored as null
    files = write_report(tmp_path, ReportOptions(certificates=certs))
    page = files.html.read_text()
    assert "figures/mu.png" in page and "the value at ω = 0 is the point at the left edge" in page
    # a certificate without a sweep (a gain) has none
    gain = Certificate(Status.NOT_CERTIFIED, float("inf"), float("nan"), float("nan"), None, Scope(), ("no P",))
    assert "sweep" not in certificate_record(gain) and certificate_sweep(gain) is None


def _first_screen(page: str) -> str:
    """What a reader sees before the first section heading: the verdict, deployment and the problem."""
    return page.split("<h2>", 1)[0]


def test_the_headline_names_its_certificate_and_every_row_reads_in_words(tmp_path):
    """A CERTIFIED headline above a NOT_CERTIFIED row says which certificate it is, and names the others."""
    frozen = Certificate(
        Status.CERTIFIED, 0.9449, 0.94, 0.93, None, Scope(frequencies="every frequency"), mu=SimpleMu()
    )
    fast = Certificate(
        Status.NOT_CERTIFIED,
        5.76,
        float("nan"),
        float("nan"),
        None,
        Scope(variation=ARBITRARY),
        ("performance: scaled small gain 5.76 >= 1",),
    )
    grid = Certificate(Status.GRID_ONLY, 0.96, 0.96, 0.9, None, Scope(kind="robust stability"), ("gave up",))
    certs = {f"{TIME_VARYING_ROW} (scaled small gain)": fast, FROZEN_ROW: frozen, "robust stability": grid}
    files = write_report(tmp_path, ReportOptions(certificates=certs))
    page = files.html.read_text()
    top = _first_screen(page)
    assert "<p id='verdict'>Frozen robot, robust performance: CERTIFIED, mu &lt;= 0.9449 at every frequency</p>" in top
    assert (
        "Other certificates (table below): arbitrarily fast variation (scaled small gain): NOT_CERTIFIED; "
        "robust stability: GRID_ONLY." in top
    )
    rows = _certificate_rows(page)
    assert [r[1] for r in rows] == ["NOT_CERTIFIED", "CERTIFIED", "GRID_ONLY"]
    assert [r[2] for r in rows] == [
        "Not proved either way: it is not shown that the robot with its parameters varying arbitrarily fast in the "
        "set meets the performance weights (performance: scaled small gain 5.76 >= 1)",
        "Proved: every frozen robot of the set meets the performance weights (mu <= 0.9449 at every frequency)",
        "Not proved: every frozen robot of the set is stable at the frequencies of the grid (peak mu 0.96), "
        "but nothing is shown between them",
    ]


class SimpleMu:
    """A sweep's shape (the report plots it)."""

    omega = np.array([0.1, 1.0])
    upper = np.array([0.9, 0.94])
    lower = np.array([0.8, 0.93])


def test_deployment_blockers_are_on_the_first_screen(tmp_path):
    """The word length (39 bits, an appendix figure) and the sample rate, called out before any section."""
    disc = {
        "rate_hz": 1000.0,
        "discrete_loop_stable": True,
        "mu_continuous_grid": 0.9352,
        "mu_discrete_grid": 0.9352,
        "min_rate_hz": 19.11,
        "min_word_length_bits": 39,
        "sections": 16,
    }
    cert = Certificate(Status.CERTIFIED, 0.9449, 0.94, 0.93, None, Scope(frequencies="every frequency"))
    page = write_report(tmp_path, ReportOptions(certificates={FROZEN_ROW: cert}, discretization=disc)).html.read_text()
    top = _first_screen(page)
    assert "<p id='deployment' class='bad'>Deployment: run the controller at 1000 Hz" in top
    assert "the lowest rate keeping mu within 5 % of it: 19.11 Hz" in top
    assert "BLOCKER: its 16 second-order sections need 39-bit fixed-point coefficients, more than a 32-bit word" in top
    # a controller that fits a 32-bit word is no blocker; an unstable sampled loop is
    fits = write_report(tmp_path, ReportOptions(discretization=dict(disc, min_word_length_bits=24))).html.read_text()
    assert "<p id='deployment'>Deployment:" in fits and "they fit a 32-bit word" in fits and "BLOCKER" not in fits
    unstable = write_report(tmp_path, ReportOptions(discretization=dict(disc, discrete_loop_stable=False)))
    assert "BLOCKER: sampled at 1000 Hz the discretised loop is unstable" in unstable.html.read_text()


def test_the_paper_controller_is_compared_only_on_the_papers_problem():
    from types import SimpleNamespace

    from polyrob.report.build import _paper_reference

    paper = polyrob.load_robot("paper_2r")
    assert list(_paper_reference(SimpleNamespace(robot=paper, domain=polyrob.Domain.from_robot(paper)))) == ["paper K*"]
    smaller = polyrob.Domain.from_robot(paper, qdot_scale=0.5)
    assert _paper_reference(SimpleNamespace(robot=paper, domain=smaller)) == {}
    twin = polyrob.load_robot("planar_2r")  # the physical twin, on its own domain (the main job's)
    assert _paper_reference(SimpleNamespace(robot=twin, domain=polyrob.Domain.from_robot(twin))) == {}


def test_torques_are_plotted_on_their_own_scale(tmp_path, monkeypatch):
    """Torques of about 1 N m against +-100 N m limits: the axis fits the torques, the limits are named."""
    from polyrob.report import plots

    figs = []
    save = plots.save_figure
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figs.append(fig) or save(fig, path))
    robot = polyrob.load_robot("planar_2r")
    sim = simulate(
        robot, polyrob.paper_controller(), polyrob.Domain.from_robot(robot), step_reference([5e-4, -2e-4]), t_final=1.0
    )
    peak = float(np.abs(sim.u).max())
    assert {mt.effort_limit for mt in sim.metrics} == {100.0} and peak < 20
    plots.plot_tracking([sim], tmp_path / "tracking.png")
    torque = figs[0].axes[-1]
    assert torque.get_ylim()[1] < 2 * peak and not any(line.get_ydata()[0] == 100.0 for line in torque.lines)
    assert "limits ±100 N·m off scale" in torque.get_title()
    # torques near their limit: the limit lines are drawn
    assert plots.limits_on_scale([100.0], [[60.0, -90.0]]) == ([100.0], [])
