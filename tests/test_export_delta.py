"""Delta-operator sections (issue 39, item 5): a realisation that keeps its accuracy in float and short words.

In the shift form the planar_2r computed-torque PID at 1 kHz loses its integral gain in float (its numerator's
zeros near z = 1 round onto it) and needs 35-bit fixed point; in ``δ = (z - 1)/T`` it keeps it in float and
in 13 bits, with the integrator exactly at z = 1.
"""

from __future__ import annotations

import json

import control
import numpy as np
import pytest
from test_export_run import _C, SYNTH_FILE, _export, _library, cc  # noqa: F401 - cc is a fixture

import polyrob
from polyrob.io.controller import load_controller
from polyrob.validate.delta_sections import delta_entry_gain, delta_response
from polyrob.validate.discretize import discretize
from polyrob.validate.export_c import write_c
from polyrob.validate.quantize import (
    SOSController,
    check_accuracy,
    quantize,
    round_to_float,
    smallest_accurate_word_length,
    sos_realization,
)

RATE = 1000.0
T = 1.0 / RATE


def _tustin_exact(Kc, omega):
    """The Tustin discretisation's exact response: ``Kd(e^{jωT}) = Kc(j (2/T) tan(ωT/2))`` (no pre-warping)."""
    s = 2j / T * np.tan(omega * T / 2)
    return np.asarray(control.ss(Kc)(s, squeeze=False))  # (p, q, n_omega)


def _delta_sections_response(sos, omega):
    H = np.zeros((sos.n_outputs, sos.n_inputs, omega.size), complex)
    for i, j, secs in sos.entries():
        H[i, j] += delta_response(secs, sos.dt, omega)
    return H


def _pid(kp=2.0, ki=0.05, kd=0.3, tau=0.002):
    """A PID whose integral action is slow at 1 kHz: the zeros sit within 1e-4 of z = 1."""
    s = control.tf("s")
    return kp + ki / s + kd * s / (tau * s + 1)


# (a) the same frequency response as the exact controller ---------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_delta_sections_of_a_random_controller_match_the_exact_response(seed):
    rng = np.random.default_rng(seed)
    n = 5
    A = rng.normal(size=(n, n))
    A -= (np.max(np.linalg.eigvals(A).real) + rng.uniform(0.05, 2.0)) * np.eye(n)  # stable, slowest mode slow
    Kc = control.ss(A, rng.normal(size=(n, 2)), rng.normal(size=(2, n)), rng.normal(size=(2, 2)))
    sos = sos_realization(discretize(Kc, RATE), form="delta")
    omega = np.logspace(-2, np.log10(0.9 * np.pi * RATE), 60)
    exact, got = _tustin_exact(Kc, omega), _delta_sections_response(sos, omega)
    assert sos.form == "delta" and sos.n_sections >= 4 * 3  # 4 entries, 5 modes each: 3 sections
    assert np.max(np.abs(got - exact) / np.abs(exact)) < 1e-9


def test_delta_sections_of_a_pid_at_1khz_match_and_keep_the_integrator_at_zero():
    Kc = _pid()
    sos = sos_realization(discretize(Kc, RATE), form="delta")
    (secs,) = sos.sections[0]
    omega = np.logspace(-3, np.log10(0.9 * np.pi * RATE), 80)
    exact, got = _tustin_exact(Kc, omega)[0, 0], delta_response(secs, T, omega)
    assert np.max(np.abs(got - exact) / np.abs(exact)) < 1e-9
    poles, n_int, n_dif, gain = delta_entry_gain(secs, T)
    assert n_int == 1 and n_dif == 0 and np.sum(poles == 1.0) == 1  # exactly z = 1
    assert gain == pytest.approx(0.05 * T, rel=1e-9)  # (1 - z^-1) K(z) at z = 1: ki T
    # the shift state space of the cascade and the run agree with the exact discrete controller
    dc = discretize(Kc, RATE)
    e = np.random.default_rng(3).normal(size=(1, 400))
    ref = control.forced_response(dc.system, U=e).outputs
    assert np.max(np.abs(sos.run(e) - ref)) < 1e-9 * np.max(np.abs(ref))
    assert np.max(np.abs(control.forced_response(sos.to_ss(), U=e).outputs - ref)) < 1e-9 * np.max(np.abs(ref))


# (b) float: the shift form loses the PID's integral gain, the delta form keeps it --------------------------


