"""μ-synthesis (D-K / D-G-K): distillation column, scalings, dispatch, bad inputs."""

from __future__ import annotations

import control
import numpy as np
import pytest
from test_synthesis_checks import closed_loop, dscaled_mu, loop_stable, response

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.bounds import mussv
from polyrob.errors import PolyrobError, SynthesisError
from polyrob.examples import DISTILLATION_BLK, distillation_plant
from polyrob.synthesis import musyn
from polyrob.synthesis.dk.iteration import frequency_grid, performance_lower_bound
from polyrob.synthesis.scalings.dscale import (
    BlockScaling,
    GFit,
    MagnitudeFit,
    Scalings,
    balanced_realization,
    fit_g,
    fit_magnitude,
    scaled_plant,
    scaling_data,
)


@pytest.fixture(scope="module")
def distillation_result():
    P = distillation_plant()
    res = musyn(P, DISTILLATION_BLK, n_u=2, n_y=2, max_iter=8, omega=np.logspace(-3, 3, 61), progress=False)
    return P, res


def test_distillation_plant_matches_textbook():
    P = distillation_plant()
    H = P(0.1j)
    # W_I(j0.1) on the v <- u channel, -G(j0.1) on y <- d
    assert H[0, 4] == pytest.approx((0.1j + 0.2) / (0.05j + 1))
    G = np.array([[87.8, -86.4], [108.2, -109.6]]) / (7.5j + 1)
    assert np.allclose(H[4:6, 0:2], -G)


def test_distillation_mu_below_1_05(distillation_result):
    P, res = distillation_result
    assert res.peak_mu <= 1.05  # dkpy reports 1.03-1.04 on this example
    assert res.peak_mu_lower <= res.peak_mu + 1e-9
    assert res.certificate.mu.omega.min() < 1e-3  # a decade beyond the D-step grid


def test_distillation_certificate_checked_independently(distillation_result):
    """μ of Fl(P, K) recomputed without polyrob: python-control's LFT and, for three
    complex full blocks, μ = min_D σ̄(D N D⁻¹) (Doyle 1982), on a dense grid."""
    P, res = distillation_result
    N = closed_loop(P, res.controller, 2, 2)
    assert np.max(np.linalg.eigvals(np.asarray(N.A)).real) < 0  # nominal (internal) stability
    w = np.union1d(np.logspace(-4, 3, 141), [res.peak_frequency])
    H = response(N, w)
    mu, x = np.zeros(w.size), None
    for k in range(w.size):
        mu[k], x = dscaled_mu(H[k], [1, 1, 2], x)
    # no frequency exceeds the certified peak, and the peak is where the certificate says
    assert mu.max() <= res.peak_mu * (1 + 1e-3)
    assert mu[np.searchsorted(w, res.peak_frequency)] == pytest.approx(res.peak_mu, rel=2e-3)
    # robust stability (implied by robust performance): real input gains within 1/μ keep the loop stable
    r = 0.999 / res.peak_mu
    for d1 in (-r, r):
        for d2 in (-r, r):
            assert loop_stable(N, np.diag([d1, d2]))


def test_result_bookkeeping(distillation_result):
    _, res = distillation_result
    assert res.structure == "full"
    assert len(res.mu_history) == len(res.gamma_history) == res.iterations
    assert res.mu_history[0] > res.mu_history.min()  # D-K improved on the plain H∞ controller
    assert res.info["method"] == "D-K"
    best = res.info["best_iteration"] - 1
    assert res.mu_history[best] == pytest.approx(res.info["grid_peak_mu"])
    # what the iteration did instead of the plain route is recorded, not hidden
    assert isinstance(res.info["fallbacks"], list)
    sc = res.scalings[0]
    assert sc is None or sc.blocks[-1].d is None  # performance block normalised to d = 1


def test_balanced_filters_are_moderate(distillation_result):
    _, res = distillation_result
    sc = res.scalings[0]
    # deterministic: on this example D-K improves on the unscaled H-inf controller at
    # every step (best iteration 8 of 8), so the best controller carries fitted D filters
    assert sc is not None
    dynamic = [b for b in sc.blocks[:-1] if b.d is not None and b.d.order > 0]
    assert dynamic  # the filters checked below exist
    for b in dynamic:
        for inv in (False, True):
            A, B, C, D = b.d.ss(inverse=inv)
            assert np.all(np.linalg.eigvals(A).real < 0)
            assert np.abs(np.hstack([B.ravel(), C.ravel()])).max() < 1e4


