"""Generated C: compiles with -std=c99 -Wall -Werror and reproduces the Python discrete controller."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import polyrob
from polyrob.validate.discretize import discretize
from polyrob.validate.export_c import write_c, write_json
from polyrob.validate.quantize import SOSController, quantize, sos_realization

CC = shutil.which("cc") or shutil.which("gcc")
FIXTURE = Path(__file__).parent / "fixtures" / "validate_planar_2r_K.json"
N_STEPS = 400


@pytest.fixture
def cc():
    """The C compiler; its absence skips locally but fails on CI (.ci/run installs gcc)."""
    if CC is None:
        if os.environ.get("CI"):
            pytest.fail("no C compiler on CI: .ci/run must install one, the C export is not checked without it")
        pytest.skip("no C compiler")
    return CC


HARNESS = r"""
#include <stdio.h>
#include "controller.h"
int main(void)
{
    int j, k, i;
    for (j = 0; j < CONTROLLER_N_INPUTS; ++j) {
        controller_state_t st;
        controller_reset(&st);
        for (k = 0; k < N_STEPS; ++k) {
            double e[CONTROLLER_N_INPUTS] = {0};
            double u[CONTROLLER_N_OUTPUTS];
            e[j] = 1.0;
            controller_step(&st, e, u);
            for (i = 0; i < CONTROLLER_N_OUTPUTS; ++i) printf("%.17g\n", u[i]);
        }
    }
    return 0;
}
""".replace("N_STEPS", str(N_STEPS))


#: What the exported C must compile under without a warning (also tests/test_export_run.py).
STRICT_C99 = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]


def _run_c(cc, sos, tmp_path):
    write_c(sos, tmp_path)
    (tmp_path / "main.c").write_text(HARNESS)
    exe = tmp_path / "harness"
    subprocess.run(
        [
            cc,
            *STRICT_C99,
            "-o",
            str(exe),
            str(tmp_path / "main.c"),
            str(tmp_path / "controller.c"),
        ],
        check=True,
        capture_output=True,
    )
    out = np.array(
        [float(x) for x in subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split()]
    )
    m_in, m_out = sos.n_inputs, sos.n_outputs
    return out.reshape(m_in, N_STEPS, m_out).transpose(2, 0, 1)  # [i, j, k]


@pytest.mark.parametrize("word_length", [None, 24])
def test_c_step_response_matches_python(cc, tmp_path, word_length):
    dc = discretize(polyrob.paper_controller(), 1000.0, method="tustin", prewarp=10.0)
    sos = sos_realization(dc)
    if word_length is not None:
        sos = quantize(sos, word_length)
    c_out = _run_c(cc, sos, tmp_path)
    # the Python sections, same operation order: equal to rounding
    for j in range(2):
        e = np.zeros((2, N_STEPS))
        e[j] = 1.0
        py = sos.run(e)
        assert np.max(np.abs(c_out[:, j] - py) / np.maximum(1.0, np.abs(py))) <= 1e-12
    if word_length is None:
        # and the discrete state-space controller (another realisation) to 1e-9
        ref = dc.step_response(N_STEPS)
        assert np.max(np.abs(c_out - ref) / np.maximum(1.0, np.abs(ref))) <= 1e-9
        # the value itself: K*(z) at z = 1 equals K*(0) (Tustin keeps DC), the step tends to it slowly;
        # the first sample is D of the Tustin map
        assert c_out[0, 0, 0] == pytest.approx(float(np.asarray(dc.system.D)[0, 0]), rel=1e-12)


def test_c_float_compiles(cc, tmp_path):
    sos = sos_realization(discretize(polyrob.paper_controller(), 500.0, method="zoh"))
    write_c(sos, tmp_path, real="float")
    subprocess.run(
        [cc, "-std=c99", "-Wall", "-Werror", "-c", "-o", str(tmp_path / "c.o"), str(tmp_path / "controller.c")],
        check=True,
        capture_output=True,
    )


def test_quantised_coefficients_are_fixed_point(tmp_path):
    sos = sos_realization(discretize(polyrob.paper_controller(), 1000.0, prewarp=10.0))
    q = quantize(sos, 16)
    for i, j, secs in q.entries():
        for s, (fb, fa) in zip(secs, q.formats[i][j]):
            mant_b, mant_a = s[:3] * 2.0**fb, s[4:] * 2.0**fa
            assert np.all(mant_b == np.round(mant_b)) and np.all(mant_a == np.round(mant_a))
            assert np.all(np.abs(mant_b) <= 2**15) and np.all(np.abs(mant_a) <= 2**15)
    # rounding error at most half an LSB of each format
    for (i, j, a), (_, _, b) in zip(sos.entries(), q.entries()):
        lsb_b = 2.0 ** -q.formats[i][j][:, 0]
        assert np.all(np.abs(a[:, :3] - b[:, :3]) <= 0.5 * lsb_b[:, None] + 1e-300)
    path = write_json(q, tmp_path / "controller.json")
    back = SOSController.from_dict(json.loads(path.read_text()))
    assert back.word_length == 16 and np.array_equal(back.sections[1][0], q.sections[1][0])


def test_sos_matches_state_space():
    dc = discretize(polyrob.paper_controller(), 1000.0, prewarp=10.0)
    sos = sos_realization(dc)
    assert [s.shape[0] for _, _, s in sos.entries()] == [2, 2, 2, 2]  # third order per entry: 2 biquads
    z = np.exp(1j * np.array([1e-4, 1e-2, 0.3, 2.0]))
    H, R = sos.to_ss()(z), dc.system(z)
    assert np.max(np.abs(H - R) / np.abs(R)) < 1e-8


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory):
    """A run directory of the paper's K* on paper_2r: K.json recording its problem, pldi.json beside it."""
    from polyrob.io.controller import save_controller
    from polyrob.pipeline import build_problem

    run = tmp_path_factory.mktemp("run")
    robot = polyrob.load_robot("paper_2r")
    pldi = polyrob.bound_pldi(robot, samples=256, coverage=0, progress=False)
    problem = build_problem(robot, pldi=pldi, uncertainty="box")
    pldi.save(run / "pldi.json")
    save_controller(polyrob.paper_controller(), run / "K.json", info=problem.description())
    return run


