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


# --------------------------------------------------------------------------- which block carries mu
def test_leaving_a_block_out_gives_mu_of_the_rest():
    from polyrob.analysis.margins import block_shares

    # uncoupled real scalars: mu is the largest |m_ii|, without a block the largest of the others
    M = np.diag([2.0, 0.5, 1.0]).astype(complex)
    shares = block_shares(M, [[-1, 0], [-1, 0], [-1, 0]], ["a", "b", "c"], skip_last=False)
    assert [s.block for s in shares] == ["a", "b", "c"]  # ties keep the model's order
    assert [s.mu_without for s in shares] == pytest.approx([1.0, 2.0, 2.0], rel=1e-3)
    # a loop through two complex scalars: mu = sqrt(|ab|) = 2; either one out breaks the loop, mu 0
    M = np.array([[0.0, 4.0], [1.0, 0.0]], complex)
    shares = block_shares(M, [[1, 0], [1, 0]], skip_last=False)
    assert [s.mu_without for s in shares] == pytest.approx([0.0, 0.0], abs=1e-9)
    # robust performance: the last block (performance) stays in; a full 1x2 block (Delta 1x2) has two rows of M
    M = np.array([[0.3, 0.1], [0.0, 0.2], [0.4, 0.9]], complex)
    (only,) = block_shares(M, [[-1, 0], [1, 2]])
    assert only.block == "block 0" and only.mu_without == pytest.approx(np.linalg.norm(M[1:, 1:], 2), rel=1e-3)


def test_blocks_are_named_in_the_model_s_words():
    from types import SimpleNamespace

    from polyrob.analysis.margins import block_words

    # an inner-links-like model: two residual blocks (state columns 0..3, acceleration columns 4..5), one real t0 x2
    unc = SimpleNamespace(
        channel_names=("res#0", "res#1", "res#2", "res#3", "res#4", "res#5", "t0#0", "t0#1"),
        channel_parameter=np.array([-1, -1, -1, -1, -1, -1, 0, 0]),
        parameter_names=("t0",),
        n_x=4,
        info={"residual_blocks": [{"cols": np.arange(4)}, {"cols": np.array([4, 5])}]},
    )
    words = block_words(unc, [[4, 4], [2, 2], [-2, 0], [2, 6]])
    assert words == (
        "the state columns' residual (4x4)",
        "the acceleration columns' residual, the inertia (2x2)",
        "t0",
        "performance",
    )