# ------------------------------------------------------------------ fits
def test_fit_magnitude_recovers_second_order_scaling():
    w = np.logspace(-3, 3, 80)
    true = (1j * w) ** 2 + 0.4 * (1j * w) + 4.0
    true = np.abs(3.0 * true / ((1j * w) ** 2 + 2.0 * (1j * w) + 0.25))
    fit = fit_magnitude(w, true, 2)
    assert fit.error < 1e-4
    assert np.all(fit.poles.real < 0) and np.all(fit.zeros.real < 0)
    assert np.allclose(np.abs(fit(1j * w)), true, rtol=1e-3)
    # exact inverse from the factors
    A, B, C, D = fit.ss(inverse=True)
    Hi = control.ss(A, B, C, D)(1j * w[10])
    assert abs(complex(Hi)) == pytest.approx(1 / true[10], rel=1e-3)


def test_balanced_realization_is_balanced():
    A = np.array([[-1.0, 0.0], [0.0, -1e3]])
    B = np.array([[1.0], [1e4]])
    C = np.array([[1.0, 1e-4]])
    Ab, Bb, Cb, _ = balanced_realization(A, B, C, np.zeros((1, 1)))
    import scipy.linalg as sla

    Wc = sla.solve_continuous_lyapunov(Ab, -Bb @ Bb.T)
    Wo = sla.solve_continuous_lyapunov(Ab.T, -Cb.T @ Cb)
    assert np.allclose(Wc, Wo, rtol=1e-6, atol=1e-12)
    assert np.allclose(Wc, np.diag(np.diag(Wc)), atol=1e-9)


def test_fit_g_realises_a_narrow_bump():
    w = np.logspace(-2, 2, 60)
    F0 = 0.12 * (1j * w) / ((1j * w) ** 2 + 0.3 * (1j * w) + 1.0)  # resonant G scaling, max 0.4
    h = -2 * F0.imag / (1 - np.abs(F0) ** 2)
    fit = fit_g(w, h, 2)
    assert fit.hinf < 1
    assert fit.error < 0.05 * np.abs(h).max()
    A, B, C, D = fit.ss()
    assert np.all(np.linalg.eigvals(A).real < 0)


def test_j_factorisation_certifies_mixed_mu():
    """With the exact F of the module docstring, ||T|| = 1 exactly at the mixed-μ bound."""
    rng = np.random.default_rng(3)
    blk = [[-1, 0], [-1, 0], [2, 2]]
    for _ in range(3):
        M = rng.standard_normal((4, 4)) + 1j * rng.standard_normal((4, 4))
        r = mussv(M, blk, lower=False)
        beta = r.upper
        sd = scaling_data([1.0], [beta], r.D[None], r.G[None], blk)
        blocks = []
        for i in range(2):
            p, h = sd.d[0, i] ** 2, sd.g[0, i] / (beta * sd.d[0, i] ** 2)
            tau = -h / (1 + np.sqrt(1 + h * h))  # F = j tau exactly (a constant, at this frequency)
            d = np.sqrt(p / (1 - tau**2))
            blocks.append((d, 1j * tau))
        dl = np.array([blocks[0][0], blocks[1][0], 1, 1])
        Fr = np.diag([blocks[0][1], blocks[1][1], 0, 0])
        Nt = M / beta
        T = np.diag(dl) @ (Nt + Fr) @ np.linalg.inv(np.eye(4) + Fr.T @ Nt) @ np.diag(1 / dl)
        assert np.linalg.norm(T, 2) == pytest.approx(1.0, abs=1e-6)
        # complex D scaling alone does not reach it
        assert (
            np.linalg.norm(np.diag(np.r_[sd.d[0, :2], 1, 1]) @ Nt @ np.diag(1 / np.r_[sd.d[0, :2], 1, 1]), 2)
            >= 1 - 1e-9
        )


