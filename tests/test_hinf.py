"""H∞ synthesis: robot-type plants that control.hinfsyn refuses, γ accuracy, clear errors."""

from __future__ import annotations

import control
import numpy as np
import pytest
from test_synthesis_checks import closed_loop, dense_peak, hamiltonian_below, response

from polyrob.errors import PolyrobError, SynthesisError
from polyrob.synthesis.hinf.synthesis import check_stabilizable, hinf_norm, hinf_norm_estimate, hinfsyn

# control.augw builds its plants with the deprecated control.connect
pytestmark = pytest.mark.filterwarnings("ignore:connect\\(\\) is deprecated:FutureWarning")


def _double_integrator_plant(with_wt: bool = False) -> control.StateSpace:
    """Mixed-sensitivity plant of 1/s^2: D12 = 0 and two poles at s = 0."""
    G = control.ss(control.tf([1], [1, 0, 0]))
    WS = control.ss(control.tf([0.5, 0.5], [1, 0.005]))
    if with_wt:
        WT = control.ss(control.tf([1, 10], [0.01, 21]))
        return control.augw(G, w1=WS, w3=WT)
    return control.augw(G, w1=WS)


def _scherer_plant():
    """Scherer, Gahinet & Chilali (1997), Example 7: regular (full-rank D12, D21)."""
    A = np.array([[0, 10, 2], [-1, 1, 0], [0, 2, -5]], float)
    B1 = np.array([[1], [0], [1]], float)
    B2 = np.array([[0], [1], [0]], float)
    C1 = np.array([[1, 0, 0], [0, 0, 0]], float)
    C2 = np.array([[0, 1, 0]], float)
    D11 = np.zeros((2, 1))
    D12 = np.array([[0], [1]], float)
    D21 = np.array([[2]], float)
    D22 = np.zeros((1, 1))
    return control.ss(A, np.hstack([B1, B2]), np.vstack([C1, C2]), np.block([[D11, D12], [D21, D22]]))


def test_control_hinfsyn_fails_but_ours_does_not():
    P = _double_integrator_plant()
    with pytest.raises(Exception):
        control.hinfsyn(P, 1, 1)
    res = hinfsyn(P, 1, 1)
    assert res.method == "riccati"
    assert np.all(np.linalg.eigvals(res.closed_loop.A).real < 0)
    # the regularisation is recorded, in words
    assert any("D12 lacks full column rank" in r for r in res.regularization)
    assert any("imaginary-axis" in r for r in res.regularization)
    # |W_S(inf)| = 0.5 and S(inf) = 1 for a strictly proper plant: gamma >= 0.5
    assert 0.5 - 1e-6 <= res.gamma < 0.52
    _check_gamma_is_the_closed_loop_norm(P, res)


def _check_gamma_is_the_closed_loop_norm(P, res, n_u=1, n_y=1):
    """γ is the norm of Fl(P, K) with the user's plant, checked without polyrob's code."""
    cl = closed_loop(P, res.K, n_u, n_y)  # python-control's LFT
    w = np.logspace(-4, 4, 9)
    np.testing.assert_allclose(response(res.closed_loop, w), response(cl, w), rtol=1e-7, atol=1e-10)
    assert dense_peak(cl) <= res.gamma * (1 + 1e-9)  # nothing above γ on a dense grid
    assert hamiltonian_below(cl, res.gamma * (1 + 1e-6))  # and provably nothing between grid points


def test_double_integrator_with_complementary_weight():
    res = hinfsyn(_double_integrator_plant(with_wt=True), 1, 1)
    assert np.all(np.linalg.eigvals(res.closed_loop.A).real < 0)
    assert res.gamma <= res.gamma_bound * (1 + 1e-2)
    assert res.gamma < 0.6
    _check_gamma_is_the_closed_loop_norm(_double_integrator_plant(with_wt=True), res)


def test_regular_plant_matches_slicot_optimum():
    P = _scherer_plant()
    from threadpoolctl import threadpool_limits

    # one BLAS thread: SB10AD with threaded OpenBLAS took 38 s instead of 0.14 s on a loaded 2-core machine
    with threadpool_limits(limits=1):
        ref = control.hinfsyn(P, 1, 1)[2]
    res = hinfsyn(P, 1, 1, tol=1e-4)
    assert res.regularization == () and res.fallbacks == ()
    assert res.gamma == pytest.approx(ref, rel=2e-3)
    _check_gamma_is_the_closed_loop_norm(P, res)


def test_lmi_route_agrees_with_riccati():
    P = _scherer_plant()
    ric = hinfsyn(P, 1, 1, method="riccati")
    lmi = hinfsyn(P, 1, 1, method="lmi")
    assert lmi.method == "lmi"
    assert np.all(np.linalg.eigvals(lmi.closed_loop.A).real < 0)
    assert lmi.gamma == pytest.approx(ric.gamma, rel=0.05)


def test_gamma_range_bracket():
    P = _scherer_plant()
    res = hinfsyn(P, 1, 1, gamma_range=(1.0, 100.0))
    assert res.gamma <= 100.0


