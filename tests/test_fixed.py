"""Fixed-structure μ-synthesis (polyrob.synthesis.fixed.synthesis) and its parametrisations (structures).

The paper-2R tests share one short synthesis (tf3 from K*, two D-G-K
iterations, a 36-point certification grid) so the file stays well under a
minute on two cores; the measured figures of full runs are in the report.
"""

from __future__ import annotations

import control
import numpy as np
import pytest
from test_synthesis_checks import closed_loop, dg_mixed_upper, loop_stable, response

import polyrob
from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.bounds import mu_bounds
from polyrob.errors import PolyrobError, SynthesisError
from polyrob.plant.generalized import PAPER_CONTROLLER, generalized_plant, lft, paper_controller
from polyrob.plant.weights import paper_weights
from polyrob.synthesis.fixed.structures import controller_structure
from polyrob.synthesis.fixed.synthesis import closed_loop_response, fixed_structure_musyn

#: certification grid shared by K* and the synthesised controller (coarse: fast)
OMEGA = np.logspace(-3, 4, 36)


def _fr(sys, w) -> np.ndarray:
    """Frequency response as (N, p, m) from python-control (the independent reference)."""
    H = np.asarray(sys(1j * np.asarray(w), squeeze=False))
    return np.moveaxis(H.reshape(sys.noutputs, sys.ninputs, -1), -1, 0)


@pytest.fixture(scope="module")
def paper_plant():
    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), progress=False)
    W_S, W_T = paper_weights()
    return generalized_plant(polyrob.uncertain_plant(pldi), W_S, W_T)


@pytest.fixture(scope="module")
def mu_k_star(paper_plant):
    """K*'s verified lower bound of robust-performance mu on the grid (no peak search between the points:
    a lower bound needs none, and the search cost 14 of the 17 s)."""
    P = paper_plant
    return mu_bounds(
        lft(P, paper_controller()), P.block_structure_rp, OMEGA, refine_peak=False, progress=False
    ).peak_lower


@pytest.fixture(scope="module")
def tf3(paper_plant):
    return fixed_structure_musyn(
        paper_plant, structure="tf3", init="paper", starts=1, max_iter=2, omega=OMEGA, certify_omega=OMEGA, seed=0
    )


def _tiny_plant():
    """x' = x + 0.5 d + u (unstable), v = x, z = 0.5 (w - x), y = w - x; blk: real δ, 1x1 performance."""
    A = [[1.0]]
    B = [[0.5, 0.0, 1.0]]
    C = [[1.0], [-0.5], [-1.0]]
    D = [[0.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 1.0, 0.0]]
    return control.ss(A, B, C, D), [[-1, 0], [1, 1]]


# ----------------------------------------------------------------- the paper's 2R


def test_tf3_from_k_star_beats_k_star(tf3, mu_k_star):
    # K* is not robust on this uncertainty model (a verified RP mu lower bound > 1: 2.08); the
    # fixed-structure synthesis started from it must certify a bound below K*'s mu itself
    assert mu_k_star > 1.0
    assert tf3.structure == "tf3"
    assert tf3.peak_mu < mu_k_star
    assert tf3.peak_mu_lower <= tf3.peak_mu * (1 + 1e-9)
    # grid peaks never increase (every accepted step decreases the bound)
    h = tf3.mu_history[:-1]
    assert np.all(np.diff(h) <= 1e-9 * h[0])


def test_certificate_checked_independently(paper_plant, tf3):
    """The certified peak, recomputed without polyrob: python-control's LFT, a D-G LMI
    (cvxpy) at the certificate's peak frequency, and frozen real parameters inside
    the certified radius that must keep the loop stable."""
    P = paper_plant
    n_real = sum(1 for b in as_block_structure(P.block_structure_rp).blocks if b.kind == "real")
    N = closed_loop(P.system, tf3.controller, P.n_u, P.n_y)
    Nw = response(N, [tf3.peak_frequency])[0]
    # the D-G bound is the certificate's bound (same Fan-Tits-Doyle scalings, another solver)
    assert dg_mixed_upper(Nw, n_real, tol=1e-4) == pytest.approx(tf3.peak_mu, rel=1e-2)
    # robust stability (implied by robust performance): |δ_i| < 1/μ keeps every frozen loop stable
    rng = np.random.default_rng(0)
    r = 0.999 / tf3.peak_mu
    for _ in range(40):
        delta = np.diag(r * rng.choice([-1.0, 1.0], size=n_real))
        assert loop_stable(N, delta)


