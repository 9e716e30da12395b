"""The per-joint PID start (polyrob.synthesis.pid_tuning) and where the pipeline uses it."""

from __future__ import annotations

from types import SimpleNamespace

import control
import numpy as np
import pytest

from polyrob.errors import PolyrobError
from polyrob.synthesis.pid_tuning import CROSSOVER_FRACTIONS, MIN_GAIN, pid_controller, pid_gains, tuned_pid


@pytest.fixture(scope="module")
def P(unc):
    from polyrob.plant.generalized import generalized_plant
    from polyrob.plant.weights import paper_weights

    return generalized_plant(unc, *paper_weights())


def test_gains_are_the_critically_damped_pid_of_a_double_integrator():
    g = pid_gains(4.0, 16.0, 20.0, [1.0, 2.0])
    # Kp = wc^2 / b, Ki = wc^3 / (k_i b), Kd = 2 wc / b, tau = 1 / (n_f wc)
    assert g[0] == pytest.approx([16.0, 4.0, 8.0, 1 / 80])
    assert g[1] == pytest.approx([8.0, 2.0, 4.0, 1 / 80])
    # closed on 1/s^2 without the integral and the filter: s^2 + 2 wc s + wc^2 = (s + wc)^2
    kp, _, kd, _ = g[0]
    assert np.roots([1.0, kd, kp]) == pytest.approx([-4.0, -4.0])


def test_controller_is_the_pid_formula_per_joint():
    g = pid_gains(3.0, 8.0, 10.0, [0.5, 1.0])
    K = pid_controller(g)
    assert K.nstates == 4 and K.ninputs == K.noutputs == 2
    for w in (0.1, 1.0, 30.0):
        s = 1j * w
        H = K(s)
        for j in range(2):
            kp, ki, kd, tau = g[j]
            assert H[j, j] == pytest.approx(kp + ki / s + kd * s / (tau * s + 1), rel=1e-12)
        assert H[0, 1] == 0 and H[1, 0] == 0


def test_tuned_pid_takes_the_best_candidate_and_its_figure_is_an_upper_bound(P, unc):
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.plant.loops import lower_lft

    omega = np.logspace(-2, 2, 9)
    r = tuned_pid(P, omega=omega, decouple=False)
    # crossovers placed by the smallest W_T bandwidth of the paper's weights (10 rad/s)
    assert sorted({t[0] for t in r.tried}) == pytest.approx([f * 10.0 for f in CROSSOVER_FRACTIONS])
    finite = [t for t in r.tried if np.isfinite(t[3])]
    # the chosen row's figure; a row dropped early is at least 1 - MIN_GAIN of the best at its time
    chosen = [t for t in finite if t[:3] == (r.crossover, r.integral_ratio, r.filter_ratio)]
    assert r.grid_mu in [t[3] for t in chosen]
    assert min(t[3] for t in finite) >= (1 - MIN_GAIN) * r.grid_mu
    # the gains were divided by the nominal input gain b_j = B_nom[m + j, j]
    b = np.diag(np.asarray(unc.B_nom)[2:])
    assert r.input_gains == pytest.approx(b)
    assert r.gains()[:, 0] == pytest.approx(r.crossovers() ** 2 / b)
    # the ranking figure bounds mu from above at its frequencies
    CL = lower_lft(P.system, r.controller, P.n_u, P.n_y)
    H = matrix_response(CL.A, CL.B, CL.C, CL.D)(omega)
    lower = max(mussv(H[k], P.block_structure_rp, lower=True).lower for k in range(omega.size))
    assert lower <= r.grid_mu * (1 + 1e-6)
    assert "per-joint PID critically damped" in r.words()


def test_a_coupled_input_matrix_gets_the_pid_through_its_inverse(P, unc):
    # the paper's 2R has no inner layer: B_v = M^-1 at the box's centre couples the joints
    B_v = np.asarray(unc.B_nom)[2:]
    assert abs(B_v[0, 1]) > 0.1 * abs(B_v).max()
    r = tuned_pid(P, omega=np.logspace(-2, 2, 9), refine_window=None)
    assert r.decoupling == pytest.approx(np.linalg.inv(B_v))
    assert r.input_gains == pytest.approx([1.0, 1.0])
    assert "through the nominal inertia" in r.words()
    # the controller is T diag(K_j): the nominal loop B_v T K = K, each joint a unit double integrator's PID
    K = pid_controller(r.gains())
    for w in (0.3, 3.0):
        assert B_v @ r.controller(1j * w) == pytest.approx(K(1j * w), rel=1e-9, abs=1e-12)


def test_per_joint_crossovers_only_lower_the_figure_and_the_figure_is_the_controllers(P):
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.plant.loops import lower_lft
    from polyrob.synthesis.pid_tuning import JOINT_SCALES

    omega = np.logspace(-2, 2, 9)
    common = tuned_pid(P, omega=omega, refine_window=None)
    assert common.joint_scales == (1.0, 1.0)
    r = tuned_pid(P, omega=omega, refine_window=(0.0, np.inf))  # always search the joints' factors
    assert r.grid_mu <= common.grid_mu
    assert (r.crossover, r.integral_ratio, r.filter_ratio) == (
        common.crossover,
        common.integral_ratio,
        common.filter_ratio,
    )
    # each factor is a product of the tried ones (two sweeps at most)
    allowed = {1.0, *JOINT_SCALES, *(a * b for a in JOINT_SCALES for b in JOINT_SCALES)}
    assert all(min(abs(s - a) for a in allowed) < 1e-12 for s in r.joint_scales)
    assert r.crossovers() == pytest.approx(r.crossover * np.array(r.joint_scales))
    # the figure is the returned controller's own, recomputed
    CL = lower_lft(P.system, r.controller, P.n_u, P.n_y)
    H = matrix_response(CL.A, CL.B, CL.C, CL.D)(omega)
    upper = max(mussv(H[k], P.block_structure_rp, method="relaxed", lower=False).upper for k in range(omega.size))
    assert upper == pytest.approx(r.grid_mu, rel=1e-9)
    if r.joint_scales != (1.0, 1.0):
        assert r.grid_mu < common.grid_mu and "per joint" in r.words()


