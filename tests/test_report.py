"""The report: every file the HTML references exists, every PNG is a valid image, verdicts are shown."""

from __future__ import annotations

import functools
import json
import re
from pathlib import Path

import numpy as np
import pytest

import polyrob
from polyrob.io.controller import load_controller, save_controller
from polyrob.report.html import write_report
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


def test_report_references_existing_valid_pngs(tmp_path):
    pldi, unc, P = _paper()
    K = polyrob.paper_controller()
    mc = monte_carlo(P, K, n=3, seed=0, omega=np.logspace(-2, 3, 60))
    robot = polyrob.load_robot("planar_2r")
    dom = polyrob.Domain.from_robot(robot)
    inside = simulate(robot, K, dom, step_reference([0.005, -0.002]), t_final=4.0)
    outside = simulate(robot, K, dom, step_reference([0.2, -0.1]), t_final=1.0)
    w = np.logspace(-2, 2, 5)
    files = write_report(
        tmp_path,
        robot_name="paper_2r",
        pldi=pldi,
        unc=unc,
        controller=K,
        controllers={"other": 0.5 * K},
        monte_carlo=mc,
        simulations=[inside, outside],
        certificates={
            "constant-parameter μ": {"peak_mu_upper": 2.43, "certified": False},
            "time-varying (quadratic)": {"feasible": False, "gamma": float("inf")},
        },
        discretization={"rate_hz": 1000.0, "min_word_length_bits": 24, "spectral_radius": 0.99999997},
        mu_curves={"robust performance": (w, 2 * np.ones(5), 1.9 * np.ones(5))},
    )
    page = files.html.read_text()
    refs = _check_links(tmp_path, page, r"<img src='([^']+)'")
    assert set(refs) == {f"figures/{p.name}" for p in files.figures}
    assert {"pldi_bode.png", "sensitivities.png", "controllers.png", "mu.png", "tracking.png"} <= {
        Path(r).name for r in refs
    }
    _check_links(tmp_path, files.markdown.read_text(), r"!\[[^\]]*\]\(([^)]+)\)")
    # self-contained: no scripts, stylesheets or remote resources
    assert "<script" not in page and "http" not in page.replace("http-equiv", "")
    # the verdicts: the run that left the domain in red, the certificates, the PLDI table, the 0.99999997
    assert "class='bad'" in page and "LEFT THE DOMAIN" in page
    assert "time-varying (quadratic)" in page and "b42" in page and "0.99999997" in page
    val = json.loads(files.validation.read_text())
    assert [s["stayed_in_domain"] for s in val["simulations"]] == [True, False]
    # rewriting replaces the files atomically: no temporary files left
    write_report(tmp_path, robot_name="paper_2r", simulations=[inside])
    assert not list(tmp_path.rglob("*.tmp"))


def test_build_report_from_run_directory(tmp_path):
    """`polyrob report RUN_DIR`: rebuilt from K.json + pldi.json (+ certificate.json, K_*.json)."""
    robot = polyrob.load_robot("planar_2r")
    pldi = polyrob.bound_pldi(robot, samples=256, coverage=200, progress=False)
    pldi.save(tmp_path / "pldi.json")
    doc = json.loads(FIXTURE.read_text())
    save_controller(
        load_controller(FIXTURE),
        tmp_path / "K.json",
        certificate=doc["certificate"],
        info={
            "weights": {
                k: list(v) for k, v in __import__("polyrob.plant.weights", fromlist=["x"]).PAPER_HYPERPARAMETERS.items()
            },
            "uncertainty": {"requested": "box", "merge_symmetric": False},
        },
    )
    save_controller(polyrob.paper_controller(), tmp_path / "K_fixed.json")
    (tmp_path / "certificate.json").write_text(json.dumps({"time-varying": {"feasible": False}}))
    from polyrob.report.build import build_report

    files = build_report(
        tmp_path,
        rate=100.0,
        mc=3,
        mu_omega=np.logspace(-2, 2, 8),
        search_rate=False,
        word_lengths=(30, 34),
        discrete_omega=np.logspace(-2, 2, 4),
    )
    page = files.html.read_text()
    _check_links(tmp_path, page, r"<img src='([^']+)'")
    assert "time-varying" in page and "reduced:9" in page and "Discretisation and quantisation" in page
    val = json.loads(files.validation.read_text())
    assert len(val["simulations"]) == 3  # continuous step, sampled step at 100 Hz, smooth move
    assert val["simulations"][1]["rate_hz"] == 100.0
    assert val["discretization"]["rate_hz"] == 100.0 and val["discretization"]["discrete_loop_stable"]


def test_build_report_needs_the_run_files(tmp_path):
    from polyrob.report.build import build_report

    with pytest.raises(polyrob.PolyrobError, match="K.json"):
        build_report(tmp_path)


def test_cli_report_json_is_one_document(tmp_path, monkeypatch, capsys):
    """`polyrob report RUN_DIR --json` prints one JSON document naming the files it wrote."""
    from types import SimpleNamespace

    import polyrob.report.build as build
    from polyrob.cli import main

    def fake_build_report(run_dir, **_):  # the report itself is tested above; here the CLI's output
        run_dir = Path(run_dir)
        return SimpleNamespace(
            html=run_dir / "report.html",
            markdown=run_dir / "report.md",
            validation=run_dir / "validation.json",
            figures=[run_dir / "figures" / "mu.png"],
        )

    monkeypatch.setattr(build, "build_report", fake_build_report)
    assert main(["report", str(tmp_path), "--json", "--quiet"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["html"] == str(tmp_path / "report.html") and doc["figures"] == [str(tmp_path / "figures" / "mu.png")]
