"""The sampled-data certificate: the loop sampled at a rate with a computation delay (polyrob.analysis.sampled_data).

The problem is the planar 2R with computed torque and a 10 % mass error of
``tests/test_constant_moving.py``; the controller
``tests/fixtures/planar_2r_ct_pid_K.json`` is that problem's PID, CERTIFIED
in continuous time (mu <= 0.6773).
"""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np
import pytest
import scipy.linalg

from polyrob import load_robot
from polyrob.analysis.sampled_data import (
    SamplingSpec,
    bilinear_to_continuous,
    physical_frequency,
    remainder_bound,
    sampled_certificate,
    sampled_generalized_plant,
)
from polyrob.domains.task import TaskDomain
from polyrob.errors import ArgumentError
from polyrob.io.controller import load_controller
from polyrob.model.inner import inner_loop
from polyrob.pipeline import build_problem
from polyrob.plant.lftplant import upper_lft_matrices

FIXTURE = Path(__file__).parent / "fixtures" / "planar_2r_ct_pid_K.json"


@pytest.fixture(scope="module")
def problem():
    arm = inner_loop(load_robot("planar_2r"), "computed-torque", model_error=0.1)
    dom = TaskDomain.from_robot(arm, pose=[0.4, 0.3], q_radius=0.3, qdot_max=0.5, qddot_max=2.0)
    return build_problem(arm, dom, progress=False, bound_options={"samples": 1024})


@pytest.fixture(scope="module")
def lft_problem():
    """The main job's task (an ``lft`` model: inner feedback ``D_vd`` in Δ), coarsely bounded."""
    dom = TaskDomain.from_robot(load_robot("planar_2r"), pose=[0, 1.5708], q_radius=0.5, qdot_max=1, qddot_max=2.0)
    return build_problem(load_robot("planar_2r"), dom, progress=False, bound_options={"samples": 256})


def _member(unc, rng):
    """A random member of the continuous set: ``δ`` (half of them at corners) and full blocks of norm 1."""
    delta = rng.choice([-1.0, 1.0], unc.n_params) if rng.uniform() < 0.5 else rng.uniform(-1, 1, unc.n_params)
    residual = []
    for size in unc.full_blocks:
        R = rng.standard_normal((size, size))
        residual.append(R / np.linalg.norm(R, 2))
    return delta, residual


@pytest.mark.parametrize("which, rate", [("inner-gain", 1000.0), ("inner-gain", 20.0), ("lft", 1000.0)])
def test_discrete_model_holds_the_exact_zoh_of_random_members(request, which, rate):
    problem = request.getfixturevalue("problem" if which == "inner-gain" else "lft_problem")
    unc = problem.P.uncertain
    assert unc.model == which and (which != "lft" or np.any(unc.D_vd))
    n, m = unc.n_x, unc.m
    sp = sampled_generalized_plant(problem.P, SamplingSpec(rate, 0))
    S = sp.system
    A, B, C, D = (np.asarray(X, float) for X in (S.A, S.B, S.C, S.D))
    rng = np.random.default_rng(7)
    ratios = []
    for _ in range(200):
        delta, residual = _member(unc, rng)
        Ac, Bc = unc.matrices_at(delta, residual=residual)
        F = np.zeros((n + m, n + m))
        F[:n, :n], F[:n, n:] = Ac, Bc
        exact = scipy.linalg.expm(F / rate)[:n]  # [A_d B_d] of this member's zero-order hold
        # the model at this member, remainder block closed at 0: its first-order part
        Dm = unc.delta_matrix(delta, residual)
        nd = unc.n_delta
        Delta = np.zeros((n + nd, n + m + nd))
        Delta[n:, n + m :] = Dm
        first = upper_lft_matrices(A, B, C, D, Delta)  # inputs left: [r, u]
        model = np.hstack([first[0][:n, :n], first[1][:n, m:]])
        remainder = exact - model
        ratios.append(np.linalg.norm(remainder, 2) / sp.remainder)
        # the remainder block at R / rho (norm <= 1) closes the model onto the exact discretisation
        Delta[:n, : n + m] = remainder / sp.remainder
        closed = upper_lft_matrices(A, B, C, D, Delta)
        got = np.hstack([closed[0][:n, :n], closed[1][:n, m:]])
        np.testing.assert_allclose(got, exact, rtol=0, atol=1e-12)
    assert max(ratios) <= 1.0  # every member inside the model
    assert max(ratios) > 0.1  # a remainder bound ten times smaller misses some member: the bound is not vacuous


def test_remainder_bound_is_above_the_true_remainder_of_scalar_exponentials():
    # e^{g+h} - e^g - e^{g/2} h e^{g/2} for commuting scalars is e^g (e^h - 1 - h): the bound's first part
    for g, h in [(1e-3, 5e-4), (0.05, 0.01), (0.5, 0.2), (2.0, 1.0)]:
        true = abs(np.exp(g + h) - np.exp(g) - h * np.exp(g))
        assert true <= remainder_bound(g, h) <= 1.5 * true + h * (g * g / 6 + 2 * (np.exp(g) - 1 - g - g * g / 2))
    with pytest.raises(ArgumentError):
        remainder_bound(-1.0, 0.0)


