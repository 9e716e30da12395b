"""Stability verdicts that survive badly conditioned realisations (issue 14)."""

from __future__ import annotations

import json
from pathlib import Path

import control
import numpy as np
import pytest

from polyrob.analysis.mu.frequency import freqresp_extended, response_error
from polyrob.analysis.robust import loop_mu
from polyrob.analysis.stability import stability_verdict
from polyrob.examples import DISTILLATION_BLK, distillation_plant
from polyrob.plant.generalized import lft

FIXTURE = Path(__file__).parent / "fixtures" / "dkpy_distillation_controller.json"


def _dkpy_controller() -> control.StateSpace:
    doc = json.loads(FIXTURE.read_text())
    return control.ss(*(np.array(doc[k], dtype=float) for k in "ABCD"))


def _stable_loop():
    """A stable closed loop: a lightly damped MIMO plant with a static output feedback."""
    G = control.ss(
        [[0, 1, 0, 0], [-4, -0.4, 1, 0], [0, 0, 0, 1], [1, 0, -9, -0.6]],
        [[0, 0], [1, 0], [0, 0], [0, 1]],
        [[1, 0, 0, 0], [0, 0, 1, 0]],
        np.zeros((2, 2)),
    )
    return control.feedback(G, np.eye(2))


def test_real_pole_at_plus_1e_3_is_unstable():
    cl = _stable_loop()
    A = np.array(cl.A, dtype=float)
    n = A.shape[0]
    # append a decoupled real pole at +1e-3, then mix it in with a random similarity
    A1 = np.block([[A, np.zeros((n, 1))], [np.zeros((1, n)), np.array([[1e-3]])]])
    T = np.random.default_rng(1).standard_normal((n + 1, n + 1)) + 3 * np.eye(n + 1)
    v = stability_verdict(T @ A1 @ np.linalg.inv(T))
    assert v.verdict == "unstable"
    assert v.abscissa == pytest.approx(1e-3, rel=1e-6)
    assert v.error_bound < 1e-9


def test_stable_loop_under_similarity_of_condition_1e10_is_stable():
    cl = _stable_loop()
    A = np.array(cl.A, dtype=float)
    n = A.shape[0]
    # T = D Q: an orthogonal mixing, then state scalings over 2^34 ~ 1.7e10 (powers
    # of 2: the badly scaled matrix is the exact similarity of the rounded T A T^-1)
    Q, _ = np.linalg.qr(np.random.default_rng(0).standard_normal((n, n)))
    d = 2.0 ** np.linspace(0, 34, n).round()
    T = d[:, None] * Q
    assert np.linalg.cond(T) > 1e10
    Aill = d[:, None] * (Q @ A @ Q.T) / d[None, :]
    assert np.linalg.norm(Aill, 2) > 1e9
    v = stability_verdict(Aill)
    assert v.verdict == "stable"
    exact = np.linalg.eigvals(A).real.max()
    assert v.abscissa == pytest.approx(exact, rel=1e-6)
    assert v.transform_condition > 1e9  # the balancing undid the scaling and says so


def test_undecided_when_the_margin_is_inside_the_bound():
    # a defective triple eigenvalue at -1e-9: relative changes of 4 eps in the entries
    # move it by ~(4 eps)^(1/3) ~ 1e-5, so no precision can call the given data stable
    a = -1e-9
    v = stability_verdict(np.array([[a, 1.0, 0.0], [0.0, a, 1.0], [0.0, 0.0, a]]))
    assert v.verdict == "undecided at double precision"
    assert v.error_bound > 1e-5 and len(v.tests) == 4
    assert v.tests[2].startswith("106-bit") and v.tests[3].startswith("212-bit")  # both precisions tried


def test_extended_precision_decides_what_double_precision_cannot():
    # eigenvalue -1e-14 with condition ~1e3: double precision bound 4e-10 > 1e-14
    A = np.array([[-1e-14, 1e3], [0.0, -1.0]])
    assert stability_verdict(A, extended_bits=0).verdict == "undecided at double precision"
    v = stability_verdict(A)
    # triangular: the eigenvalues are the diagonal entries, exactly
    assert v.verdict == "stable" and v.abscissa == -1e-14 and v.precision_bits == 106  # double-double decides


def test_dkpy_distillation_controller_double_precision_is_fooled():
    """The fixture's closed loop: plain double eigenvalues show a spurious unstable pole."""
    N = lft(distillation_plant(), _dkpy_controller(), n_u=2, n_y=2)
    assert np.linalg.eigvals(N.A).real.max() > 1e-3  # what the old path read as "unstable"
    v = stability_verdict(N)
    assert v.verdict == "stable"
    assert v.abscissa == pytest.approx(-1e-6, rel=1e-6)  # 600-bit value quoted in issue 14
    assert v.error_bound < 1e-9


def test_dkpy_distillation_controller_mu_matches_independent_value():
    """Issue 14: stable, μ upper within 0.5 % of 1.036 (1.0360 / 1.0358 with independent tools)."""
    r = loop_mu(
        distillation_plant(),
        _dkpy_controller(),
        DISTILLATION_BLK,
        np.logspace(-3, 3, 61),
        n_u=2,
        n_y=2,
        refine_peak=True,
    )
    assert r.stability.stable
    assert r.mu_upper_grid == pytest.approx(1.036, rel=5e-3)
    assert r.mu_lower <= r.mu_upper_grid and r.mu_lower == pytest.approx(1.036, rel=5e-3)
    assert not r.robust and r.certificate.status.value == "VIOLATED"
    assert r.failed == (
        f"mu lower bound {r.mu_lower:.4g} >= 1: a member of the uncertainty model's set breaks it "
        "(the model holds the robot's set, maybe more)",
    )


def test_double_precision_response_checked_against_extended_precision():
    """Diagonal balancing (TB01ID) of dkpy's controller ruins its double-precision response;
    response_error sees it, and the 212-bit evaluation agrees across both realisations."""
    import slycot

    K = _dkpy_controller()
    A, B, C = (np.array(getattr(K, k), dtype=float) for k in "ABC")
    _, Ab, Bb, Cb, _ = slycot.tb01id(A.shape[0], B.shape[1], C.shape[0], 0.0, A.copy(), B.copy(), C.copy(), job="A")
    Kb = control.ss(Ab, Bb, Cb, K.D)
    w = np.array([1e-3, 1e-1, 1.0])
    assert response_error(K, w) < 1e-4  # the realisation as given evaluates fine
    assert response_error(Kb, w) > 0.1  # the balanced one does not, in double precision
    He, Hbe = freqresp_extended(K, w), freqresp_extended(Kb, w)
    # same transfer function up to the (non power-of-2) scaling's rounding
    assert np.max(np.abs(He - Hbe)) <= 1e-5 * np.max(np.abs(He))
