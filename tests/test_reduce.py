"""Controller order reduction with a μ certificate at every order tried."""

from __future__ import annotations

import control
import numpy as np
import pytest

from polyrob.errors import PolyrobError, SynthesisError
from polyrob.synthesis import musyn, reduce_controller
from polyrob.synthesis.reduce import balanced_reduction, stable_unstable_split

from polyrob.examples import DISTILLATION_BLK, distillation_plant


@pytest.fixture(scope="module")
def distillation():
    P = distillation_plant()
    res = musyn(P, DISTILLATION_BLK, n_u=2, n_y=2, max_iter=6, omega=np.logspace(-3, 3, 61), progress=False)
    return P, res


def test_split_reconstructs_an_unstable_controller():
    K = control.ss(control.tf([[[1, 3], [2]], [[1], [1, 0.5, 1]]],
                              [[[1, 1, -2], [1, 5]], [[1, 0], [1, 2, 10]]]))
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


def test_reduce_distillation_controller(distillation):
    P, res = distillation
    red = reduce_controller(P, res, DISTILLATION_BLK, n_u=2, n_y=2)
    assert red.meets_target
    assert red.order <= res.order
    assert red.peak_mu <= res.peak_mu * 1.05 + 1e-12
    assert red.target == pytest.approx(res.peak_mu * 1.05)
    assert red.controller.nstates == red.order
    # the trade-off table holds every order certified, the chosen one included
    orders = [row["order"] for row in red.table]
    assert orders == sorted(orders) and red.order in orders
    row = next(r for r in red.table if r["order"] == red.order)
    assert row["peak_mu"] == pytest.approx(red.peak_mu) and row["stable"]
    # and the MusynResult view carries the certificate
    assert red.result.structure == f"reduced:{red.order}"
    assert red.result.certificate.peak_upper == pytest.approx(red.peak_mu)
    assert red.summary()["order"] == red.order


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
