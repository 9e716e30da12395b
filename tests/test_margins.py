"""What a controller certifies when robust performance is not: the margin read from a proved mu level."""

from __future__ import annotations

import control
import numpy as np
import pytest

from polyrob.analysis.certificate import certify_loop
from polyrob.analysis.margins import robust_margin
from polyrob.analysis.mu.between import LEVEL_MARGIN


def _loop(gain: float, pole: float = -1.0):
    """``P`` whose loop with ``K = -1`` is ``N = gain / (s - pole + 1)``."""
    return control.ss([[pole]], [[gain, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])


def test_margin_is_the_level_proved_at_every_frequency():
    # N = 3/(s + 2): |N| peaks at omega = 0 with 1.5; one complex block, so mu = |N| exactly
    cert = certify_loop(_loop(3.0), -1.0, [[1, 1]], n_u=1, n_y=1)
    assert not cert.certified
    m = robust_margin(cert)
    assert m.proved and 1.5 <= m.level <= 1.5 * (1 + LEVEL_MARGIN) ** 2
    assert m.fraction == pytest.approx(1 / m.level) and m.peak_omega == min(cert.mu.omega)  # |N| falls with omega
    assert m.sentence().startswith("robust performance at level 1.5")


def test_a_certified_loop_keeps_its_bound():
    cert = certify_loop(_loop(1.0), -1.0, [[1, 1]], n_u=1, n_y=1)  # N = 1/(s + 2): mu 0.5
    m = robust_margin(cert)
    assert cert.certified and m.proved and m.level == cert.bound < 1
    assert (
        m.sentence() == f"robust performance at level {m.level:.3g} for {100 / m.level:.0f} % of the parameter ranges"
    )


def test_no_margin_without_a_stable_nominal_loop():
    # P's pole at +3 with K = -1: N = 1/(s - 2), unstable at Delta = 0: nothing is proved, whatever mu says
    cert = certify_loop(_loop(1.0, pole=3.0), -1.0, [[1, 1]], n_u=1, n_y=1)
    m = robust_margin(cert)
    assert not m.proved and np.isnan(m.fraction) and "not proved stable" in m.reason


def test_the_dominant_weighted_signal_is_the_largest_block_of_the_nominal_loop():
    """On the paper's loop with K*: the label whose block of w -> z is largest, evaluated by python-control."""
    from conftest import paper_pldi

    import polyrob
    from polyrob.analysis.margins import dominant_weight
    from polyrob.pipeline import build_problem
    from polyrob.plant.generalized import paper_controller
    from polyrob.plant.loops import lft

    P = build_problem(polyrob.load_robot("paper_2r"), pldi=paper_pldi(), uncertainty="box").P
    N = lft(P, paper_controller())
    zs, ws = P.output_slices["z"], P.input_slices["w"]
    seen = set()
    for w in (1e-3, 1.0, 1e2, 1e4):
        H = np.asarray(N(1j * w))[zs, ws]
        gains = {lab: np.linalg.norm(H[rows], 2) for lab, rows in P.z_slices.items()}
        assert dominant_weight(P, N, w) == max(gains, key=gains.get)
        seen.add(dominant_weight(P, N, w))
    assert seen == {"W_S e", "W_T y"}  # both demands dominate somewhere (before: always the first label)