def test_export_refuses_a_word_length_the_analysis_rules_out(paper_run, tmp_path, capsys):
    """K* at 1000 Hz: 24 bits move its DC gain by 14.7 % (35 bits keep poles and DC gains): refused in one
    line, exit 2, naming 35; --force writes it with both checks' warnings (the μ analysis asks for 25);
    35 is written without one."""
    from polyrob.cli import main

    K = str(paper_run / "K.json")
    out = tmp_path / "ctrl"
    assert main(["export", K, "--rate", "1000", "--word-length", "24", "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("polyrob: error: export refused: 24-bit")
    assert "DC gain moves by 14.7 %" in err and "is 35 bits (--word-length 35)" in err and "--force" in err
    assert not (out / "controller.c").exists()

    assert main(["export", K, "--rate", "1000", "--word-length", "24", "-o", str(out), "--force", "--json"]) == 0
    cap = capsys.readouterr()
    warnings = [line for line in cap.err.splitlines() if line.startswith("polyrob: warning:")]
    assert len(warnings) == 2 and "35 bits" in warnings[0] and "written anyway (--force)" in warnings[0]
    assert "the smallest word length that does is 25 bits" in warnings[1]
    doc = json.loads(cap.out)
    assert doc["word_length"] == 24 and doc["word_length_check"]["ok"] is False
    assert doc["word_length_check"]["smallest_word_length"] == 25 and doc["smallest_word_length"] == 35
    assert "24-bit fixed-point" in (out / "controller.h").read_text()

    assert main(["export", K, "--rate", "1000", "--word-length", "35", "-o", str(out), "--json", "--quiet"]) == 0
    cap = capsys.readouterr()
    assert "warning" not in cap.err and json.loads(cap.out)["word_length_check"]["ok"] is True


def test_export_refuses_a_rate_the_loop_mu_rules_out(paper_run, tmp_path, capsys):
    """K* at 50 Hz passes the crossover rule (44.1 Hz on the nominal arm) but the discretised loop's μ is 5.5 %
    above the continuous loop's: refused in one line naming the rate that keeps it; --allow-low-rate warns."""
    from polyrob.cli import main

    argv = ["export", str(paper_run / "K.json"), "--rate", "50", "--word-length", "40", "-o", str(tmp_path / "c")]
    assert main([*argv, "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("polyrob: error: --rate 50: too low")
    assert "(exact coefficients) is μ 2.592 above 2.457" in err and "from about 8" in err
    assert main([*argv, "--allow-low-rate", "--json"]) == 0
    cap = capsys.readouterr()
    doc = json.loads(cap.out)
    rate = doc["word_length_check"]["rate"]
    assert rate["ok"] is False and rate["mu"] == pytest.approx(2.592, abs=1e-3)
    assert doc["word_length_check"]["checked"] is False  # no word length keeps μ at a rate that loses it
    assert "--rate 50 Hz is too low" in cap.err
    assert "μ of the discretised loop at this rate: NOT kept" in (tmp_path / "c" / "controller.h").read_text()


def test_export_refusal_when_no_word_length_works(tmp_path, capsys):
    """The issue's controller: no word length up to 40 bits keeps its discretised loop stable."""
    from polyrob.cli import main
    from polyrob.io.controller import load_controller, save_controller

    doc = json.loads(FIXTURE.read_text())
    robot = polyrob.load_robot("planar_2r")
    dom = polyrob.Domain.from_dict(doc["info"]["domain"])
    polyrob.bound_pldi(robot, dom, samples=256, coverage=0, progress=False).save(tmp_path / "pldi.json")
    save_controller(load_controller(FIXTURE), tmp_path / "K.json", info=doc["info"])
    out = tmp_path / "ctrl"
    argv = ["export", str(tmp_path / "K.json"), "--rate", "1000", "--word-length", "24", "-o", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "moves by 89.7 % of its distance to z = 1" in err and "is 52 bits" in err
    assert not out.exists() or not list(out.iterdir())
    assert main([*argv, "--force", "--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.err.count("polyrob: warning:") == 2 and "no word length up to 40 bits does" in cap.err
    assert (out / "controller.c").is_file()


def test_export_without_a_problem_warns(tmp_path, capsys):
    """A controller file that records no problem: the word length cannot be checked; written, with a warning."""
    from polyrob.cli import main
    from polyrob.io.controller import save_controller

    save_controller(polyrob.paper_controller(), tmp_path / "K.json")
    out = tmp_path / "ctrl"
    assert main(["export", str(tmp_path / "K.json"), "--rate", "500", "--word-length", "33", "-o", str(out)]) == 0
    cap = capsys.readouterr()
    assert cap.err.count("polyrob: warning:") == 1
    assert "polyrob: warning: 33-bit coefficients not checked" in cap.err and "--pldi" in cap.err
    assert (out / "controller.c").is_file()
