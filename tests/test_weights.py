"""Tests of polyrob.plant.weights: MATLAB makeweight and the paper's weights."""

import control
import numpy as np
import pytest

from polyrob.errors import PolyrobError
from polyrob.plant.weights import (
    PAPER_HYPERPARAMETERS,
    complementary_weight,
    diagonal_weight,
    makeweight,
    paper_weights,
    sensitivity_weight,
)


def _coeffs(W, i=0, j=0):
    return np.asarray(W.num[i][j], float), np.asarray(W.den[i][j], float)


def test_makeweight_matches_matlab_answers_example():
    # MATLAB: makeweight(100, 10, 0.1) -> (0.1 s + 9.95)/(s + 0.0995)
    num, den = _coeffs(makeweight(100, 10, 0.1))
    np.testing.assert_allclose(num, [0.1, 9.9504], atol=5e-5)
    np.testing.assert_allclose(den, [1.0, 0.0995], atol=5e-5)


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize(
    "dc, crossover, hf",
    [(100, 10, 0.1), (0.01, (3.0, 0.5), 2.0), (0.5, (0.2, 2.0), 10.0), (0.0, (1.0, 0.3), 4.0), (5.0, (2.0, 1.0), 0.0)],
)
def test_makeweight_meets_its_three_constraints(dc, crossover, hf, order):
    W = makeweight(dc, crossover, hf, order=order)
    freq, mag = crossover if isinstance(crossover, tuple) else (crossover, 1.0)
    assert abs(W(0)) == pytest.approx(dc, rel=1e-9, abs=1e-12)
    assert abs(W(1j * 1e9)) == pytest.approx(hf, rel=1e-6, abs=1e-6)
    assert abs(W(1j * freq)) == pytest.approx(mag, rel=1e-9)
    # stable and minimum phase, of the requested order
    assert np.all(np.real(W.poles()) < 0)
    assert np.all(np.real(W.zeros()) <= 0)
    assert len(W.den[0][0]) == order + 1
    # monotonic gain profile
    g = np.abs(W(1j * np.logspace(-4, 4, 400)))
    d = np.diff(g)
    assert np.all(d <= 1e-12) or np.all(d >= -1e-12)


def test_makeweight_higher_order_is_steeper():
    w1, w3 = makeweight(0.01, 1, 100), makeweight(0.01, 1, 100, order=3)
    # one decade above crossover the 3rd order weight has risen more
    assert abs(w3(10j)) > abs(w1(10j))
    assert abs(w3(0.1j)) < abs(w1(0.1j))


@pytest.mark.parametrize(
    "args, kwargs",
    [
        ((1.0, 1.0, 10.0), {}),  # mag == dcgain
        ((0.1, (1.0, 20.0), 10.0), {}),  # mag above both
        ((-1.0, 1.0, 10.0), {}),
        ((0.1, (-1.0, 1.0), 10.0), {}),
        ((0.1, (1.0, 1.0, 2.0), 10.0), {}),
        ((0.1, 1.0, float("nan")), {}),
        ((0.1, 1.0, 10.0), {"order": 0}),
        ((0.1, 1.0, 10.0), {"order": 1.5}),
    ],
)
def test_makeweight_rejects_bad_input(args, kwargs):
    with pytest.raises(PolyrobError):
        makeweight(*args, **kwargs)


def test_sensitivity_and_complementary_weights_formulae():
    WS = sensitivity_weight(0.5, 2.0, 1e-2)
    num, den = _coeffs(WS)
    np.testing.assert_allclose(num, [0.5, 0.5])
    np.testing.assert_allclose(den, [1.0, 0.005])
    # 1/|W_S|: A_s at DC, M_s at high frequency
    assert 1 / abs(WS(0)) == pytest.approx(1e-2)
    assert 1 / abs(WS(1e9j)) == pytest.approx(2.0, rel=1e-6)
    WT = complementary_weight(10.0, 2.1, 1e-2)
    num, den = _coeffs(WT)
    np.testing.assert_allclose(num, [1.0, 10.0])
    np.testing.assert_allclose(den, [0.01, 21.0])
    assert 1 / abs(WT(0)) == pytest.approx(2.1)
    assert 1 / abs(WT(1e9j)) == pytest.approx(1e-2, rel=1e-6)
    with pytest.raises(PolyrobError):
        sensitivity_weight(0.0, 2.0, 1e-2)
    with pytest.raises(PolyrobError):
        complementary_weight(10.0, -2.1, 1e-2)


def test_paper_weights_reproduce_printed_coefficients():
    # W_S = diag((0.5s+0.5)/(s+0.005), (0.3333s+0.1)/(s+0.002))
    # W_T = diag((s+10)/(0.01s+21), (s+12)/(0.01s+36))
    assert PAPER_HYPERPARAMETERS["omega_b"] == (0.5, 0.1)
    WS, WT = paper_weights()
    assert (WS.noutputs, WS.ninputs, WT.noutputs, WT.ninputs) == (2, 2, 2, 2)
    expected_ws = [([0.5, 0.5], [1.0, 0.005]), ([0.3333, 0.1], [1.0, 0.002])]
    expected_wt = [([1.0, 10.0], [0.01, 21.0]), ([1.0, 12.0], [0.01, 36.0])]
    for i in range(2):
        for W, exp in ((WS, expected_ws[i]), (WT, expected_wt[i])):
            num, den = _coeffs(W, i, i)
            np.testing.assert_array_equal(np.round(num, 4), exp[0])
            np.testing.assert_array_equal(np.round(den, 4), exp[1])
    assert WS.num[1][1][0] == pytest.approx(1 / 3, rel=1e-15)
    # diagonal: zero off-diagonal responses
    for W in (WS, WT):
        H = W(1j)
        assert H[0, 1] == 0 and H[1, 0] == 0


def test_paper_weights_bad_hyperparameters():
    h = dict(PAPER_HYPERPARAMETERS)
    h["M_s"] = (2.0,)
    with pytest.raises(PolyrobError):
        paper_weights(h)
    del h["M_s"]
    with pytest.raises(PolyrobError):
        paper_weights(h)


def test_diagonal_weight_accepts_tf_ss_and_numbers():
    w1 = control.tf([1, 2], [1, 3])
    w2 = control.ss(control.tf([4], [1, 1]))
    W = diagonal_weight([w1, w2, 0.5])
    assert (W.noutputs, W.ninputs) == (3, 3)
    s = 0.7j
    H = W(s)
    np.testing.assert_allclose(np.diag(H), [w1(s), w2(s), 0.5])
    assert np.count_nonzero(H - np.diag(np.diag(H))) == 0
    # a realisation has the sum of the orders
    assert control.ss(W).nstates == 2
    with pytest.raises(PolyrobError):
        diagonal_weight([])
    with pytest.raises(PolyrobError):
        diagonal_weight([control.tf([[[1]], [[1]]], [[[1, 1]], [[1, 2]]])])
    with pytest.raises(PolyrobError):
        diagonal_weight(["not a weight"])