def test_tf3_controller_is_internally_stable_with_third_order_entries(paper_plant, tf3):
    P = paper_plant
    # internal stability: every pole of the interconnection, rebuilt from scratch
    poles = np.linalg.eigvals(np.asarray(lft(P, tf3.controller).A))
    assert np.max(poles.real) < 0
    assert np.max(np.linalg.eigvals(np.asarray(tf3.closed_loop.A)).real) < 0
    # each K_ij: monic third-order denominator, numerator of degree <= 3, stable
    coef = tf3.info["coefficients"]
    assert tf3.order == 12
    w = np.logspace(-2, 3, 30)
    Kw = _fr(tf3.controller, w)
    for i in range(2):
        for j in range(2):
            num, den = np.array(coef["num"][i][j]), np.array(coef["den"][i][j])
            assert den.size == 4 and den[0] == 1.0 and num.size <= 4
            assert np.all(np.roots(den).real < 0)
            ref = _fr(control.tf(num, den), w)[:, 0, 0]
            np.testing.assert_allclose(Kw[:, i, j], ref, rtol=1e-8)


def test_structure_round_trip_of_k_star():
    s = controller_structure("tf3", 2, 2)
    th = s.from_controller(paper_controller())
    w = np.logspace(-3, 4, 60)
    ref = _fr(paper_controller(), w)
    np.testing.assert_allclose(s.freqresp(th, w), ref, rtol=1e-9)
    np.testing.assert_allclose(_fr(s.controller(th), w), ref, rtol=1e-9)
    # printed like the paper: the denominator's constant term scaled to 1
    d = s.describe(th)
    for i in range(2):
        for j in range(2):
            np.testing.assert_allclose(d["den_paper_form"][i][j], PAPER_CONTROLLER["den"][i][j], rtol=1e-9)
            np.testing.assert_allclose(d["num_paper_form"][i][j][1:], PAPER_CONTROLLER["num"][i][j], rtol=1e-9)


# ----------------------------------------------------------------- parametrisations


def _independent(s, th):
    """The controller rebuilt with control.tf / control.ss from the structure's own description."""
    d = s.describe(th)
    if s.name.startswith("tf"):
        return control.tf(d["num"], d["den"])
    if s.name == "pid":
        sv = control.tf("s")
        entries = [[0 * sv] * 2 for _ in range(2)]
        for i in range(2):
            entries[i][i] = d["Kp"][i] + d["Ki"][i] / sv + d["Kd"][i] * sv / (d["tau"][i] * sv + 1)
        return control.tf(
            [[entries[i][j].num[0][0] for j in range(2)] for i in range(2)],
            [[entries[i][j].den[0][0] for j in range(2)] for i in range(2)],
        )
    return control.ss(d["A"], d["B"], d["C"], d["D"])


