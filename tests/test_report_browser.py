"""The run report as a reader gets it: labelled figures, valid HTML, and a real (headless Chromium) rendering.

Every figure of report/plots.py has axis labels with units and a title; the
μ figure spans the certificate's whole grid, ω = 0 included.  The page is
the report of tests/test_report.py's fast fixtures (the planar_2r controller
analysed as `polyrob run` does, on small grids).  The HTML check
runs everywhere; the screenshot needs a Chromium binary (Debian's
``chromium``): without one it is skipped locally and fails under CI, where
.ci/run must install it (``apt-get install -y chromium``).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from test_report import FAST, _paper, _run, _write_run_files

import polyrob
from polyrob.validate.monte_carlo import monte_carlo
from polyrob.validate.simulate import simulate, step_reference

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "screenshot_report.py"
#: Elements without an end tag (HTML's void elements).
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


def _axes_labels(fig):
    """``(xlabel, ylabel, title)`` of every axes of a figure that holds data."""
    return [(ax.get_xlabel(), ax.get_ylabel(), ax.get_title()) for ax in fig.axes if ax.has_data()]


def test_every_figure_has_axis_labels_with_units_and_a_title(tmp_path, monkeypatch):
    """Each figure function of report/plots.py: every axes labelled with units, and titled."""
    from polyrob.report import plots

    figs = {}
    save = plots.save_figure
    monkeypatch.setattr(
        plots, "save_figure", lambda fig, path: figs.setdefault(Path(path).name, fig) and save(fig, path)
    )
    pldi, unc, P = _paper()
    K = polyrob.paper_controller()
    mc = monte_carlo(P, K, n=2, seed=0, omega=np.logspace(-2, 3, 40))
    robot = polyrob.load_robot("planar_2r")
    sim = simulate(robot, K, polyrob.Domain.from_robot(robot), step_reference([0.005, -0.002]), t_final=1.0)
    w = np.logspace(-2, 2, 5)
    plots.plot_pldi_bode(unc, tmp_path / "bode.png", n=2, omega=w)
    plots.plot_sensitivities(mc, tmp_path / "s.png")
    plots.plot_steps(mc, tmp_path / "steps.png")
    plots.plot_controllers({"K*": K}, tmp_path / "k.png", omega=w)
    plots.plot_mu({"rp": (w, 2 * np.ones(5), 1.9 * np.ones(5))}, tmp_path / "mu.png")
    plots.plot_tracking([sim], tmp_path / "tracking.png", joint_names=["joint1", "joint2"])
    assert set(figs) == {"bode.png", "s.png", "steps.png", "k.png", "mu.png", "tracking.png"}
    units = {
        "bode.png": ("rad/s", "dB, rad/N·m"),
        "s.png": ("rad/s", "dB"),
        "steps.png": ("(s)", "(rad)"),
        "k.png": ("rad/s", "dB, N·m/rad"),
        "mu.png": ("rad/s", "absolute"),
        "tracking.png": ("(s)", ""),
    }
    for name, fig in figs.items():
        labels = _axes_labels(fig)
        assert labels, name
        for xlabel, ylabel, title in labels:
            assert units[name][0] in xlabel and units[name][1] in ylabel, (name, xlabel, ylabel)
            assert re.search(r"\(.+\)", ylabel) and title, (name, ylabel, title)
        assert len(labels) == 1 or fig.get_suptitle(), f"{name}: no overall title"
    ylabels = [y for _, y, _ in _axes_labels(figs["tracking.png"])]
    assert ylabels == ["joint1 (rad)", "joint2 (rad)", "torque (N·m)"]
    # a prismatic joint: m and N
    plots.plot_tracking([sim], tmp_path / "t2.png", kinds=["revolute", "prismatic"])
    assert [y for _, y, _ in _axes_labels(figs["t2.png"])][1:] == ["joint 2 (m)", "effort (N·m, N)"]


def test_mu_plot_shows_the_whole_grid_and_omega_zero(tmp_path, monkeypatch):
    """The issue: the μ figure stopped at 1e-3 rad/s while the peak was at ω = 0."""
    from polyrob.report import plots

    figs = []
    save = plots.save_figure
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: figs.append(fig) or save(fig, path))
    cert_w = np.concatenate([[0.0], np.logspace(-5, 2, 8)])  # the certificate's grid: lower, with ω = 0
    up = np.linspace(3.0, 0.5, 9)  # peak 3 at ω = 0
    curves = {
        "certificate: frozen robot (μ)": (cert_w, up, 0.9 * up),
        "report's curve": (np.logspace(-3, 2, 6), np.linspace(2.5, 0.5, 6), None),
    }
    plots.plot_mu(curves, tmp_path / "mu.png")
    (ax,) = figs[0].axes
    left, right = ax.get_xlim()
    assert left < 1e-5 and right >= 1e2  # the whole grid, from its lowest frequency
    points = [ln for ln in ax.get_lines() if ln.get_marker() == "o"]
    assert points and points[0].get_xdata()[0] < 1e-5 and points[0].get_ydata()[0] == 3.0
    assert "ω = 0" in [t.get_text() for t in ax.texts]
    labels = [t.get_text() for t in figs[0].legends[0].get_texts()]
    assert "certificate: frozen robot (μ): upper (peak 3 at ω = 0)" in labels
    # without ω = 0: no such point; the axis starts at the lowest frequency
    figs.clear()
    plots.plot_mu({"rp": (np.logspace(-4, 1, 5), np.ones(5), None)}, tmp_path / "mu2.png")
    (ax,) = figs[0].axes
    assert ax.get_xlim()[0] == pytest.approx(1e-4) and "ω = 0" not in [t.get_text() for t in ax.texts]


class _Checker(HTMLParser):
    """Tags balanced (every start tag closed in order), and every <img> with alt text and a src."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.stack, self.errors, self.images, self.doctype = [], [], [], False

    def handle_decl(self, decl):
        self.doctype = self.doctype or decl.lower().startswith("doctype html")

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.images.append(dict(attrs))
        if tag not in VOID:
            self.stack.append((tag, self.getpos()))

    def handle_startendtag(self, tag, attrs):
        if tag == "img":
            self.images.append(dict(attrs))
        elif tag not in VOID:
            self.errors.append(f"<{tag}/> at {self.getpos()}: not a void element")

    def handle_endtag(self, tag):
        if tag in VOID:
            self.errors.append(f"</{tag}> at {self.getpos()}: a void element has no end tag")
        elif not self.stack or self.stack[-1][0] != tag:
            open_ = self.stack[-1] if self.stack else None
            self.errors.append(f"</{tag}> at {self.getpos()} closes {open_}")
        else:
            self.stack.pop()


