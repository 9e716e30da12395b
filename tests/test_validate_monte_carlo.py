"""Monte Carlo loop responses: identities of S, T, KS, the weight shapes, step responses."""

from __future__ import annotations

import functools

import control
import numpy as np
import pytest

import polyrob
from polyrob.validate.monte_carlo import frequency_response, monte_carlo, weight_shape


@functools.cache
def _problem():
    from polyrob.plant.weights import paper_weights

    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    unc = polyrob.uncertain_plant(pldi)
    return unc, polyrob.generalized_plant(unc, *paper_weights()), paper_weights()


@functools.cache
def _mc():
    unc, P, _ = _problem()
    return monte_carlo(
        P, polyrob.paper_controller(), n=4, seed=3, omega=np.logspace(-2, 3, 50), t=np.linspace(0, 2, 201)
    )


def test_loop_function_identities():
    unc, _, _ = _problem()
    mc = _mc()
    K = frequency_response(control.ss(polyrob.paper_controller()), mc.omega)
    I = np.eye(2)
    for k, d in enumerate(mc.deltas):
        G = frequency_response(unc.plant_at(d), mc.omega)
        # S + T = I, S = (I + G K)^-1, KS = K S
        assert np.allclose(mc.S[k] + mc.T[k], I, atol=1e-9)
        assert np.allclose(mc.S[k], np.linalg.inv(I + G @ K), rtol=1e-7, atol=1e-10)
        assert np.allclose(mc.KS[k], K @ mc.S[k], rtol=1e-7, atol=1e-6)
    Gn = frequency_response(unc.nominal_system(), mc.omega)
    assert np.allclose(mc.S_nominal, np.linalg.inv(I + Gn @ K), rtol=1e-7, atol=1e-10)
    assert mc.deltas.shape == (4, unc.n_params) and np.all(np.abs(mc.deltas) <= 1)


def test_weight_shapes_and_steps():
    _, _, (W_S, W_T) = _problem()
    mc = _mc()
    w = mc.omega
    ws = frequency_response(W_S, w)
    assert np.allclose(mc.inv_W_S, 1.0 / np.abs(np.diagonal(ws, axis1=1, axis2=2)).T)
    # the paper's W_S(0) = 1/A_S: 1/|W_S| starts at A_S = 0.01, 0.02
    assert np.allclose(weight_shape(W_S, [1e-9], 2)[:, 0], [0.01, 0.02], rtol=1e-6)
    assert weight_shape(None, w, 2) is None and weight_shape(2.0, w, 2).shape == (2, 50)
    # step of r_j -> y_i: starts at 0 (T strictly proper); all samples stable (as μ analysis reports)
    assert mc.all_stable
    assert np.allclose(mc.step_y[:, :, :, 0], 0.0) and np.allclose(mc.step_y_nominal[:, :, 0], 0.0)
    # the rise of the diagonal within 2 s (K* tracks steps)
    assert np.all(mc.step_y[:, 0, 0, -1] > 0.5)
    s = mc.summary()
    assert s["samples"] == 4 and s["stable_fraction"] == 1.0 and s["weight_ratio"]["S"] > 0


def test_bad_arguments():
    unc, _, _ = _problem()
    with pytest.raises(polyrob.PolyrobError, match="corners"):
        monte_carlo(unc, polyrob.paper_controller(), n="edges")
    with pytest.raises(polyrob.PolyrobError, match="at least 1"):
        monte_carlo(unc, polyrob.paper_controller(), n=0)
    with pytest.raises(polyrob.PolyrobError):
        monte_carlo(object(), polyrob.paper_controller())
