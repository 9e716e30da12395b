"""Tests of polyrob.plant: the generalized plant of eq. (10), its LFTs and loop functions."""

import control
import numpy as np
import pytest

from polyrob.analysis.mu.blocks import BlockStructure
from polyrob.errors import PolyrobError
from polyrob.plant.generalized import (
    ClosedLoop,
    GeneralizedPlant,
    closed_loop,
    generalized_plant,
    lft,
    loop_functions,
    nominal_closed_loop,
    paper_controller,
)
from polyrob.plant.uncertainty import uncertain_plant, upper_lft
from polyrob.plant.weights import paper_weights

FREQS = (0.1, 0.7, 3.0, 20.0, 150.0)


def _diag(*tfs):
    n = len(tfs)
    num = [[tfs[i].num[0][0] if i == j else [0.0] for j in range(n)] for i in range(n)]
    den = [[tfs[i].den[0][0] if i == j else [1.0] for j in range(n)] for i in range(n)]
    return control.tf(num, den)


# the paper's weights, transcribed from section 3 (independent of polyrob.plant.weights)
W_S = _diag(control.tf([0.5, 0.5], [1, 0.005]), control.tf([0.3333, 0.1], [1, 0.002]))
W_T = _diag(control.tf([1, 10], [0.01, 21]), control.tf([1, 12], [0.01, 36]))


@pytest.fixture(scope="module")
def P(unc):
    return generalized_plant(unc, W_S, W_T)


@pytest.fixture(scope="module")
def K():
    return paper_controller()