def test_planar_2r_pid_in_float_fails_in_shift_and_passes_in_delta():
    dc = discretize(load_controller(SYNTH_FILE), RATE)
    shift, delta = sos_realization(dc), sos_realization(dc, form="delta")
    in_shift = check_accuracy(shift, round_to_float(shift))
    assert not in_shift.ok and "integral gain is lost" in in_shift.problem
    rounded = round_to_float(delta)
    in_delta = check_accuracy(delta, rounded)
    assert in_delta.ok and in_delta.arithmetic == "float" and in_delta.pole_move < 1e-6
    assert in_delta.dc_error < 1e-6
    for _, _, secs in rounded.entries():  # the integrator: alpha2 an exact zero, its pole exactly at z = 1
        poles, n_int, _, _ = delta_entry_gain(secs, T)
        assert n_int == 1 and secs[-1, 5] == 0.0 and np.sum(poles == 1.0) == 1
    assert rounded.form == "delta" and quantize(delta, 16).form == "delta"


# (c) the C code of the delta form reproduces SOSController.run ----------------------------------------------


def test_delta_c_code_reproduces_run_with_saturation_and_bumpless_start(cc, tmp_path):  # noqa: F811
    sos = sos_realization(discretize(load_controller(SYNTH_FILE), RATE), form="delta")
    write_c(sos, tmp_path)
    head, src = (tmp_path / "controller.h").read_text(), (tmp_path / "controller.c").read_text()
    assert "realisation: delta-operator sections" in head and "s[0] = s[0] + delta_T * (" in src
    c = _C(_library(cc, tmp_path), sos.n_sections, 2, 2)
    lo, hi = np.array([-2.0, -2.0]), np.array([2.0, 2.0])
    c.set_limits(lo, hi)
    e = np.zeros((2, 600))
    e[0, :300], e[1, :300] = 0.05, -0.03
    u_c = np.array([c.step(e[:, k]) for k in range(e.shape[1])]).T
    u_py = sos.run(e, lower=lo, upper=hi)
    assert np.max(np.abs(u_c - u_py)) <= 1e-9 * np.max(np.abs(u_py))
    assert u_c.max() == 2.0 and u_c.min() == -2.0  # saturated
    wound = np.clip(sos.run(e), lo[:, None], hi[:, None])
    assert abs(wound[0, 310]) > 1.9 and np.max(np.abs(u_py[:, 310:])) < 0.05  # anti-windup: nothing to unwind
    c.bumpless([0.01, -0.02], [0.7, -1.3])
    assert np.allclose(c.step([0.01, -0.02]), [0.7, -1.3], rtol=0, atol=1e-12)
    start = sos.bumpless_state([0.01, -0.02], [0.7, -1.3])
    assert np.allclose(sos.run(np.array([[0.01], [-0.02]]), initial=start)[:, 0], [0.7, -1.3], rtol=0, atol=1e-12)


# (d) the smallest word length -----------------------------------------------------------------------------


def test_delta_needs_far_fewer_bits_than_shift_on_the_pid():
    dc = discretize(load_controller(SYNTH_FILE), RATE)
    shift, delta = sos_realization(dc), sos_realization(dc, form="delta")
    assert smallest_accurate_word_length(shift) == 35
    assert smallest_accurate_word_length(delta) == 13
    assert smallest_accurate_word_length(shift, float_=True) is None  # float's 24-bit significand never does
    assert smallest_accurate_word_length(delta, float_=True) == 13


# (e) the CLI end to end, and the file round trip -------------------------------------------------------------