def test_unstabilisable_plant_names_the_mode():
    # an unstable mode (s = +1) that u cannot reach
    A = np.diag([1.0, -2.0])
    B = np.array([[1.0, 0.0], [0.0, 1.0]])  # [w, u]
    C = np.array([[1.0, 1.0], [1.0, 1.0]])  # [z, y]
    D = np.array([[0.0, 1.0], [1.0, 0.0]])
    P = control.ss(A, B, C, D, states=["bad", "good"])
    with pytest.raises(SynthesisError, match=r"not stabilisable.*s = 1 .*bad"):
        hinfsyn(P, 1, 1)


def test_undetectable_plant():
    A = np.diag([1.0, -2.0])
    B = np.array([[1.0, 1.0], [1.0, 1.0]])
    C = np.array([[1.0, 0.0], [0.0, 1.0]])  # y sees only the stable state
    D = np.array([[0.0, 1.0], [1.0, 0.0]])
    with pytest.raises(SynthesisError, match="not detectable"):
        hinfsyn(control.ss(A, B, C, D), 1, 1)


def test_pbh_accepts_slow_but_controllable_modes():
    # modes at 1e-5 and 1e3 rad/s next to a double integrator, all controllable
    A = np.zeros((4, 4))
    A[0, 1] = 1.0
    A[2, 2] = -1e-5
    A[3, 3] = -1e3
    A[2, 0] = 1.0
    B2 = np.array([[0.0], [1.0], [0.0], [1e3]])
    C2 = np.array([[1.0, 0.0, 1e-3, 1.0]])
    check_stabilizable(A, B2, C2)


def test_bad_sizes_are_polyrob_errors():
    P = _scherer_plant()
    with pytest.raises(PolyrobError, match="do not fit"):
        hinfsyn(P, 1, 2)
    with pytest.raises(PolyrobError, match="needs n_y and n_u"):
        hinfsyn(P)
    with pytest.raises(PolyrobError, match="method"):
        hinfsyn(P, 1, 1, method="magic")


def _resonance(zeta=1e-4, w0=1.2345):
    G = control.ss(control.tf([w0**2], [1, 2 * zeta * w0, w0**2]))
    return G, 1 / (2 * zeta * np.sqrt(1 - zeta**2))  # analytic peak


def test_hinf_norm_is_an_upper_bound_when_ab13dd_fails(monkeypatch):
    """Before the fix a 2000-point grid value was returned: 139 for a true norm of 5000."""
    import slycot
    from slycot.exceptions import SlycotArithmeticError

    G, peak = _resonance()

    def fail(*args, **kwargs):
        raise SlycotArithmeticError("forced failure", 1)

    monkeypatch.setattr(slycot, "ab13dd", fail)
    g = hinf_norm(G)
    assert peak * (1 - 1e-12) <= g <= peak * (1 + 1e-5)
    assert hamiltonian_below(G, g * (1 + 1e-9))


def test_unstable_system_has_infinite_norm():
    G = control.ss(control.tf([1], [1, -1]))
    assert control.linfnorm(G)[0] == pytest.approx(1.0)  # python-control: L∞, finite
    assert hinf_norm(G) == np.inf


def test_controller_accepted_only_below_gamma():
    """The accept check is the Hamiltonian test, so a resonance between grid points cannot pass."""
    from polyrob.synthesis.hinf.problem import SynthesisProblem
    from polyrob.synthesis.hinf.riccati import verify_controller

    G, peak = _resonance()
    A, B, C = (np.asarray(X, float) for X in (G.A, G.B, G.C))
    # inputs [w, u], outputs [z, y]; with K = 0 the loop is G itself
    prob = SynthesisProblem(A, np.hstack([B, B]), np.vstack([C, C]), np.zeros((2, 2)), 1, 1)
    K0 = (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.zeros((1, 1)))
    assert not verify_controller(prob, K0, peak * 0.99, rtol=0.0)
    assert verify_controller(prob, K0, peak * 1.001, rtol=0.0)


def test_failed_lmi_conditioning_pass_is_recorded(monkeypatch):
    import cvxpy as cp

    real_solve = cp.Problem.solve
    calls = []

    def solve(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:  # the second (conditioning) pass
            raise cp.error.SolverError("forced failure")
        return real_solve(self, *args, **kwargs)

    monkeypatch.setattr(cp.Problem, "solve", solve)
    # without the conditioning pass the reconstruction from X, Y is singular
    # here: the error says which pass failed (no silent fallback)
    with pytest.raises(SynthesisError, match="conditioning pass .* failed"):
        hinfsyn(_scherer_plant(), 1, 1, method="lmi")


def test_norm_estimate_close_to_ab13dd():
    sys = control.ss(control.tf([1, 0.1, 4], [1, 0.05, 4.2]) * control.tf([10], [1, 10]))
    A, B, C, D = (np.asarray(X) for X in (sys.A, sys.B, sys.C, sys.D))
    assert hinf_norm_estimate(A, B, C, D) == pytest.approx(hinf_norm(sys), rel=1e-4)
    assert hinf_norm_estimate(np.array([[1.0]]), B[:1, :], C[:, :1], D) == np.inf


def test_paper_plant(paper_plant):
    res = hinfsyn(paper_plant)
    assert np.isfinite(res.gamma)
    assert np.all(np.linalg.eigvals(res.closed_loop.A).real < 0)


@pytest.fixture(scope="module")
def paper_plant():
    import polyrob
    import polyrob.plant.weights

    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    return polyrob.generalized_plant(polyrob.uncertain_plant(pldi), *polyrob.plant.weights.paper_weights())