@pytest.mark.parametrize("name", ["tf1", "tf2", "tf3", "tf4", "pid", "ss:3"])
def test_structure_round_trip_and_derivative(name):
    s = controller_structure(name, 2, 2)
    th = s.initial(7)
    w = np.logspace(-2, 3, 40)
    K, dK = s.freqresp(th, w, jac=True)
    ref = _fr(_independent(s, th), w)
    np.testing.assert_allclose(K, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    np.testing.assert_allclose(_fr(s.controller(th), w), ref, rtol=1e-8, atol=1e-12 * np.abs(ref).max())
    assert s.controller(th).nstates == s.order
    # analytic dK/dθ against central differences
    sc = s.scale(th)
    for p in range(s.n_params):
        e = np.zeros(s.n_params)
        e[p] = 1e-6 * sc[p]
        fd = (s.freqresp(th + e, w) - s.freqresp(th - e, w)) / (2 * e[p])
        np.testing.assert_allclose(dK[:, p], fd, rtol=1e-5, atol=1e-6 * np.abs(dK[:, p]).max() + 1e-300)
    # θ -> K -> θ' -> K' reproduces the controller
    th2 = s.from_controller(s.controller(th))
    np.testing.assert_allclose(s.freqresp(th2, w), K, rtol=1e-6, atol=1e-9 * np.abs(K).max())


def test_tf_entries_are_stable_for_any_theta():
    s = controller_structure("tf3", 2, 2)
    rng = np.random.default_rng(1)
    for _ in range(20):
        th = 3.0 * rng.standard_normal(s.n_params)
        assert np.all(np.linalg.eigvals(s.realization(th)[0]).real < 0)


def test_closed_loop_response_matches_lft(paper_plant):
    K = paper_controller()
    w = np.logspace(-2, 3, 20)
    ref = _fr(lft(paper_plant, K), w)
    np.testing.assert_allclose(
        closed_loop_response(paper_plant.system, K, w, n_u=2, n_y=2), ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max()
    )


# ----------------------------------------------------------------- errors and small plants


def test_unknown_structure_raises(paper_plant):
    with pytest.raises(PolyrobError, match='valid: "tfN"'):
        controller_structure("lqg", 2, 2)
    with pytest.raises(PolyrobError, match="pid"):
        fixed_structure_musyn(paper_plant, structure="tf-three")
    with pytest.raises(PolyrobError):
        controller_structure("pid", 2, 3)  # a decentralised PID needs a square K


def test_unstabilisable_plant_raises_synthesis_error():
    # the unstable mode does not see u: no controller can stabilise the loop
    P = control.ss([[1.0]], [[1.0, 0.0, 0.0]], [[1.0], [1.0], [1.0]], np.zeros((3, 3)))
    with pytest.raises(SynthesisError, match="no start stabilises"):
        fixed_structure_musyn(
            P,
            [[-1, 0], [1, 1]],
            "tf1",
            n_u=1,
            n_y=1,
            starts=2,
            max_iter=1,
            omega=np.logspace(-1, 1, 5),
            certify_omega=np.logspace(-1, 1, 5),
        )


@pytest.mark.parametrize("structure", ["pid", "ss:1", "tf2"])
def test_small_plant_structures_are_internally_stable(structure):
    P, blk = _tiny_plant()
    w = np.logspace(-2, 2, 21)
    r = fixed_structure_musyn(
        P, blk, structure, n_u=1, n_y=1, init=-4.0, starts=1, max_iter=3, omega=w, certify_omega=w
    )
    N = closed_loop(P, r.controller, 1, 1)  # python-control's LFT
    assert np.max(np.linalg.eigvals(np.asarray(N.A)).real) < 0
    # the certified peak, by a D-G LMI (real δ, 1x1 performance block) at its frequency
    assert dg_mixed_upper(response(N, [r.peak_frequency])[0], 1) == pytest.approx(r.peak_mu, rel=1e-2)
    assert r.order == {"pid": 2, "ss:1": 1, "tf2": 2}[structure]
    assert np.isfinite(r.peak_mu) and r.peak_mu_lower <= r.peak_mu * (1 + 1e-9)
    if structure == "pid":  # Ki/s: a controller pole at 0, yet a stable loop
        assert 0.0 in np.round(np.linalg.eigvals(np.asarray(r.controller.A)), 12)


def test_same_seed_same_result():
    P, blk = _tiny_plant()
    w = np.logspace(-2, 2, 21)
    kw = dict(n_u=1, n_y=1, init=-4.0, starts=2, max_iter=2, seed=3, omega=w, certify_omega=w)
    a = fixed_structure_musyn(P, blk, "tf1", **kw)
    b = fixed_structure_musyn(P, blk, "tf1", **kw)
    assert a.info["theta"] == b.info["theta"]
    assert a.peak_mu == b.peak_mu


def test_failed_h2_start_is_recorded(monkeypatch):
    import polyrob.synthesis.fixed.synthesis as fixed_module

    def fail(*args, **kwargs):
        raise np.linalg.LinAlgError("forced failure")

    monkeypatch.setattr(fixed_module, "default_controller", fail)
    P, blk = _tiny_plant()
    w = np.logspace(-2, 2, 21)
    r = fixed_structure_musyn(P, blk, "tf1", n_u=1, n_y=1, starts=1, max_iter=1, omega=w, certify_omega=w)
    assert r.info["start"] == "random"
    assert any("H2 start failed" in f and "random start" in f for f in r.info["fallbacks"])


def test_the_job_s_line_moves_through_the_first_scalings_the_iterations_and_the_certificate():
    """`synth ur5 --structure pid` sat at "31 % of the job" for 17 min: the first scalings (a cold μ bound per
    frequency), the iterations and the certificate reported nothing into the job's line.  Now each has its part."""
    import io

    from polyrob.progress import JobProgress

    P, blk = _tiny_plant()
    w = np.logspace(-2, 2, 21)
    job = JobProgress(["synthesis"], stream=io.StringIO(), clock=lambda: 0.0).start()
    job._stop.set()  # no ticking thread: the shares are read from the job's own record
    shares, within = [], job.within
    job.within = lambda share: (shares.append(share), within(share))[1]
    try:
        job.begin(1, "synthesis")
        fixed_structure_musyn(P, blk, "tf1", n_u=1, n_y=1, init=-4.0, starts=2, max_iter=3, omega=w, certify_omega=w)
    finally:
        job.stop()
    from polyrob.synthesis.fixed.synthesis import FIRST_SCALINGS_SHARE, STARTS_SHARE

    first = STARTS_SHARE / 2 * FIRST_SCALINGS_SHARE  # the first start's first scalings end here
    assert len([s for s in shares if 0 < s < first]) >= 10  # its frequencies move the line one by one
    assert any(first < s < STARTS_SHARE / 2 for s in shares)  # the first start's iterations
    assert any(STARTS_SHARE / 2 < s < STARTS_SHARE for s in shares)  # the second start's
    assert any(STARTS_SHARE < s < 1.0 for s in shares)  # the certificate's sweep
