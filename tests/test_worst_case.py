"""The worst-case gain over the set with an upper bound at every frequency (:mod:`polyrob.analysis.worst_case`)."""

import control
import numpy as np
import pytest

from polyrob.analysis.worst_case import performance_scaled, wcgain
from polyrob.errors import ArgumentError


def two_parameter_loop(a, b):
    """``x1' = -x1 + a δ1 x1 + w``, ``x2' = -2 x2 + x1 + b δ2 x2``, ``z = x2``: two real scalars ``δ_i ∈ [-1, 1]``.

    Inputs ``[d1, d2, w, u]``, outputs ``[v1, v2, z, y]`` (``v_i`` the states, ``d_i = δ_i v_i``).
    """
    A = np.array([[-1.0, 0.0], [1.0, -2.0]])
    B = np.array([[a, 0.0, 1.0, 0.0], [0.0, b, 0.0, 0.0]])
    C = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
    return control.ss(A, B, C, np.zeros((4, 4)))


def brute_gain(a, b, grid=41):
    """``sup ||F_u||_∞`` by enumeration: ``F_u = 1/((s + 1 - a δ1)(s + 2 - b δ2))`` peaks at DC for these poles."""
    d = np.linspace(-1.0, 1.0, grid)
    d1, d2 = np.meshgrid(d, d)
    p1, p2 = 1.0 - a * d1, 2.0 - b * d2
    return float(np.where((p1 > 0) & (p2 > 0), 1.0 / (p1 * p2), np.inf).max())


@pytest.mark.parametrize("a, b", [(0.5, 1.0), (0.3, 0.5), (0.8, 1.5)])
def test_two_real_scalars_bounds_hold_the_enumerated_worst_case(a, b):
    worst = brute_gain(a, b)  # δ = (1, 1): 1 / ((1 - a)(2 - b))
    assert worst == pytest.approx(1.0 / ((1 - a) * (2 - b)))
    g = wcgain(two_parameter_loop(a, b), 0.0, [[-1, 0], [-1, 0], [1, 1]], n_u=1, n_y=1)
    assert g.proved and g.certificate.certified
    assert g.lower <= worst * (1 + 1e-9) <= g.upper
    assert g.lower == pytest.approx(worst, rel=1e-2)  # the lower bound's perturbation: near the worst member
    assert g.upper <= 1.1 * worst
    assert g.critical_frequency == pytest.approx(0.0, abs=1e-6)
    assert g.certificate.scope.kind == "worst-case gain"
    assert g.certificate.scope.frequencies == "every frequency"


def test_a_complex_block_gives_the_small_gain_worst_case():
    # x' = -x + w + d, v = 0.5 x, z = x: F_u = 1 / (s + 1 - 0.5 Δ(s)), worst |Δ| = 1 in phase at DC: gain 2
    P = control.ss([[-1.0]], [[1.0, 1.0, 0.0]], [[0.5], [1.0], [0.0]], np.zeros((3, 3)))
    g = wcgain(P, 0.0, [[1, 1], [1, 1]], n_u=1, n_y=1)
    assert g.proved
    assert g.lower == pytest.approx(2.0, rel=1e-3)
    assert 2.0 <= g.upper <= 2.0 * 1.05


def test_no_upper_bound_without_robust_stability():
    # δ ∈ [-1, 1] with a = 1.2 moves the pole 1 - 1.2 δ past zero: some member is unstable
    g = wcgain(two_parameter_loop(1.2, 0.5), 0.0, [[-1, 0], [-1, 0], [1, 1]], n_u=1, n_y=1)
    assert not g.proved and g.upper == np.inf
    assert "robust stability" in g.reason
    assert g.lower == np.inf or g.lower > 10.0  # a member near the singular one
    assert "robust stability fails" in g.sentence() if g.lower == np.inf else "no upper bound proved" in g.sentence()


def test_a_sufficient_structure_claims_no_member():
    g = wcgain(two_parameter_loop(0.5, 1.0), 0.0, [[-1, 0], [-1, 0], [1, 1]], n_u=1, n_y=1, members=False)
    assert g.proved and g.lower == 0.0
    assert g.summary()["critical_frequency"] is None  # strict JSON: no member, no frequency


def test_performance_scaled_divides_the_performance_inputs_only():
    P = two_parameter_loop(0.5, 1.0)
    S = performance_scaled(P, 4.0, 1, 1)
    B, B0 = np.asarray(S.B), np.asarray(P.B)
    assert np.allclose(B[:, 2], B0[:, 2] / 4.0)
    assert np.allclose(np.delete(B, 2, axis=1), np.delete(B0, 2, axis=1))


def test_refusals():
    P = two_parameter_loop(0.5, 1.0)
    with pytest.raises(ArgumentError, match="needs blk"):
        wcgain(P, 0.0)
    with pytest.raises(ArgumentError, match="last block"):
        wcgain(P, 0.0, [[-1, 0], [-1, 0], [-1, 0]], n_u=1, n_y=1)
