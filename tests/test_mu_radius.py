"""How far a grid point's scalings certify a level (polyrob.analysis.mu.radius), and the check that uses it."""

from __future__ import annotations

import control
import numpy as np
import pytest

import polyrob.analysis.mu.between as between
from polyrob.analysis.mu.bounds import mu_bounds
from polyrob.analysis.mu.radius import covering_radius


def _sigma(A, B, C, D, w):
    return np.linalg.norm(C @ np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, B) + D, 2)


def test_first_order_radius_stops_before_the_crossing():
    """|1/(jω + 1)| = 0.8 at ω = 0.75: from ω = 2 the radius must stay short of 1.25, and be positive."""
    A, B, C, D = -np.eye(1), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1))
    r = covering_radius(A, B, C, D, np.zeros((1, 1)), 0.8, 2.0)
    assert 0.05 < r < 2.0 - 0.75
    assert covering_radius(A, B, C, D, np.zeros((1, 1)), 0.8, 0.5) == 0.0  # |M| = 0.894 > 0.8 there


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_radius_is_sound_on_random_scaled_loops(seed):
    """Inside the radius the scaled test holds at every sampled frequency (D scalings spanning decades)."""
    rng = np.random.default_rng(seed)
    n, k = 6, 3
    A = rng.standard_normal((n, n))
    A -= (np.max(np.linalg.eigvals(A).real) + 0.3) * np.eye(n)
    B, C, D = rng.standard_normal((n, k)), rng.standard_normal((k, n)), 0.1 * rng.standard_normal((k, k))
    Dh = np.diag(10.0 ** rng.uniform(-3, 0, k))
    Di = np.linalg.inv(Dh)
    w0 = float(rng.uniform(0.0, 3.0))
    level = 1.05 * max(_sigma(A, B @ Di, Dh @ C, Dh @ D @ Di, w) for w in np.linspace(max(w0 - 5, 0), w0 + 5, 400))
    r = covering_radius(A, B @ Di, Dh @ C, Dh @ D @ Di, np.zeros((k, k)), level, w0)
    assert r > 0
    for w in np.linspace(max(w0 - r, 0.0), w0 + r, 101):
        assert _sigma(A, B @ Di, Dh @ C, Dh @ D @ Di, w) < level


def test_check_without_hamiltonian_still_covers_smooth_loops_and_finds_resonances(monkeypatch):
    """Where the Hamiltonian test does not apply (Φ(∞) singular: ``None``), the radii carry the check alone.

    The Hamiltonian answers once, for the scalings of the grid's last point (the interval up to
    infinity, which no radius reaches, is the first one taken); every other call says ``None``.
    """
    original, calls = between.crossing_frequencies, []

    def only_the_first(*args):
        calls.append(1)
        return original(*args) if len(calls) == 1 else None

    monkeypatch.setattr(between, "crossing_frequencies", only_the_first)
    monkeypatch.setattr(between, "crossings_around", lambda *a: None)  # nor with the axis turned
    smooth = control.tf([1], [1, 1])
    ok = between.verify_between(smooth, mu_bounds(smooth, [[1, 1]], progress=False))
    assert ok.holds and ok.level >= 1.0 and "perturbation bounds" in ok.sentence()
    assert 0 < ok.by_radius < ok.intervals  # the interval up to infinity: the Hamiltonian's
    assert "Hamiltonian tests and perturbation bounds" in ok.sentence()
    assert len(calls) > 1 and ok.points_added > 1
    calls.clear()
    sharp = control.tf([1], [1, 0.02, 1])  # peak 50 near 1 rad/s, between the coarse points
    coarse = mu_bounds(sharp, [[1, 1]], [0.1, 0.5, 2.0, 10.0], refine_peak=False, progress=False)
    miss = between.verify_between(sharp, coarse, level=1.4)
    assert not miss.holds


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_series_radius_reaches_farther_on_a_slow_loop_with_spread_scalings_and_stays_sound(seed):
    """Scalings over four decades make the first-order bound's norm product large while the scaled ``M``
    moves little: the series kept to order 4 reaches farther from ω = 0, and the scaled test holds at every
    sampled frequency inside it (the module text's ur5 case, in small)."""
    rng = np.random.default_rng(seed)
    n, k = 6, 3
    A = rng.standard_normal((n, n))
    A -= (np.max(np.linalg.eigvals(A).real) + 0.05) * np.eye(n)  # a slow pole: ||R|| about 20
    B, C, D = rng.standard_normal((n, k)), rng.standard_normal((k, n)), 0.1 * rng.standard_normal((k, k))
    Dh = np.diag(10.0 ** np.array([-4.0, -2.0, 0.0]))
    Di = np.linalg.inv(Dh)
    loop = (A, B @ Di, Dh @ C, Dh @ D @ Di)
    level = 1.05 * max(_sigma(*loop, w) for w in np.linspace(0.0, 0.2, 400))
    first = covering_radius(*loop, np.zeros((k, k)), level, 0.0, order=0)
    series = covering_radius(*loop, np.zeros((k, k)), level, 0.0)
    assert series >= first > 0
    for w in np.linspace(0.0, series, 101):
        assert _sigma(*loop, w) < level
    assert series > 1.5 * first