def test_scaled_plant_matches_frequency_formula():
    """State-space K-step plant == D (N/β + F)(I + F N/β)^{-1} D^{-1} for any controller."""
    rng = np.random.default_rng(0)
    blk = [[-1, 0], [1, 1], [1, 2]]
    st = as_block_structure(blk)
    nr, nc = st.m_shape  # 4 rows (outputs), 3 cols (inputs)
    n = 4
    A = rng.standard_normal((n, n)) - 4 * np.eye(n)
    P = control.ss(
        A,
        rng.standard_normal((n, nc + 1)),
        rng.standard_normal((nr + 1, n)),
        0.1 * rng.standard_normal((nr + 1, nc + 1)),
    )
    d0 = fit_magnitude(
        np.logspace(-1, 1, 20), np.abs((1j * np.logspace(-1, 1, 20) + 2) / (1j * np.logspace(-1, 1, 20) + 0.5)), 1
    )
    d1 = MagnitudeFit(0, 3.0, np.zeros(0, complex), np.zeros(0, complex), 0.0, 0.0, np.array([np.log(3.0)]))
    F = GFit(2, 0.1, np.array([0.2]), np.array([1.5]), 0.0, 0.3, np.array([[2.0, 0.3, 0.1, -0.2]]))
    sc = Scalings((BlockScaling(d0, F), BlockScaling(d1, None), BlockScaling(None, None)), 1.7, st)
    Ps = scaled_plant(P, sc, 1, 1)
    K = control.ss([[-1.0]], [[0.5]], [[0.3]], [[0.1]])
    from polyrob.plant.generalized import lft

    w = np.logspace(-1, 1, 7)
    N = lft(P, K, n_u=1, n_y=1)
    Nw = np.moveaxis(N(1j * w), -1, 0)
    T = sc.transformed(Nw, w)
    Ts = np.moveaxis(lft(Ps, K, n_u=1, n_y=1)(1j * w), -1, 0)
    assert np.allclose(T, Ts, atol=1e-9)


# -------------------------------------------------------------- mixed μ
def _mixed_toy():
    """First-order plant, one real parametric gain uncertainty (±40%) and a performance block."""
    # x' = -x + (1 + 0.4 δ) u ;  v = u ;  z = 0.3 e ; y = e = w - x
    A = np.array([[-1.0]])
    B = np.array([[0.4, 0.0, 1.0]])  # [d, w, u]
    C = np.array([[0.0], [-0.3], [-1.0]])  # [v, z, y]
    D = np.array([[0.0, 0.0, 1.0], [0.0, 0.3, 0.0], [0.0, 1.0, 0.0]])
    return control.ss(A, B, C, D)


def test_mixed_dgk_runs_and_certifies_with_real_block():
    P = _mixed_toy()
    res = musyn(P, [[-1, 0], [1, 1]], n_u=1, n_y=1, max_iter=4, progress=False)
    assert res.info["mixed"] is True
    assert res.certificate.mu.structure.has_real
    cplx = musyn(P, [[-1, 0], [1, 1]], n_u=1, n_y=1, max_iter=4, mixed=False, progress=False)
    assert cplx.info["method"] == "D-K"
    # both certified against the real structure; D-G-K is not worse
    assert res.peak_mu <= cplx.peak_mu * 1.02


def test_paper_plant_smoke():
    """Two D-K iterations on the paper's 2R plant: runs, stable, certified (mixed μ)."""
    import polyrob
    import polyrob.plant.weights

    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    P = polyrob.generalized_plant(polyrob.uncertain_plant(pldi), *polyrob.plant.weights.paper_weights())
    res = musyn(
        P, max_iter=2, mixed=False, omega=np.logspace(-3, 3, 31), progress=False, certify_omega=np.logspace(-3, 3, 31)
    )
    assert np.isfinite(res.peak_mu)
    assert res.mu_history[-1] < res.mu_history[0]
    assert res.certificate.mu.structure.has_real  # certified with the real parameters


# ------------------------------------------------------------ dispatch, errors
def test_unknown_structure():
    # the structure name is validated once, by controller_structure (no second parser in musyn)
    with pytest.raises(PolyrobError, match="unknown controller structure 'magic'; valid"):
        musyn(distillation_plant(), DISTILLATION_BLK, structure="magic", n_u=2, n_y=2)