def test_export_realization_delta_end_to_end(tmp_path, capsys):
    out = tmp_path / "ctrl"
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "1000", "--real", "float", "-o", out)
    assert code == 2 and err.count("\n") == 1 and "--realization delta keeps it in float" in err
    assert not out.exists()
    code, _, err = _export(capsys, SYNTH_FILE, "--rate", "1000", "--word-length", "16", "-o", out)
    assert code == 2 and "--realization delta keeps it in 16-bit fixed point" in err
    code, stdout, _ = _export(
        capsys, SYNTH_FILE, "--rate", "1000", "--real", "float", "--realization", "delta", "-o", out, "--json"
    )
    doc = json.loads(stdout)
    assert code == 0 and doc["form"] == "delta" and doc["accuracy"]["ok"] and doc["accuracy"]["arithmetic"] == "float"
    assert doc["smallest_word_length_by_form"] == {"delta": 13, "shift": 35}
    head = (out / "controller.h").read_text()
    assert "realisation: delta-operator sections" in head and "integrators exactly at d = 0" in head
    assert "static const float delta_T = 0.001f;" in (out / "controller.c").read_text()
    data = json.loads((out / "controller.json").read_text())
    back = SOSController.from_dict(data)
    assert data["form"] == "delta" and back.form == "delta" and back.info.get("arithmetic") == "float"
    for (_, _, a), (_, _, b) in zip(
        back.entries(),
        round_to_float(sos_realization(discretize(load_controller(SYNTH_FILE), RATE), form="delta")).entries(),
    ):
        assert np.array_equal(a, b)
    code, stdout, _ = _export(capsys, SYNTH_FILE, "--rate", "1000", "-o", tmp_path / "plain")
    assert code == 0 and "35 bits (--word-length 35) in shift sections; in delta sections 13 bits" in stdout


def test_a_file_without_form_is_shift_and_a_bad_form_is_refused():
    sos = sos_realization(discretize(_pid(), RATE), form="delta")
    data = sos.to_dict()
    back = SOSController.from_dict(data)
    assert back.form == "delta" and np.array_equal(back.sections[0][0], sos.sections[0][0]) and back.dt == sos.dt
    del data["form"]
    assert SOSController.from_dict(data).form == "shift"
    with pytest.raises(ValueError, match="section form"):
        sos_realization(discretize(_pid(), RATE), form="lattice")


# the main job's controller: K* on paper_2r -----------------------------------------------------------------


def test_paper_controller_keeps_its_poles_in_float_and_18_bits_in_delta():
    """K* at 1 kHz: shift sections need 35 bits and fail in float (DC gain 14 % off); delta: 18 bits, float passes."""
    dc = discretize(polyrob.paper_controller(), RATE)
    shift, delta = sos_realization(dc), sos_realization(dc, form="delta")
    assert smallest_accurate_word_length(shift) == 35 and smallest_accurate_word_length(delta) == 18
    assert not check_accuracy(shift, round_to_float(shift)).ok
    in_float = check_accuracy(delta, round_to_float(delta))
    assert in_float.ok and in_float.pole_move < 1e-6 and in_float.dc_error < 1e-6
    # its state space (what the μ check closes the loop with): no spurious pole at z = 1 from first-order sections
    sys = delta.to_ss()
    assert sys.nstates == 12 and np.max(np.abs(np.linalg.eigvals(sys.A))) < 1.0
    e = np.random.default_rng(4).normal(size=(2, 300))
    ref = control.forced_response(dc.system, U=e).outputs
    assert np.max(np.abs(control.forced_response(sys, U=e).outputs - ref)) < 1e-9 * np.max(np.abs(ref))


@pytest.mark.slow
def test_word_length_mu_check_in_delta_and_the_refusal_naming_it(tmp_path, capsys):
    """--word-length 20: the shift form's loop is unstable (μ needs 25 bits), the delta form's keeps μ."""
    from polyrob.io.controller import save_controller
    from polyrob.pipeline import build_problem

    robot = polyrob.load_robot("paper_2r")
    pldi = polyrob.bound_pldi(robot, samples=256, coverage=0, progress=False)
    pldi.save(tmp_path / "pldi.json")
    problem = build_problem(robot, pldi=pldi, uncertainty="box")
    save_controller(polyrob.paper_controller(), tmp_path / "K.json", info=problem.description())
    argv = [tmp_path / "K.json", "--rate", "1000", "--word-length", "20"]
    code, _, err = _export(capsys, *argv, "--force", "-o", tmp_path / "s", "--quiet")
    mu_line = [w for w in err.splitlines() if "discretised loop" in w]
    assert code == 0 and len(mu_line) == 1 and "(unstable)" in mu_line[0] and "is 25 bits" in mu_line[0]
    assert "--realization delta keeps it in 20-bit fixed point" in mu_line[0]
    code, stdout, err = _export(capsys, *argv, "--realization", "delta", "-o", tmp_path / "d", "--json")
    doc = json.loads(stdout)
    assert code == 0 and "warning" not in err and doc["form"] == "delta"
    assert doc["word_length_check"]["ok"] is True and doc["word_length_check"]["stable"] is True