def _rel(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(np.asarray(b)).max()


def _loop_fr(G, K, s):
    """S and T at s by complex matrix arithmetic (independent of the state-space code)."""
    Gj = np.asarray(G(s)).reshape(2, 2)
    L = Gj @ np.asarray(K(s)).reshape(2, 2)
    S = np.linalg.inv(np.eye(2) + L)
    return S, L @ S


def test_paper_controller_transcription(K):
    assert isinstance(K, control.TransferFunction) and (K.noutputs, K.ninputs) == (2, 2)
    np.testing.assert_array_equal(K.num[0][0], [1.07e5, 1.392e5, 44157])
    np.testing.assert_array_equal(K.num[0][1], [264150, 5.362e05, 15849])
    np.testing.assert_array_equal(K.num[1][0], [3.421e4, 4.447e4, 14454])
    np.testing.assert_array_equal(K.num[1][1], [1.172e5, 4.728e5, 16406])
    np.testing.assert_array_equal(K.den[0][0], [0.02, 4, 200, 1])
    np.testing.assert_array_equal(K.den[0][1], [0.08333, 13.33, 500, 1])
    np.testing.assert_array_equal(K.den[1][0], [0.01422, 3.556, 222.2, 1])
    np.testing.assert_array_equal(K.den[1][1], [0.02319, 6.494, 454.6, 1])
    np.testing.assert_allclose(np.real(K(0)), [[44157, 15849], [14454, 16406]])
    poles = np.concatenate([np.roots(K.den[i][j]) for i in range(2) for j in range(2)])
    assert len(poles) == 12 and np.all(poles.real < 0)  # "the controller is stable"


def test_generalized_plant_sizes_and_partition(P):
    assert isinstance(P, GeneralizedPlant)
    assert (P.n_delta, P.n_w, P.n_z, P.n_u, P.n_y) == (10, 2, 4, 2, 2)
    sys = P.system
    assert (sys.ninputs, sys.noutputs, sys.nstates) == (14, 16, 8)  # 4 plant + 2 W_S + 2 W_T states
    assert sys.input_labels[10:] == ["r[0]", "r[1]", "u[0]", "u[1]"]
    assert sys.output_labels[10:] == ["z_S[0]", "z_S[1]", "z_T[0]", "z_T[1]", "e[0]", "e[1]"]
    assert P.z_labels == ("W_S e", "W_T y")
    assert P.input_slices == {"d": slice(0, 10), "w": slice(10, 12), "u": slice(12, 14)}
    assert P.output_slices == {"v": slice(0, 10), "z": slice(10, 14), "y": slice(14, 16)}
    assert P.z_slices == {"W_S e": slice(0, 2), "W_T y": slice(2, 4)}
    D = np.asarray(sys.D)
    np.testing.assert_array_equal(D[:10, :10], 0)  # D_vd = 0
    np.testing.assert_array_equal(D[14:, 10:12], np.eye(2))  # e = r - y: D_yw = I
    np.testing.assert_array_equal(D[14:, 12:], 0)  # D_yu = 0
    np.testing.assert_array_equal(D[10:14, 12:], 0)  # D_zu = 0 without W_KS (hence `regularize`)
    np.testing.assert_array_equal(np.asarray(sys.C)[14:, :4], -np.hstack([np.eye(2), np.zeros((2, 2))]))


def test_block_structures(P, unc, pldi):
    assert P.block_structure_rs.tolist() == [[-1, 0]] * 10
    assert P.block_structure_rp.tolist() == [[-1, 0]] * 10 + [[2, 4]]  # Δ_perf is n_w x n_z
    np.testing.assert_array_equal(P.block_structure_rs, unc.block_structure)
    Pm = generalized_plant(uncertain_plant(pldi, model="box", merge_symmetric=True), W_S, W_T)
    assert Pm.n_delta == 10
    assert Pm.block_structure_rp.tolist() == [[-1, 0]] * 7 + [[-2, 0], [-1, 0], [2, 4]]


def test_rp_block_fits_the_closed_loop(P, K):
    N = lft(P, K)
    st = BlockStructure.from_matlab(P.block_structure_rp)
    assert st.m_shape == (N.noutputs, N.ninputs) == (14, 12)
    assert st.delta_shape == (12, 14)
    assert BlockStructure.from_matlab(P.block_structure_rs).m_shape == (10, 10)


@pytest.mark.parametrize("merge", [False, True])
def test_lft_with_delta_equals_the_direct_closed_loop(pldi, K, merge):
    u = uncertain_plant(pldi, model="box", merge_symmetric=merge)
    P = generalized_plant(u, W_S, W_T)
    N = lft(P, K)
    assert (N.ninputs, N.noutputs, N.nstates) == (12, 14, 8 + 12)
    assert N.input_labels[-2:] == ["r[0]", "r[1]"] and N.output_labels[-4:] == ["z_S[0]", "z_S[1]", "z_T[0]", "z_T[1]"]
    rng = np.random.default_rng(11)
    for d in rng.uniform(-1, 1, (3, u.n_params)):
        Nd = upper_lft(N, u.delta_matrix(d))  # close the uncertainty channels: w -> z
        G = u.plant_at(d)
        # the two LFTs commute: Fu(Fl(P, K), Δ) = Fl(Fu(P, Δ), K)
        Nd2 = lft(P.at(d), K, n_u=2, n_y=2)
        for w in FREQS:
            s = 1j * w
            S, T = _loop_fr(G, K, s)
            ref = np.vstack([np.asarray(W_S(s)) @ S, np.asarray(W_T(s)) @ T])
            assert _rel(Nd(s), ref) < 1e-8
            assert _rel(Nd2(s), ref) < 1e-8


def test_nominal_sensitivity_from_the_lft(pldi, K):
    # midpoint nominal: G_n is the LFT centre, so Δ = 0 gives W_S S_n
    u_mid = uncertain_plant(pldi, model="box", nominal="midpoint")
    N = lft(generalized_plant(u_mid, W_S, W_T), K)
    Nww = upper_lft(N, np.zeros((10, 10)))
    # PLDI nominal (equilibrium, off-centre): Δ = diag(nominal_delta) gives W_S S_n
    u = uncertain_plant(pldi, model="box")
    Nn = upper_lft(lft(generalized_plant(u, W_S, W_T), K), u.delta_matrix(u.nominal_delta))
    for w in FREQS:
        s = 1j * w
        WSinv = np.linalg.inv(np.asarray(W_S(s)))
        S_mid, _ = _loop_fr(u_mid.nominal_system(), K, s)
        assert _rel(WSinv @ np.asarray(Nww(s))[:2], S_mid) < 1e-8
        S_n, T_n = _loop_fr(u.nominal_system(), K, s)
        assert _rel(WSinv @ np.asarray(Nn(s))[:2], S_n) < 1e-8
        assert _rel(np.linalg.inv(np.asarray(W_T(s))) @ np.asarray(Nn(s))[2:], T_n) < 1e-8


def test_loop_function_helpers(unc, K):
    cl = nominal_closed_loop(unc, K)
    assert isinstance(cl, ClosedLoop) and cl.delta is None
    assert cl.stable and cl.poles.real.max() < 0  # K* stabilises the paper's G_n
    assert (cl.S.ninputs, cl.S.noutputs, cl.system.nstates) == (2, 2, 16)
    d = np.linspace(-1, 1, 10)
    cd = closed_loop(unc, K, d)
    np.testing.assert_array_equal(cd.delta, d)
    for w in FREQS:
        s = 1j * w
        S, T = _loop_fr(unc.nominal_system(), K, s)
        assert _rel(cl.S(s), S) < 1e-9 and _rel(cl.T(s), T) < 1e-9
        np.testing.assert_allclose(np.asarray(cl.S(s)) + np.asarray(cl.T(s)), np.eye(2), atol=1e-9)
        assert _rel(cl.KS(s), np.asarray(K(s)) @ S) < 1e-9
        Sd, Td = _loop_fr(unc.plant_at(d), K, s)
        assert _rel(cd.S(s), Sd) < 1e-9 and _rel(cd.T(s), Td) < 1e-9
    # an unstable loop is reported as such: positive feedback on a double integrator
    bad = loop_functions(control.ss(control.tf([1], [1, 0, 0])), -1.0)
    assert not bad.stable and bad.poles.real.max() > 0


def test_siso_weight_applies_to_every_channel(unc):
    w = control.tf([0.5, 0.5], [1, 0.005])
    P1 = generalized_plant(unc, w)
    P2 = generalized_plant(unc, _diag(w, w))
    assert P1.system.nstates == P2.system.nstates == 6 and P1.n_z == 2
    for f in FREQS:
        np.testing.assert_allclose(P1.system(1j * f), P2.system(1j * f), rtol=1e-12, atol=1e-14)
    # a static gain is a weight too
    P3 = generalized_plant(unc, W_S, W_KS=0.01)
    assert P3.z_labels == ("W_S e", "W_KS u") and P3.n_z == 4 and P3.system.nstates == 6
    np.testing.assert_array_equal(np.asarray(P3.system.D)[12:14, 12:], 0.01 * np.eye(2))


def test_regularize_adds_a_full_rank_D_zu(unc):
    P = generalized_plant(unc, W_S, W_T, regularize=1e-4)
    assert P.z_labels == ("W_S e", "W_T y", "reg u") and P.n_z == 6 and P.regularize == 1e-4
    assert P.block_structure_rp[-1].tolist() == [2, 6]
    D_zu = np.asarray(P.system.D)[P.output_slices["z"], P.input_slices["u"]]
    np.testing.assert_array_equal(D_zu, np.vstack([np.zeros((4, 2)), 1e-4 * np.eye(2)]))
    assert np.linalg.matrix_rank(D_zu) == 2


def test_weights_of_the_wrong_kind_raise(unc):
    with pytest.raises(PolyrobError, match=r"W_T is 3x3; expected SISO .* or 2x2"):
        generalized_plant(unc, W_S, control.ss(-np.eye(3), np.eye(3), np.eye(3), np.zeros((3, 3))))
    with pytest.raises(PolyrobError, match=r"W_S is 2x1"):
        generalized_plant(unc, control.tf([[[1]], [[1]]], [[[1, 1]], [[1, 2]]]))
    with pytest.raises(PolyrobError, match=r"W_KS is a \(3,\) gain"):
        generalized_plant(unc, W_S, W_KS=np.ones(3))
    with pytest.raises(PolyrobError, match="discrete-time"):
        generalized_plant(unc, control.tf([1], [1, -0.5], 0.1))
    with pytest.raises(PolyrobError, match="Re >= 0"):
        generalized_plant(unc, control.tf([1], [1, 0]))
    with pytest.raises(PolyrobError, match="improper"):
        generalized_plant(unc, control.tf([1, 0, 0], [1, 1]))
    with pytest.raises(PolyrobError, match="at least one weight"):
        generalized_plant(unc)
    with pytest.raises(PolyrobError, match="regularize"):
        generalized_plant(unc, W_S, regularize=-1.0)
    with pytest.raises(PolyrobError, match="UncertainPlant"):
        generalized_plant(unc.nominal_system(), W_S)


def test_lft_rejects_mismatched_controllers(P):
    with pytest.raises(PolyrobError, match="expected 2 measurements -> 2 controls"):
        lft(P, np.ones((3, 2)))
    with pytest.raises(PolyrobError, match="needs n_u and n_y"):
        lft(P.system, np.eye(2))
    with pytest.raises(PolyrobError, match="discrete-time"):
        lft(P, control.ss([[0.5]], [[1, 0]], [[1], [0]], np.zeros((2, 2)), 0.1))
    # a static controller closes the loop without adding states
    assert lft(P, 100.0 * np.eye(2)).nstates == P.system.nstates


def test_paper_weights_from_the_weights_module_agree():
    WS, WT = paper_weights()
    for w in FREQS:
        np.testing.assert_allclose(WS(1j * w), W_S(1j * w), rtol=1e-3)  # 0.3333 vs 1/3
        np.testing.assert_allclose(WT(1j * w), W_T(1j * w), rtol=1e-12)


def test_a_large_controller_feedthrough_is_a_well_posed_loop():
    """python-control's rank test of [[I, -D22], [-D_K, I]] refuses a D_K of 1e14 although D22 = 0.

    (A tf3 synthesis on paper_2r ended with "LFT not well-posed to working precision" this way.)
    The loop equations solve ``I - D22 D_K = I``: polyrob closes the loop all the same.
    """
    from polyrob.plant.loops import lft

    P = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])  # y = x, D22 = 0
    K = control.ss([[-1.0]], [[1.0]], [[1.0]], [[1e14]])
    with pytest.raises(ValueError, match="well-posed"):
        P.lft(K, nu=1, ny=1)
    N = lft(P, K, n_u=1, n_y=1)
    # u = 1e14 y + xK: A_cl = [[-1 + 1e14, 1], [1, -1]]
    np.testing.assert_allclose(N.A, [[-1.0 + 1e14, 1.0], [1.0, -1.0]])
    np.testing.assert_allclose(N.B, [[1.0], [0.0]])