def test_fixed_structure_is_dispatched_with_options_passed_through(monkeypatch):
    import polyrob.synthesis.mu_synthesis as musyn_module
    from polyrob.synthesis.fixed.options import FixedStructureOptions
    from polyrob.synthesis.options import FixedStructure, MusynOptions

    calls = {}

    def fake(P, blk, *, options, **kw):
        calls.update(P=P, blk=blk, options=options, kw=kw)
        return "fixed-result"

    monkeypatch.setattr(musyn_module, "fixed_structure_musyn", fake)
    P = distillation_plant()
    tuning = FixedStructureOptions(grid_density=5.0)
    out = musyn(P, DISTILLATION_BLK, structure="tf3", max_iter=7, starts=2, options=tuning, n_u=2, n_y=2)
    assert out == "fixed-result"
    opts = calls["options"]
    assert isinstance(opts, MusynOptions)
    # the flat keywords of earlier versions become one options object: the method a
    # FixedStructure holding the tuning by identity; the common options left at None
    # ("the fixed-structure solver's own default"), not musyn's defaults
    assert opts.method == FixedStructure("tf3", starts=2, tuning=tuning) and opts.method.tuning is tuning
    assert opts.max_iter == 7 and opts.tol is None and opts.mixed is None and opts.omega is None
    assert calls["kw"]["n_u"] == 2 and calls["kw"]["n_y"] == 2
    # the same call with the options object
    calls.clear()
    method = FixedStructure("tf3", starts=2, tuning=tuning)
    musyn(P, DISTILLATION_BLK, options=MusynOptions(method=method, max_iter=7), n_u=2, n_y=2)
    assert calls["options"] == opts


def test_full_order_options_refused_for_a_fixed_structure():
    with pytest.raises(PolyrobError, match="full-order synthesis only"):
        musyn(distillation_plant(), DISTILLATION_BLK, structure="tf3", d_order=(0, 1), n_u=2, n_y=2)
    with pytest.raises(PolyrobError, match="unexpected options"):
        musyn(distillation_plant(), DISTILLATION_BLK, starts=3, n_u=2, n_y=2)


def test_infeasible_weights():
    import polyrob
    from polyrob.plant.weights import complementary_weight, sensitivity_weight

    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    unc = polyrob.uncertain_plant(pldi)
    # |S| < 1/|W_S| up to 50 rad/s while |T| < 1/|W_T| from 1 rad/s: S + T = I forbids it
    P = polyrob.generalized_plant(unc, sensitivity_weight(50.0, 1.5, 1e-3), complementary_weight(1.0, 1.2, 1e-2))
    lb, w = performance_lower_bound(P)
    assert lb > 1
    with pytest.raises(SynthesisError, match="weights make robust performance impossible"):
        musyn(P)


def test_unstabilisable_plant():
    P = _mixed_toy()
    A = np.array([[-1.0, 0.0], [0.0, 2.0]])  # an unstable mode nobody drives
    B = np.vstack([np.asarray(P.B), np.zeros((1, 3))])
    C = np.hstack([np.asarray(P.C), np.ones((3, 1))])
    bad = control.ss(A, B, C, P.D)
    with pytest.raises(SynthesisError, match="not stabilisable"):
        musyn(bad, [[-1, 0], [1, 1]], n_u=1, n_y=1)


def test_bad_sizes():
    with pytest.raises(PolyrobError, match="needs n_u and n_y"):
        musyn(distillation_plant(), DISTILLATION_BLK)
    with pytest.raises(PolyrobError, match="block structure"):
        musyn(distillation_plant(), [[1, 1], [2, 2]], n_u=2, n_y=2)


def test_frequency_grid_ignores_integrators():
    G = control.ss(control.tf([1], [1, 0])) * control.ss(control.tf([1], [1, 10]))
    w = frequency_grid(G)
    assert w.min() == pytest.approx(1.0) and w.max() == pytest.approx(100.0)