def check_html(page: Path) -> list[dict]:
    """Assert the page is well formed and its images are described and present; returns the <img> attributes."""
    checker = _Checker()
    checker.feed(page.read_text(encoding="utf-8"))
    checker.close()
    assert checker.doctype, "no <!DOCTYPE html>"
    assert not checker.errors, checker.errors[:5]
    assert not checker.stack, f"unclosed tags: {checker.stack[:5]}"
    assert checker.images, "the page shows no figure"
    for img in checker.images:
        assert (img.get("alt") or "").strip(), f"<img src={img.get('src')!r}> has no alt text"
        src = img.get("src") or ""
        assert src and not src.startswith(("http:", "https:", "/")), f"<img> src {src!r}: not a relative path"
        assert (page.parent / src).is_file(), f"<img> src {src!r} does not exist"
    return checker.images


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    """report.html of test_report's fast run fixture, written as `polyrob run -o DIR` writes it."""
    import polyrob.report.build as build
    from polyrob.cli.run import report_certificates

    run = tmp_path_factory.mktemp("run")
    problem, K, a = _run()
    _write_run_files(run, problem, K, a)
    q0 = np.asarray(problem.pldi.nominal_point["q"], float)
    files = build.write_run_report(
        run,
        problem,
        K,
        certificates=report_certificates(a),
        rate=100.0,
        scenarios=[(step_reference(q0 + 0.002), {"t_final": 3.0})],
        discrete_omega=np.logspace(-2, 2, 4),
        **FAST,
    )
    return files.html