def test_musyn_starts_from_the_tuned_pid_and_keeps_the_best(P, monkeypatch):
    import polyrob.synthesis.pid_tuning as tuning
    from polyrob.synthesis import musyn

    monkeypatch.setattr(tuning, "CROSSOVER_FRACTIONS", (0.4,))  # one crossover: the path, not the search

    w = np.logspace(-2, 2, 12)
    res = musyn(P, initial_controller="pid", max_iter=1, progress=False, omega=w, certify_omega=w)
    assert res.info["start"].startswith("per-joint PID critically damped")
    assert res.order == 2 * P.n_u  # one iteration: the PID itself
    # max_iter=1 is the start alone: no D-K step, the PID's own certificate
    assert res.structure == "pid" and res.iterations == 0 and "max_iter=1" in res.info["stopped_by"]
    from polyrob.analysis.certificate import certify_loop

    cert = certify_loop(P, res.controller, None, w, sweep_unstable=False)
    assert res.certificate.status is cert.status and res.certificate.bound == pytest.approx(cert.bound, rel=1e-12)
    assert np.array_equal(res.controller.A, tuned_pid(P).controller.A)
    with pytest.raises(PolyrobError, match="GeneralizedPlant"):
        musyn(control.ss(-1.0, 1.0, 1.0, 0.0), [[1, 1]], n_u=1, n_y=1, initial_controller="pid")


def test_default_start_only_for_computed_torque_and_never_over_the_users():
    from polyrob.pipeline.design import with_default_start

    ct = SimpleNamespace(robot=SimpleNamespace(inner="computed-torque"))
    assert with_default_start(ct, {"structure": "full"})["initial_controller"] == "pid"
    assert with_default_start(ct, {"init": "paper"}) == {"init": "paper"}
    assert with_default_start(ct, {"initial_controller": "K"}) == {"initial_controller": "K"}
    for inner in ("gravity", "none", None):
        plain = SimpleNamespace(robot=SimpleNamespace(inner=inner))
        assert "initial_controller" not in with_default_start(plain, {"structure": "full"})


def _certificate(bound):
    from polyrob.analysis.certificate import Certificate, Scope, decide_gain

    return Certificate(decide_gain(True, bound, True)[0], bound, bound, 0.0, None, Scope())


@pytest.mark.parametrize("bound, target, answered", [(0.8, 1.0, True), (0.95, 0.9, False), (1.2, 1.5, False)])
def test_the_pid_start_answers_only_when_its_certificate_meets_the_target(P, monkeypatch, bound, target, answered):
    """MATLAB's TargetPerf on the start: a PID certified below ``target`` is the result, no D-K step runs;
    a certificate above the target, or not certified (mu >= 1), hands the PID to D-K."""
    import dataclasses

    import polyrob.analysis.certificate as certificate
    import polyrob.synthesis.pid_tuning as tuning
    from polyrob.synthesis.pid_tuning import pid_start

    real = tuning.tuned_pid(P, omega=np.logspace(-2, 2, 5))
    monkeypatch.setattr(tuning, "tuned_pid", lambda P, **k: dataclasses.replace(real, grid_mu=0.9 * bound))
    monkeypatch.setattr(certificate, "certify_loop", lambda *a, **k: _certificate(bound))
    K, words, done = pid_start(P, target=target)
    assert K.nstates == 2 * P.n_u and words.startswith("per-joint PID")
    if not answered:
        assert done is None
        return
    assert done.controller is K and done.structure == "pid" and done.iterations == 0
    assert done.certificate.certified and done.certificate.bound == bound
    assert f"certificate, below the target {target:g}" in done.info["stopped_by"]
    assert np.asarray(done.info["pid_gains"]).shape == (P.n_u, 4)
    # without a target nothing is certified here: D-K's loop starts from the PID
    monkeypatch.setattr(certificate, "certify_loop", lambda *a, **k: pytest.fail("certified without a target"))
    assert pid_start(P)[2] is None


def test_a_computed_torque_loop_gets_target_one_unless_one_is_given():
    from polyrob.pipeline.design import with_default_start

    ct = SimpleNamespace(robot=SimpleNamespace(inner="computed-torque"))
    assert with_default_start(ct, {})["target"] == 1.0  # a certified PID is the answer
    assert with_default_start(ct, {"target": 0.7})["target"] == 0.7  # the user's target wins


def test_a_search_screens_a_pid_whose_ranking_figure_is_already_above_one(P, monkeypatch):
    """The bandwidth search's PID per factor: a ranking figure >= 1 is a SynthesisError (a failed factor in the
    search's history) without a certificate; a target no ranking reaches hands the PID to D-K uncertified."""
    import polyrob.analysis.certificate as certificate
    from polyrob.errors import SynthesisError
    from polyrob.synthesis.pid_tuning import pid_start

    monkeypatch.setattr(certificate, "certify_loop", lambda *a, **k: pytest.fail("a screened PID was certified"))
    with pytest.raises(SynthesisError, match=r"coarse-grid mu upper bound \d+\.\d+ >= 1: its certificate was not"):
        pid_start(P, only=True, screen=1.0)  # the paper's 2R box problem: the PID's ranking is about 3.5
    assert pid_start(P, target=1.0)[2] is None
