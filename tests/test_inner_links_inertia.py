"""The inertia block's bound of the ``inner-links`` model (:mod:`polyrob.plant.models.inner_links_inertia`)."""

from __future__ import annotations

import numpy as np
import pytest

from polyrob.plant.models.inner_links_inertia import g_norm_bound, residual_norm_bounds


def _random_block(seed, J=6, S=5, m=4, P=25, k=3):
    rng = np.random.default_rng(seed)
    box = 0.1 * rng.standard_normal((J, S, m, m))  # not symmetric: a fixed weighting away from the task's centre
    payload = 0.2 * rng.standard_normal((k, S, m, m))
    pay = rng.uniform(-1.0, 1.0, (P, k))
    kappa = rng.uniform(1.0, 1.3, S)
    return box, payload, pay, kappa


def _symmetric_plus_skew(box, payload, pay, kappa):
    """The earlier bound: the symmetric part's spectrum (matrix cube) plus the skew parts' norms, centred."""
    sym = 0.5 * (box + np.swapaxes(box, -1, -2))
    skew = np.linalg.norm(box - sym, 2, axis=(-2, -1)).sum(0)
    w, V = np.linalg.eigh(sym)
    A = np.einsum("...ab,...b,...cb->...ac", V, np.abs(w), V).sum(0)
    R = np.einsum("pi,isab->psab", pay, payload)
    S_p = 0.5 * (R + np.swapaxes(R, -1, -2))
    skew = skew + np.linalg.norm(R - S_p, 2, axis=(-2, -1)).max(0)
    top, bottom = np.linalg.eigvalsh(S_p + A).max(-1), np.linalg.eigvalsh(S_p - A).min(-1)
    g0 = 0.5 * (top.max() + bottom.min())
    half = np.maximum(top - g0, g0 - bottom).max(0)
    return float((kappa * (half + skew)).max()), g0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_bound_holds_for_every_member_and_every_sample(seed):
    box, payload, pay, kappa = _random_block(seed)
    g_norm, g0 = g_norm_bound(box, payload, pay, kappa)
    rng = np.random.default_rng(100 + seed)
    m = box.shape[-1]
    worst = 0.0
    for _ in range(3000):
        u = rng.choice([-1.0, 1.0], len(box)) if rng.random() < 0.5 else rng.uniform(-1, 1, len(box))
        p, s = rng.integers(len(pay)), rng.integers(box.shape[1])
        X = np.tensordot(u, box[:, s], axes=1) + np.tensordot(pay[p], payload[:, s], axes=1) - g0 * np.eye(m)
        worst = max(worst, kappa[s] * np.linalg.norm(X, 2))
    assert worst <= g_norm * (1 + 1e-12)
    assert worst > 0.5 * g_norm  # and it is no loose bound: vertices come within a factor of two


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_it_is_smaller_than_the_symmetric_part_plus_the_skew_norms(seed):
    box, payload, pay, kappa = _random_block(seed)
    g_norm, g0 = g_norm_bound(box, payload, pay, kappa)
    old, old_g0 = _symmetric_plus_skew(box, payload, pay, kappa)
    assert g_norm / (1 - g0) < old / (1 - old_g0)


def test_one_symmetric_scalar_is_bounded_exactly():
    # u diag(0.3, -0.1), |u| <= 1: the norm is 0.3, centred at 0
    box = np.diag([0.3, -0.1])[None, None]
    g_norm, g0 = g_norm_bound(box, np.zeros((0, 1, 2, 2)), np.zeros((1, 0)), np.ones(1))
    assert g_norm == pytest.approx(0.3, abs=2e-3) and abs(g0) < 2e-3


@pytest.mark.parametrize("seed", [0, 1])
def test_the_residual_s_norm_bound_holds_for_every_member_and_is_at_most_the_triangle_inequality(seed):
    rng = np.random.default_rng(seed)
    box = rng.standard_normal((8, 4, 3, 6))  # the state residual: joints x states, 8 scalars, 4 samples
    payload = rng.standard_normal((2, 4, 3, 6))
    pay = rng.uniform(-1.0, 1.0, (30, 2))
    bound = residual_norm_bounds(box, payload, pay, chunk=3)
    triangle = np.linalg.norm(box, 2, axis=(-2, -1)).sum(0) + np.linalg.norm(
        np.einsum("pi,isab->psab", pay, payload), 2, axis=(-2, -1)).max(0)  # fmt: skip
    assert np.all(bound <= triangle * (1 + 1e-12)) and np.any(bound < 0.9 * triangle)
    for s in range(4):
        worst = max(
            np.linalg.norm(
                np.tensordot(rng.choice([-1.0, 1.0], 8), box[:, s], axes=1)
                + np.tensordot(pay[p], payload[:, s], axes=1),
                2,
            )  # fmt: skip
            for p in rng.integers(0, 30, 400)
        )
        assert 0.5 * bound[s] < worst <= bound[s] * (1 + 1e-12)


