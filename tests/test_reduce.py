"""Controller order reduction with a μ certificate at every order tried."""

from __future__ import annotations

import control
import numpy as np
import pytest
from test_synthesis_checks import closed_loop, dscaled_mu, response

from polyrob.errors import PolyrobError, SynthesisError
from polyrob.examples import DISTILLATION_BLK, distillation_plant
from polyrob.synthesis import musyn, reduce_controller
from polyrob.synthesis.reduction import balanced_reduction, stable_unstable_split


@pytest.fixture(scope="module")
def distillation():
    P = distillation_plant()
    res = musyn(P, DISTILLATION_BLK, n_u=2, n_y=2, max_iter=6, omega=np.logspace(-3, 3, 61), progress=False)
    return P, res


def test_split_reconstructs_an_unstable_controller():
    K = control.ss(control.tf([[[1, 3], [2]], [[1], [1, 0.5, 1]]], [[[1, 1, -2], [1, 5]], [[1, 0], [1, 2, 10]]]))
    Ks, Ku = stable_unstable_split(K)
    assert np.all(np.linalg.eigvals(Ks.A).real < 0)
    assert np.all(np.linalg.eigvals(Ku.A).real >= -1e-9)
    for w in (0.1, 1.0, 10.0):
        assert np.allclose(Ks(1j * w) + Ku(1j * w), K(1j * w))


def test_balanced_reduction_keeps_unstable_part_and_dc():
    K = control.ss(control.tf([1, 10], [1, 11, 10]) * control.tf([1], [1, 1000]) * control.tf([1], [1, -0.5]))
    Kr = balanced_reduction(K, 2, "matchdc")
    assert Kr.nstates == 2
    assert np.any(np.isclose(np.linalg.eigvals(Kr.A), 0.5))
    assert complex(Kr(0)) == pytest.approx(complex(K(0)), rel=1e-9)
    with pytest.raises(PolyrobError, match="unstable"):
        balanced_reduction(K, 0)


def _hankel_singular_values(G: control.StateSpace) -> np.ndarray:
    """From the two Gramians (scipy), for the check below."""
    import scipy.linalg as sla

    A, B, C = (np.asarray(X, float) for X in (G.A, G.B, G.C))
    Wc = sla.solve_continuous_lyapunov(A, -B @ B.T)
    Wo = sla.solve_continuous_lyapunov(A.T, -C.T @ C)
    return np.sort(np.sqrt(np.abs(np.linalg.eigvals(Wc @ Wo))))[::-1]


@pytest.mark.parametrize("method", ["truncate", "matchdc"])
def test_reduction_error_within_the_hankel_bounds(method):
    """σ_{r+1} <= ‖K - K_r‖∞ <= 2 Σ_{i>r} σ_i (Glover 1984), the unstable part kept exactly."""
    Ks = control.ss(
        control.tf([1, 3], [1, 1])
        * control.tf([2, 1], [1, 5, 40])
        * control.tf([1], [1, 0.3])
        * control.tf([1, 20], [1, 2, 200])
    )
    Ku = control.ss(control.tf([0.7], [1, -0.5]))
    K = control.ss(control.parallel(Ks, Ku))
    hsv = _hankel_singular_values(Ks)
    w = np.logspace(-3, 4, 4001)
    for r in (1, 2, 4):
        Kr = balanced_reduction(K, r + 1, method)
        assert Kr.nstates == r + 1
        assert np.any(np.isclose(np.linalg.eigvals(Kr.A), 0.5, rtol=1e-9))  # the unstable pole, kept
        err = np.abs(response(K, w) - response(Kr, w))[:, 0, 0].max()
        assert hsv[r] * (1 - 1e-3) <= err <= 2 * hsv[r:].sum() * (1 + 1e-9)
        if method == "matchdc":
            assert complex(Kr(0)) == pytest.approx(complex(K(0)), rel=1e-9)


def test_reduce_distillation_controller(distillation):
    P, res = distillation
    red = reduce_controller(P, res, DISTILLATION_BLK, n_u=2, n_y=2)
    assert red.meets_target
    assert red.order < res.order  # the D-K controller of this example does reduce
    assert red.peak_mu <= res.peak_mu * 1.05 + 1e-12
    # the reduced controller's μ, recomputed without polyrob at the certified peak
    # (three complex blocks: μ = the D-scaled bound), and robustly stabilising
    N = closed_loop(P, red.controller, 2, 2)
    assert np.max(np.linalg.eigvals(np.asarray(N.A)).real) < 0
    mu_pk, _ = dscaled_mu(response(N, [red.certificate.mu.peak_upper_frequency])[0], [1, 1, 2])
    assert mu_pk == pytest.approx(red.peak_mu, rel=2e-3)


def test_reduce_with_max_order(distillation):
    P, res = distillation
    red = reduce_controller(P, res, DISTILLATION_BLK, n_u=2, n_y=2, max_order=4, target=0.5)
    assert red.order <= 4
    assert not red.meets_target  # μ < 0.5 is out of reach: best within the cap, flagged


def test_reduce_rejects_impossible_cap():
    P = distillation_plant()
    K = control.ss(np.diag([0.5, -1.0]), np.eye(2), np.eye(2), np.zeros((2, 2)))  # one unstable pole
    with pytest.raises(SynthesisError, match="does not stabilise|max_order"):
        reduce_controller(P, K, DISTILLATION_BLK, n_u=2, n_y=2, max_order=0)