# -------------------------------------------------------------- the D-step grid of a double integrator
def _double_integrator_toy():
    """``k/s^2``, ``k`` in ``1 -+ 0.5`` (a joint behind computed torque), ``W_S`` with a slow pole, ``W_T`` a fast one.

    The plant's poles are the integrators (0, left out of the grid), ``W_S``'s 5e-3 (a near-integrator
    against the median) and ``W_T``'s 5000 rad/s: its own grid runs from 100 rad/s up, while the loop
    crosses over at a few rad/s.
    """
    s = control.tf("s")
    W_S = control.ss((s / 2 + 5) / (s + 5e-3))
    W_T = control.ss((s + 25) / (1e-2 * s + 50))
    # states: x1, x2 (the joint), then the weights'; inputs [d, r, u]; outputs [v, z_S, z_T, y]
    joint = control.ss(
        [[0, 1], [0, 0]], [[0, 0, 0], [1, 0, 1]], [[0, 0], [-1, 0], [1, 0], [-1, 0]],
        [[0, 0, 0.5], [0, 1, 0], [0, 0, 0], [0, 1, 0]],
    )  # fmt: skip
    one = control.ss(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[1.0]])  # a static 1, no state
    weights = control.append(one, W_S, W_T, one)  # v, z_S, z_T, y
    return weights * joint


def test_the_d_steps_see_the_crossover_of_a_double_integrator_loop():
    """Before: the D-K grid came from the open plant's poles only (100 rad/s up here), the start's
    peak near its crossover was missed (ur5 behind computed torque: 1.2 on the grid, 2.75 at 15 rad/s)
    and each K-step fitted scalings to the wrong frequencies."""
    from polyrob.plant.loops import lower_lft
    from polyrob.synthesis.dk.iteration import DKIteration
    from polyrob.synthesis.dk.strategies import HinfStep, MuUpperBound
    from polyrob.synthesis.pid_tuning import pid_controller
    from polyrob.synthesis.scalings.dfit import LogMagnitudeFit

    P = _double_integrator_toy()
    blk = [[-1, 0], [1, 2]]
    omega = frequency_grid(P)
    assert omega.min() >= 100.0  # the open plant's grid: no point near the crossover
    wc = 3.0
    K0 = pid_controller(np.array([[wc**2, wc**3 / 16, 2 * wc, 1 / (20 * wc)]]))
    dk = DKIteration(MuUpperBound(), LogMagnitudeFit(), HinfStep(), max_iter=1, progress=False)
    hist = dk.run(P, 1, 1, blk, omega, mixed=True, initial_controller=K0, start_phase="DG")  # as musyn from a start
    M = lower_lft(P, K0, 1, 1)
    A, B, C, D = (np.asarray(X) for X in (M.A, M.B, M.C, M.D))

    def mu_peak(grid):
        return max(mussv(C @ np.linalg.solve(1j * w * np.eye(len(A)) - A, B) + D, blk, lower=False).upper for w in grid)

    peak = mu_peak(np.concatenate([[0.0], np.logspace(-3, 5, 161)]))
    assert peak > 1.5 * mu_peak(omega)  # the plant's grid alone misses the peak by far
    assert hist[0].mu_peak == pytest.approx(peak, rel=0.05)


def test_the_certificate_of_the_best_iteration_has_its_own_part_of_the_job_s_progress(monkeypatch):
    """`synth ur5 --robot-uncertainty default` stood at "97 %, 5 s left" for the 120 s of its certificate: the
    D-K iterations filled the whole stage.  Now they fill ITERATIONS_SHARE of it and the certificate the rest."""
    import io

    from clocks import FakeClock

    import polyrob.synthesis.mu_synthesis as ms
    from polyrob.progress import WITHIN_CAP, JobProgress

    job = JobProgress(["synthesis"], stream=io.StringIO(), clock=FakeClock(now=0.0))
    job.start()
    job._stop.set()  # no real-time ticks: the shares are read directly
    seen = []
    certify = ms.certify_loop

    def spy(*args, **kwargs):
        seen.append(job.share)
        return certify(*args, **kwargs)

    monkeypatch.setattr(ms, "certify_loop", spy)
    try:
        job.begin(1, "synthesis (full)")
        musyn(_mixed_toy(), [[-1, 0], [1, 1]], n_u=1, n_y=1, max_iter=4, progress=False)
        after = job.share
    finally:
        job.stop()
    assert seen and seen[0] == pytest.approx(ms.ITERATIONS_SHARE)  # the iterations' part, not the stage's end
    assert after == pytest.approx(WITHIN_CAP)  # the certificate's span ended the stage (its cap)