def test_bilinear_map_keeps_the_frequency_response_and_stability():
    rng = np.random.default_rng(3)
    Hd = control.drss(6, 2, 3)
    Hd = control.ss(Hd.A, Hd.B, Hd.C, Hd.D, dt=1e-3)
    Hc = bilinear_to_continuous(Hd)
    assert Hc.dt == 0
    for theta in rng.uniform(0.0, np.pi, 20):
        np.testing.assert_allclose(Hc(1j * np.tan(theta / 2)), Hd(np.exp(1j * theta)), rtol=1e-9, atol=1e-12)
    zd, zc = np.linalg.eigvals(np.asarray(Hd.A)), np.linalg.eigvals(np.asarray(Hc.A))
    assert (np.abs(zd) < 1).all() and (zc.real < 0).all()
    unstable = control.ss(np.diag([1.2, 0.5]), np.eye(2), np.eye(2), np.zeros((2, 2)), dt=1e-3)
    assert np.linalg.eigvals(np.asarray(bilinear_to_continuous(unstable).A)).real.max() > 0
    assert physical_frequency(np.tan(np.pi / 4), 1000.0) == pytest.approx(np.pi / 2 * 1000.0)


def test_certified_at_1khz_with_one_sample_of_delay_beside_the_continuous_certificate(problem):
    from polyrob.pipeline import analyze_controller

    K = load_controller(FIXTURE)
    a = analyze_controller(
        problem, K, mc=1, time_varying=False, moving=False, stability="implied", sampled_loop=SamplingSpec(1000.0, 1)
    )
    continuous = a.robust_performance.certificate  # unchanged: the fixture's own figure
    assert continuous.certified and continuous.bound == pytest.approx(0.6773241094692622, rel=1e-6)
    assert continuous.scope.sampling == "" and "zero-order hold" not in continuous.scope.sentence()
    assert a.certificate is a.sampled.certificate and a.certificate.certified, a.verdict
    assert a.certificate.bound == pytest.approx(0.679, abs=0.01)
    covers = a.certificate.scope.sentence()
    assert "sampled at 1000 Hz with one sample of delay, zero-order hold, at the sampling instants" in covers
    assert "Nyquist frequency 3142 rad/s" in covers
    doc = a.summary()  # the JSON's verdict, status and covers are the sampled loop's
    assert doc["covers"] == covers and doc["status"] == "CERTIFIED" and doc["sampled"]["delay_samples"] == 1


def test_not_certified_at_a_rate_too_low_for_it(problem):
    slow = sampled_certificate(problem.P, load_controller(FIXTURE), SamplingSpec(10.0, 1), scope=problem.scope())
    # NOT_CERTIFIED, not VIOLATED: a lower bound may rest on the remainder block, which is no robot
    assert slow.certificate.status.value == "NOT_CERTIFIED", slow.verdict
    assert slow.certificate.mu_lower > 1.0  # far from it, not a rounding
    assert "sampled at 10 Hz with one sample of delay" in slow.certificate.scope.sentence()


def test_bad_sampling_specs_are_refused():
    for rate, delay in [(0.0, 1), (-5.0, 1), (float("nan"), 1), (1000.0, -1), (1000.0, 1.5)]:
        with pytest.raises(ArgumentError):
            SamplingSpec(rate, delay)


def _cli(capsys, *argv):
    from polyrob.cli import main

    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize(
    "argv, words",
    [
        (("--rate", "fast"), "--rate: 'fast' is not a number"),
        (("--rate", "-100"), "--rate: give a sample rate in Hz > 0 or 'continuous'"),
        (("--rate", "continuous", "--delay", "2"), "--delay: a delay in samples needs a sample rate"),
        (("--rate", "1000", "--delay", "-1"), "--delay: give a whole number of samples >= 0"),
        (("--rate", "1000", "--delay", "0.5"), "--delay: give a whole number of samples >= 0"),
        (("--delay", "2"), "--delay: a delay in samples needs a sample rate: give --rate HZ"),
    ],
)
def test_bad_rate_or_delay_is_one_line_and_exit_2(capsys, tmp_path, argv, words):
    target = tmp_path / "K.json"
    for command in (["analyze", "planar_2r", "--controller", "paper"], ["synth", "planar_2r", "-o", str(target)]):
        code, _, err = _cli(capsys, *command, *argv)
        assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err
        assert not target.exists()


def test_rate_options_read_as_a_sampling_spec():
    from types import SimpleNamespace as NS

    from polyrob.cli.options import sampling_from_args

    assert sampling_from_args(NS(rate=None, delay_samples=None)) is None  # not stated: continuous
    assert sampling_from_args(NS(rate=500.0, delay_samples=2)) == SamplingSpec(500.0, 2)
    assert sampling_from_args(NS(rate=1000.0, delay_samples=None)) == SamplingSpec(1000.0, 1)
    assert sampling_from_args(NS(rate=1000.0, delay_samples=0)) == SamplingSpec(1000.0, 0)
