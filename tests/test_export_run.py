"""`polyrob export` as a new user runs it (issue 39, item 5): every defect they met has a test here.

1. one meaning and one unit per signal in the header, with the rate, delay and coefficients;
2. a rate too low for the controller refused (``--allow-low-rate`` writes it with a warning);
3. rounded coefficients checked against the exact discrete controller (poles, DC gains);
4. ``--word-length`` on a controller file that ``synth -o`` writes on an arm's task (inner layer);
5. the smallest word length printed, and a shorter one refused;
6. output saturation with anti-windup and a bumpless start, in the C;
7. the compiled C closed around the simulated arm reproduces the Python discrete loop.
"""

from __future__ import annotations

import ctypes
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from test_export_c import STRICT_C99

import polyrob
from polyrob.cli import main
from polyrob.io.controller import load_controller, save_controller
from polyrob.validate.discretize import discretize
from polyrob.validate.export_c import write_c
from polyrob.validate.quantize import quantize, sos_realization

CC = shutil.which("cc") or shutil.which("gcc")
#: a controller file as `synth -o` writes it on planar_2r's task: a PID behind a computed-torque inner layer
SYNTH_FILE = Path(__file__).parent / "fixtures" / "planar_2r_ct_pid_K.json"


@pytest.fixture
def cc():
    if CC is None:
        pytest.skip("no C compiler")
    return CC


def _export(capsys, *argv):
    code = main(["export", *map(str, argv)])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _library(cc, out: Path) -> ctypes.CDLL:
    lib = out / "libcontroller.so"
    subprocess.run(
        [
            cc,
            *STRICT_C99,
            "-shared",
            "-fPIC",
            "-o",
            str(lib),
            str(out / "controller.c"),
            "-lm",
        ],
        check=True,
        capture_output=True,
    )
    return ctypes.CDLL(str(lib))


class _C:
    """The exported controller through ctypes (the state struct: 2 n_sections + 2 n_outputs doubles)."""

    def __init__(self, lib, n_sections, n_in, n_out):
        self.lib, self.n_in, self.n_out = lib, n_in, n_out
        self.state = (ctypes.c_double * (2 * max(1, n_sections) + 2 * n_out))()
        lib.controller_reset(self.state)

    def step(self, e):
        u = (ctypes.c_double * self.n_out)()
        self.lib.controller_step(self.state, (ctypes.c_double * self.n_in)(*e), u)
        return np.array(u[:])

    def bumpless(self, e, u):
        self.lib.controller_bumpless(self.state, (ctypes.c_double * self.n_in)(*e), (ctypes.c_double * self.n_out)(*u))

    def set_limits(self, lo, hi):
        self.lib.controller_set_limits(
            self.state, (ctypes.c_double * self.n_out)(*lo), (ctypes.c_double * self.n_out)(*hi)
        )


# 1. the header ------------------------------------------------------------------------------------------


def test_header_gives_one_meaning_and_unit_per_signal(tmp_path, capsys):
    """Inner layer: u is v, rad/s^2, and what the inner layer computes; no torque deviation. Torque: N m."""
    code, _, _ = _export(capsys, SYNTH_FILE, "--rate", "1000", "-o", tmp_path / "ct", "--quiet")
    assert code == 0
    head = (tmp_path / "ct" / "controller.h").read_text()
    assert "e[j] = r[j] - q[j], the tracking error of joint j" in head and "position), rad" in head
    assert "u[i] = v[i], the acceleration command of joint i, rad/s^2" in head
    assert "tau = M_hat(q) v + h_hat(q, qdot) (N m)" in head
    assert "torque deviation" not in head  # before: "u the joint torque deviation", then "u is the outer input v"
    assert "sample rate: 1000 Hz" in head and "computation delay:" in head and "coefficients: double precision" in head
    assert "output limits, rad/s^2" in head and "acceleration bounds qddot" in head

    save_controller(polyrob.paper_controller(), tmp_path / "K.json", info={"robot": "planar_2r", "m": 2})
    code, _, _ = _export(capsys, tmp_path / "K.json", "--rate", "1000", "-o", tmp_path / "tq", "--quiet")
    head = (tmp_path / "tq" / "controller.h").read_text()
    assert code == 0 and "u[i] = the torque deviation of joint i, N m" in head and "rad/s^2" not in head
    assert "URDF effort limits of planar_2r" in head


# 2. the rate ---------------------------------------------------------------------------------------------


