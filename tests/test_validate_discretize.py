"""Discretisation (Tustin with pre-warping, ZOH), μ of the discretised loop, quantisation."""

from __future__ import annotations

import functools
import math

import control
import numpy as np
import pytest

import polyrob
from polyrob.validate.discretize import discretize, min_sample_rate, sampled_data_mu
from polyrob.validate.quantize import min_word_length, quantize, sos_realization

GRID = np.logspace(-2, 3, 10)


@functools.cache
def _P():
    from polyrob.plant.weights import paper_weights

    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    return polyrob.generalized_plant(polyrob.uncertain_plant(pldi), *paper_weights())


def test_tustin_prewarp_is_exact_at_its_frequency():
    K = control.tf([3.0, 5.0], [1.0, 0.7, 4.0])
    rate, wp = 20.0, 6.0
    dc = discretize(K, rate, method="tustin", prewarp=wp)
    zp = np.exp(1j * wp / rate)
    assert complex(dc.system(zp)) == pytest.approx(complex(K(1j * wp)), rel=1e-10)
    plain = discretize(K, rate, method="tustin")
    assert abs(complex(plain.system(zp)) - complex(K(1j * wp))) > 1e-3  # without pre-warping it is not


def test_zoh_of_first_order_is_analytic():
    a, rate = 3.0, 50.0
    dc = discretize(control.tf([a], [1.0, a]), rate, method="zoh")
    h = 1.0 / rate
    A = float(np.asarray(dc.system.A)[0, 0])
    assert A == pytest.approx(math.exp(-a * h), rel=1e-12)
    # unit step response: 1 - exp(-a k h) at the samples
    y = dc.step_response(6)[0, 0]
    assert np.allclose(y, 1 - np.exp(-a * h * np.arange(6)), atol=1e-12)


def test_bad_discretisation_arguments():
    K = control.tf([1.0], [1.0, 1.0])
    with pytest.raises(polyrob.PolyrobError, match="rate"):
        discretize(K, 0.0)
    with pytest.raises(polyrob.PolyrobError, match="pre-warping"):
        discretize(K, 10.0, prewarp=100.0)  # above Nyquist (31.4 rad/s)
    with pytest.raises(polyrob.PolyrobError, match="unknown"):
        discretize(K, 10.0, method="euler")


def test_discretised_loop_mu_tends_to_continuous_and_fails_when_slow():
    P, K = _P(), polyrob.paper_controller()
    from polyrob.validate.discretize import continuous_mu

    mu_c = continuous_mu(P, K, GRID)
    fast = sampled_data_mu(P, K, 5000.0, omega=GRID, upper_only=True)
    assert fast.stable and fast.spectral_radius < 1
    assert fast.mu_upper_grid == pytest.approx(mu_c, rel=0.02)
    slow = sampled_data_mu(P, K, 2.0, omega=GRID)
    assert not slow.stable and slow.mu_upper_grid == math.inf
    res = min_sample_rate(P, K, mu_continuous=mu_c, omega=GRID, rate_bounds=(2.0, 5000.0), rel_tol=0.5)
    assert res.rate is not None and 2.0 < res.rate <= 5000.0
    passed = [h for h in res.history if h[3]]
    failed = [h for h in res.history if not h[3]]
    assert passed and failed and min(h[0] for h in passed) == res.rate
    assert max(h[0] for h in failed) < res.rate  # bracketed
    assert res.mu <= 1.05 * mu_c


def test_quantisation_word_length_search():
    P, K = _P(), polyrob.paper_controller()
    rate = 200.0
    sd = sampled_data_mu(P, K, rate, omega=GRID)
    sos = sos_realization(sd.controller)
    res = min_word_length(P, sos, threshold=1.05 * sd.mu_upper_grid, omega=GRID, lengths=(6, 40))
    assert res.word_length is not None and 6 < res.word_length <= 40
    ok = {h[0]: h[3] for h in res.history}
    # the bisection ends on a bracket: one bit fewer was checked and failed
    assert ok[res.word_length] is True
    assert ok[res.word_length - 1] is False
    # the quantised controller at that length: coefficients on the fixed-point grid, loop stable
    q = quantize(sos, res.word_length)
    chk = sampled_data_mu(P, None, rate, controller=q.to_ss(), omega=GRID)
    assert chk.stable and chk.mu_upper_grid <= 1.05 * sd.mu_upper_grid