def test_report_html_is_valid(report):
    images = check_html(report)
    # the fixture's one simulation is a step: a raw figure of the appendix
    assert {Path(i["src"]).name for i in images} >= {"mu.png", "controllers.png", "tracking_steps.png"}
    page = report.read_text(encoding="utf-8")
    assert "name='viewport'" in page and "<div class='scroll'><table id='certificates'>" in page


def test_checker_finds_faults(tmp_path):
    """The checker itself: an unclosed tag, an image without alt text, a missing image."""
    (tmp_path / "a.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    page = tmp_path / "r.html"
    cases = {
        "<body><p><b>x</p></body></html>": "closes",
        "<body><p><img src='a.png'></p></body></html>": "no alt text",
        "<body><p><img src='b.png' alt='b'></p></body></html>": "does not exist",
        "<body><p><img src='a.png' alt='a'></p>": "unclosed",
    }
    for body, words in cases.items():
        page.write_text(f"<!DOCTYPE html><html>{body}")
        with pytest.raises(AssertionError, match=words):
            check_html(page)
    page.write_text("<!DOCTYPE html><html><body><p><img src='a.png' alt='a'><br></p></body></html>")
    assert check_html(page) == [{"src": "a.png", "alt": "a"}]


@pytest.fixture(scope="module")
def chromium() -> str:
    """The Chromium binary; its absence skips locally but fails on CI (checked before the report is built)."""
    sys.path.insert(0, str(SCRIPT.parent))
    try:
        from screenshot_report import find_chromium
    finally:
        sys.path.remove(str(SCRIPT.parent))
    path = find_chromium()
    if path is None:
        if os.environ.get("CI"):
            pytest.fail("no chromium on CI: .ci/run must install it (apt-get install -y chromium)")
        pytest.skip("no chromium (apt-get install -y chromium)")
    return path


@pytest.mark.timeout(600)
def test_report_renders_in_chromium(chromium, report, tmp_path):
    """scripts/screenshot_report.py: 1366 px and 390 px wide PNGs, neither blank, the verdict on the first screen."""
    from PIL import Image

    bad_verdict = "<p id='verdict' class='bad'>" in report.read_text(encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), str(report), "-o", str(tmp_path), "--chromium", chromium],
        capture_output=True,
        text=True,
        timeout=540,
    )
    assert proc.returncode == 0, proc.stderr
    shots = json.loads(proc.stdout)["screenshots"]
    assert (shots["desktop"]["width"], shots["phone"]["width"]) == (1366, 390)
    for shot in shots.values():
        with Image.open(shot["path"]) as im:
            px = np.asarray(im.convert("RGB"))
        assert px.shape[1] == shot["width"] and px.shape[0] == shot["height"]
        colours = np.unique(px.reshape(-1, 3), axis=0)
        assert len(colours) > 10, f"{shot['path']}: a blank page ({len(colours)} colours)"
        dark = (px.sum(axis=2) < 200).mean()
        assert dark > 0.002, f"{shot['path']}: no text ({dark:.2%} dark pixels)"
        if bad_verdict:  # a verdict other than CERTIFIED is red, and on the first screen: red near the top
            top = px[: px.shape[0] // 3].astype(int)
            red = (top[..., 0] > 150) & (top[..., 1] < 80) & (top[..., 2] < 80)
            assert red.sum() > 50, f"{shot['path']}: no red verdict near the top"