def test_rate_too_low_is_refused_in_one_line(tmp_path, capsys):
    """The PID on the inner layer's double integrator crosses over at 4.19 rad/s: the hold's half-sample delay
    costs 10 degrees there at 12 Hz; 10 Hz is refused in one line naming 12 Hz, --allow-low-rate warns."""
    out = tmp_path / "ctrl"
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "10", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "--rate 10: too low" in err and "its lowest rate is 12 Hz" in err
    assert "crossover, 4.188 rad/s" in err
    assert not out.exists() or not list(out.iterdir())
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "10", "--allow-low-rate", "-o", out, "--quiet")
    assert code == 0 and err.count("polyrob: warning: --rate 10 Hz is too low") == 1
    assert " * WARNING: --rate 10 Hz is too low for this controller" in (out / "controller.h").read_text()
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "12.5", "-o", out, "--quiet")
    assert code == 0 and "warning" not in err


def _certified_at(tmp_path, rate, delay) -> Path:
    """SYNTH_FILE as `synth --rate RATE --delay DELAY -o` records it: the sampled loop's rate, delay and hold."""
    doc = json.loads(SYNTH_FILE.read_text())
    doc["certificate"]["sampled"] = {"rate_hz": rate, "delay_samples": delay, "hold": "zero-order", "words": "..."}
    path = tmp_path / f"K_{rate:g}.json"
    path.write_text(json.dumps(doc))
    return path


def test_export_runs_at_the_certified_rate_and_says_its_delay(tmp_path, capsys):
    """A file certified at 1 kHz with one sample of delay: exported at 1 kHz without --rate, and the header
    states the delay the certificate assumed (before: --rate was required and the header said no delay)."""
    path = _certified_at(tmp_path, 1000.0, 1)
    code, stdout, _ = _export(capsys, path, "-o", tmp_path / "ctrl", "--json")
    doc = json.loads(stdout)
    assert code == 0 and doc["certificate_sampling"] == {
        "rate_hz": 1000.0,
        "delay_samples": 1,
        "hold": "zero-order",
        "status": "CERTIFIED",
    }
    head = (tmp_path / "ctrl" / "controller.h").read_text()
    assert "sample rate: 1000 Hz" in head
    assert "computation delay: one sample (1 ms), the delay of the certificate (CERTIFIED) at 1000 Hz: u[k]," in head
    assert "applied at sample k+1" in head and "none modelled" not in head


def test_export_names_the_status_the_file_records_not_certified(tmp_path, capsys):
    """`synth --rate` records the sampled loop whatever its verdict: a NOT_CERTIFIED file is not called certified."""
    doc = json.loads(_certified_at(tmp_path, 1000.0, 1).read_text())
    doc["certificate"]["status"] = "NOT_CERTIFIED"
    path = tmp_path / "K_not.json"
    path.write_text(json.dumps(doc))
    code, _, _ = _export(capsys, path, "-o", tmp_path / "ctrl", "--quiet")
    head = (tmp_path / "ctrl" / "controller.h").read_text()
    assert code == 0 and "the delay of the certificate (NOT_CERTIFIED) at 1000 Hz" in head
    assert "as certified" not in head


def test_export_refuses_a_rate_other_than_the_certified_one(tmp_path, capsys):
    """--rate 500 on a 1 kHz certificate: one line, exit 2, nothing written; --force writes it with a WARNING."""
    path, out = _certified_at(tmp_path, 1000.0, 1), tmp_path / "ctrl"
    code, _, err = _export(capsys, path, "--rate", "500", "-o", out)
    assert code == 2 and err.count("\n") == 1
    assert (
        "certificate of" in err
        and "(CERTIFIED) is for the loop sampled at 1000 Hz" in err
        and "give --rate 1000" in err
    )
    assert not out.exists() or not list(out.iterdir())
    code, _, err = _export(capsys, path, "--rate", "500", "--force", "-o", out, "--quiet")
    assert code == 0 and "the certificate is not about this loop" in err
    assert "WARNING: --rate 500" in (out / "controller.h").read_text()


def test_export_of_a_continuous_certificate_needs_a_rate(tmp_path, capsys):
    """No rate in the certificate and no --rate: refused in one line naming --rate; the header says no delay."""
    code, _, err = _export(capsys, SYNTH_FILE, "-o", tmp_path / "ctrl")
    assert (
        code == 2 and err.count("\n") == 1 and "records no sample rate in its certificate" in err and "--rate HZ" in err
    )
    code, _, _ = _export(capsys, SYNTH_FILE, "--rate", "1000", "-o", tmp_path / "ctrl", "--quiet")
    head = (tmp_path / "ctrl" / "controller.h").read_text()
    assert code == 0 and "computation delay: none in the certificate (it is for the continuous-time loop)" in head