def _anisotropic_block(seed, S=4, m=4, P=40):
    """Box scalars that move one direction a lot and the others little, and a payload along a second direction."""
    rng = np.random.default_rng(seed)
    Q = np.linalg.qr(rng.standard_normal((m, m)))[0]
    big = 0.4 * np.outer(Q[:, 0], Q[:, 0])
    small = [0.03 * np.outer(Q[:, k], Q[:, k]) for k in range(1, m)]
    box = np.array([[M + 0.01 * rng.standard_normal((m, m)) for _ in range(S)] for M in [big, *small]])
    payload = np.array([[0.2 * np.outer(Q[:, 1], Q[:, 1]) + 0.01 * rng.standard_normal((m, m)) for _ in range(S)]])
    pay = rng.uniform(0.0, 1.0, (P, 1))  # a payload mass from none to full: not centred at the model
    return box, payload, pay


@pytest.mark.parametrize("seed", [0, 1])
def test_the_shaped_block_holds_every_member_and_is_thinner_than_the_ball(seed):
    """``shape_of`` + ``g_norm_bound(shape=, centre=)``: every member (box vertices and inside, every payload point
    and sample) lies in ``C + g0 S + g S^1/2 Delta S^1/2``; the shape follows the set (one direction 0.4, the
    others 0.03 and a payload of 0.2 off centre), so the block is far thinner than the ball in most directions."""
    from polyrob.plant.models.inner_links_inertia import shape_of

    box, payload, pay = _anisotropic_block(seed)
    S, C = shape_of(box, payload, pay)
    g, t = g_norm_bound(box, payload, pay, np.ones(box.shape[1]), shape=S, centre=C)
    values, vectors = np.linalg.eigh(S)
    H_inv = (vectors / np.sqrt(values)) @ vectors.T
    offset = C + t * S
    rng = np.random.default_rng(50 + seed)
    worst = 0.0
    for _ in range(3000):
        u = rng.choice([-1.0, 1.0], len(box)) if rng.random() < 0.5 else rng.uniform(-1, 1, len(box))
        p, s = rng.integers(len(pay)), rng.integers(box.shape[1])
        X = np.tensordot(u, box[:, s], axes=1) + pay[p, 0] * payload[0, s]
        worst = max(worst, np.linalg.norm(H_inv @ (X - offset) @ H_inv, 2))
    assert worst <= g * (1 + 1e-12)
    assert worst > 0.5 * g  # no loose bound
    ball, _ = g_norm_bound(box, payload, pay, np.ones(box.shape[1]))
    assert values.max() == pytest.approx(1.0)
    assert np.sum(g * values < 0.5 * ball) >= 2  # at least two directions at less than half the ball's radius


def test_a_shaped_block_s_member_is_in_the_lft_and_a_larger_one_is_not():
    """The membership test reads a shaped block's matrix weights (``scaled_residuals``: ``H^-1 E H^-1``, ``H = root
    g S^1/2``): a residual at the shape's edge has scaled norm 1, the same residual 10 % larger 1.1, and an error
    a ball of the same g would hold is 16 times the shape's edge along its thin axis (the LFT side:
    ``tests/test_arm_uncertainty_model.py``)."""
    from types import SimpleNamespace

    from polyrob.plant.models.factor_membership import scaled_residuals

    m = 3
    S = np.diag([1.0, 0.1, 0.05])
    H = 0.5 * np.sqrt(S)  # g = 0.25
    unc = SimpleNamespace(
        info={"residual_blocks": [{"rows": np.arange(m), "cols": np.arange(2 * m, 3 * m), "W_l": H, "W_r": H}]},
        full_blocks=[m],
    )
    E = np.zeros((m, 3 * m))
    Delta = np.linalg.qr(np.random.default_rng(4).standard_normal((m, m)))[0]  # norm 1
    E[:, 2 * m :] = H @ Delta @ H
    assert np.linalg.norm(scaled_residuals(unc, E)[0], 2) == pytest.approx(1.0)
    assert np.linalg.norm(scaled_residuals(unc, 1.1 * E)[0], 2) == pytest.approx(1.1)
    along_thin = np.zeros((m, 3 * m))
    along_thin[2, 2 * m + 2] = 0.2  # within a ball of 0.25, five times the shape's 0.25 * 0.05 there
    assert np.linalg.norm(scaled_residuals(unc, along_thin)[0], 2) == pytest.approx(16.0)