def test_a_power_of_the_scalings_keeps_their_structure_and_is_what_the_test_reads():
    """``D^t`` and ``t G~`` (between.TEMPERED): block diagonal like ``D``, ``G`` zero on the complex block, and
    the normalised loop's ``Φ`` is the D-G test of those scalings, ``D^-t Φ D^-t``."""
    from polyrob.analysis.mu.blocks import as_block_structure

    st = as_block_structure([[-2, 0], [1, 1]])  # a repeated real of 2 and a complex scalar
    rng = np.random.default_rng(3)
    X = rng.standard_normal((2, 2)) + 1j * rng.standard_normal((2, 2))
    Dh = np.zeros((3, 3), complex)
    Dh[:2, :2] = X @ X.conj().T + 0.1 * np.eye(2)
    Dh[2, 2] = 40.0
    G = np.zeros((3, 3), complex)
    G[:2, :2] = [[0.3, 0.1 - 0.2j], [0.1 + 0.2j, -0.4]]
    A, B, C, D = -np.eye(3), rng.standard_normal((3, 3)), rng.standard_normal((3, 3)), rng.standard_normal((3, 3))
    An, Bn, Cn, Dn, P, Gt = between.normalised_loop(A, B, C, D, (Dh, G), 0.5)
    assert np.allclose(P, np.eye(3)) and np.allclose(Gt[2], 0) and np.allclose(Gt[:, 2], 0)
    half = Cn @ np.linalg.inv(C)  # D^t
    assert np.allclose(half[:2, 2], 0) and np.allclose(half[2, 2], np.sqrt(40.0))
    assert np.allclose(half @ half, Dh, atol=1e-9)
    w, level = 0.7, 3.0
    M = C @ np.linalg.solve(1j * w * np.eye(3) - A, B) + D
    Pt, Gs = half @ half, half @ Gt @ half
    Phi = M.conj().T @ Pt @ M + 1j * (Gs @ M - M.conj().T @ Gs) - level**2 * Pt
    Hi = np.linalg.inv(half)
    lam = np.linalg.eigvalsh(Hi @ Phi @ Hi)[-1]
    assert lam == pytest.approx(between._largest_eigenvalue(An, Bn, Cn, Dn, P, Gt, level, w), rel=1e-9, abs=1e-9)
    assert st.padded_size == 3


def test_where_an_ends_own_scalings_cannot_be_tested_their_powers_cover_the_interval(monkeypatch):
    """The Hamiltonian test made inapplicable (``None``, also with the axis turned) for the ends' own scalings
    and the radii switched off: the check still holds through the powers of the scalings (between.TEMPERED),
    and without them it gives up."""
    original_loop, original_crossings, last = between.normalised_loop, between.crossing_frequencies, []

    def loop(*args):
        last.append(args[-1] if len(args) > 5 else 1.0)
        return original_loop(*args)

    monkeypatch.setattr(between, "normalised_loop", loop)
    monkeypatch.setattr(between, "crossing_frequencies", lambda *a: None if last[-1] == 1.0 else original_crossings(*a))
    monkeypatch.setattr(between, "crossings_around", lambda *a: None)  # nor with the axis turned
    monkeypatch.setattr(between, "covering_radius", lambda *a: 0.0)
    smooth = control.tf([1], [1, 1])
    mu = mu_bounds(smooth, [[1, 1]], progress=False)
    ok = between.verify_between(smooth, mu, max_points=20)
    assert ok.holds and ok.by_radius == 0 and 0.5 in last
    monkeypatch.setattr(between, "TEMPERED", ())
    stuck = between.verify_between(smooth, mu, max_points=20)
    assert not stuck.holds and stuck.intervals == 0  # nothing covered