def test_lowest_rate_rests_on_the_crossover_not_on_fast_modes():
    """A fast controller mode far above crossover does not raise the lowest rate; without a plant it does."""
    import control

    from polyrob.validate.export_c import lowest_rate_of_controller, nominal_arm

    K = control.ss(control.tf([100.0, 100.0], [1.0 / 5000.0, 1.0]))  # PD-like, a pole at 5000 rad/s
    low = lowest_rate_of_controller(K, nominal_arm(1))
    wc = 100.0  # |K(j w) / (j w)^2| = 1 near w = 100 (the pole is far above)
    assert low.rate == pytest.approx(wc / (2 * np.radians(10.0)), rel=0.05) and "crossover" in low.basis
    assert lowest_rate_of_controller(K).rate == pytest.approx(2 * 5000.0 / np.pi)


# 3. the arithmetic -----------------------------------------------------------------------------------------


def test_float_coefficients_checked_against_the_exact_controller(tmp_path, capsys):
    """--real float loses the PID's integral gain (its numerator's zeros near z = 1 round onto it): refused."""
    out = tmp_path / "ctrl"
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "1000", "--real", "float", "-o", out)
    assert code == 2 and err.count("\n") == 1
    assert "export refused: float coefficients do not keep" in err and "integral gain is lost" in err
    assert "--real double keeps them" in err
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "1000", "--real", "float", "--force", "-o", out, "--quiet")
    assert code == 0 and "WARNING: float coefficients" in (out / "controller.h").read_text()
    assert "integral gain is lost" in json.loads((out / "controller.json").read_text())["warnings"][0]


def test_integrators_keep_their_pole_at_one_in_every_arithmetic():
    """An integrator gets its own section [1, -1, 0]: float rounding cannot move it (paired, it moved)."""
    from polyrob.validate.quantize import check_accuracy, round_to_float

    sos = sos_realization(discretize(load_controller(SYNTH_FILE), 1000.0))
    rows = [row for _, _, secs in sos.entries() for row in secs]
    assert sum(1 for r in rows if r[4] == -1.0 and r[5] == 0.0) == 2  # one per joint
    for W in (8, 16, 24):
        q = round_to_float(quantize(sos, W))
        for _, _, secs in q.entries():
            assert any(r[3:].tolist() == [1.0, -1.0, 0.0] for r in secs)
    # the check itself: a pole moved by rounding is caught, and exact coefficients pass
    assert check_accuracy(sos, sos).ok
    paper = sos_realization(discretize(polyrob.paper_controller(), 1000.0))
    res = check_accuracy(paper, round_to_float(paper))
    assert not res.ok and res.dc_error > 0.1 and "DC gain moves by" in res.problem


# 4 and 5. word lengths on every controller file ---------------------------------------------------------


def test_word_length_on_a_synth_file_names_the_smallest(tmp_path, capsys):
    """synth -o's file on a task with an inner layer: before, `not a domain as to_dict writes it (missing 'u')`."""
    out = tmp_path / "ctrl"
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "1000", "--word-length", "16", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "missing 'u'" not in err
    assert "16-bit fixed point coefficients do not keep" in err and "is 35 bits (--word-length 35)" in err
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "1000", "--word-length", "34", "-o", out)
    assert code == 2 and "is 35 bits" in err
    code, stdout, err = _export(capsys, SYNTH_FILE, "--rate", "1000", "--word-length", "35", "-o", out, "--json")
    doc = json.loads(stdout)
    assert code == 0 and doc["word_length"] == 35 and doc["smallest_word_length"] == 35 and doc["accuracy"]["ok"]
    assert doc["word_length_check"] == {"checked": False, "why": doc["word_length_check"]["why"]}
    assert "--pldi" in err and err.count("polyrob: warning:") == 1


def test_export_prints_the_smallest_word_length(tmp_path, capsys):
    """Without --word-length the export says how many bits the realisation needs (the PID's: 35)."""
    code, stdout, _ = _export(capsys, SYNTH_FILE, "--rate", "1000", "-o", tmp_path / "ctrl")
    assert code == 0 and "the smallest fixed-point word length that keeps them is 35 bits" in stdout
    assert "35 bits" in (tmp_path / "ctrl" / "controller.h").read_text()


# 6. saturation, anti-windup, bumpless start ----------------------------------------------------------------


def test_saturation_anti_windup_and_bumpless_start_in_c(cc, tmp_path):
    sos = sos_realization(discretize(load_controller(SYNTH_FILE), 1000.0))
    write_c(sos, tmp_path)
    c = _C(_library(cc, tmp_path), sos.n_sections, 2, 2)
    lo, hi = np.array([-2.0, -2.0]), np.array([2.0, 2.0])
    c.set_limits(lo, hi)
    # a large error for 0.3 s, then none: saturated, then back
    e = np.zeros((2, 600))
    e[0, :300], e[1, :300] = 0.05, -0.03
    u_c = np.array([c.step(e[:, k]) for k in range(e.shape[1])]).T
    u_py = sos.run(e, lower=lo, upper=hi)
    assert np.array_equal(u_c, u_py)  # same operations, same doubles
    assert u_c.max() == 2.0 and u_c.min() == -2.0 and np.all(u_c <= hi[:, None]) and np.all(u_c >= lo[:, None])
    # without anti-windup the integrator winds up for 0.3 s and the output stays at the limit after the error is gone
    wound = np.clip(sos.run(e), lo[:, None], hi[:, None])
    assert np.all(wound[:, 300:320] != 0.0) and abs(wound[0, 310]) > 1.9
    assert np.max(np.abs(u_py[:, 310:])) < 0.05  # held states: nothing left to unwind
    # bumpless: from the output applied before (and the error now), the first step outputs exactly it
    c.bumpless([0.01, -0.02], [0.7, -1.3])
    assert np.allclose(c.step([0.01, -0.02]), [0.7, -1.3], rtol=0, atol=1e-12)
    start = sos.bumpless_state([0.01, -0.02], [0.7, -1.3])
    assert np.allclose(sos.run(np.array([[0.01], [-0.02]]), initial=start)[:, 0], [0.7, -1.3], rtol=0, atol=1e-12)


# 7. the C in the loop ----------------------------------------------------------------------------------


def _closed_loop(robot, step_controller, r, n_steps, h, substeps=4):
    """planar_2r under the computed-torque inner layer, v from ``step_controller(e)`` held over each period (RK4)."""
    q, qd = np.zeros(2), np.zeros(2)
    qs, vs = [q.copy()], []
    dt = h / substeps
    for _ in range(n_steps):
        v = step_controller(r - q)
        tau = robot.mass_matrix(q) @ v + robot.inverse_dynamics(q[None], qd[None], np.zeros((1, 2)))[0]
        for _ in range(substeps):

            def f(x):
                return np.concatenate([x[2:], robot.acceleration(x[:2], x[2:], tau)])

            x = np.concatenate([q, qd])
            k1 = f(x)
            k2 = f(x + 0.5 * dt * k1)
            k3 = f(x + 0.5 * dt * k2)
            k4 = f(x + dt * k3)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            q, qd = x[:2], x[2:]
        qs.append(q.copy())
        vs.append(v)
    return np.array(qs), np.array(vs)


def test_exported_c_closed_around_the_arm_reproduces_the_python_loop(cc, tmp_path, capsys):
    code, _, _ = _export(capsys, SYNTH_FILE, "--rate", "1000", "-o", tmp_path, "--quiet")
    assert code == 0
    doc = json.loads((tmp_path / "controller.json").read_text())
    c = _C(_library(cc, tmp_path), sum(len(s) for row in doc["sections"] for s in row), 2, 2)
    robot = polyrob.load_robot("planar_2r")
    r = np.array([0.005, -0.004])
    q_c, v_c = _closed_loop(robot, c.step, r, 1500, 1e-3)

    dc = discretize(load_controller(SYNTH_FILE), 1000.0)  # the Python discrete controller, state space
    A, B, C, D = (np.asarray(X, float) for X in (dc.system.A, dc.system.B, dc.system.C, dc.system.D))
    xk = np.zeros(A.shape[0])

    def python_step(e):
        nonlocal xk
        v = C @ xk + D @ e
        xk = A @ xk + B @ e
        return v

    q_py, v_py = _closed_loop(robot, python_step, r, 1500, 1e-3)
    assert np.max(np.abs(v_c)) < 2.0  # inside the task's acceleration limits: the saturation never acts
    assert np.max(np.abs(q_c - q_py)) <= 1e-9 * np.max(np.abs(q_py))
    assert np.max(np.abs(v_c - v_py)) <= 1e-9 * np.max(np.abs(v_py))
    assert abs(q_c[-1] - r).max() < 0.15 * abs(r).max()  # and the arm follows the step (overshoot decaying)
