"""The μ upper bound between grid points (polyrob.analysis.mu.between)."""

from __future__ import annotations

from pathlib import Path

import control
import numpy as np
import pytest

from polyrob.analysis.mu.between import crossing_frequencies, crossings_around, verify_between
from polyrob.analysis.mu.bounds import mu_bounds


def test_crossing_of_a_gain_level_is_where_the_magnitude_meets_it():
    """Complex 1x1 block, P = 1, G = 0: Φ(ω) = |M(jω)|² - β², zero at |1/(jω + 1)| = 1/2, ω = √3."""
    A, B, C, D = np.array([[-1.0]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]])
    # Φ(∞) = -β² P is non-singular; the crossing is exact
    w = crossing_frequencies(A, B, C, D, np.eye(1), np.zeros((1, 1)), 0.5)
    assert w is not None and np.allclose(w, [np.sqrt(3.0)], rtol=1e-9)
    assert crossing_frequencies(A, B, C, D, np.eye(1), np.zeros((1, 1)), 1.5).size == 0


def test_with_the_axis_turned_the_crossings_are_the_loop_s_own_and_a_singular_phi_at_infinity_is_no_obstacle():
    """M = -0.9 + 1/(s + 1): |M(jω)|² = 0.81 - 0.8/(1 + ω²), so Φ = |M|² - β² crosses 0 at ω² = 0.8/(0.81 - β²) - 1.

    At β = 0.6 both tests find ω = sqrt(0.8/0.45 - 1) from any centre; at β = 0.9, Φ(∞) = 0: the plain test
    does not apply, and with the axis turned the only crossing is at infinity (Φ < 0 at every finite ω; rounding
    puts it at a finite but huge frequency).
    """
    A, B, C, D = np.array([[-1.0]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[-0.9]])
    P, G = np.eye(1), np.zeros((1, 1))
    exact = np.sqrt(0.8 / 0.45 - 1.0)
    assert np.allclose(crossing_frequencies(A, B, C, D, P, G, 0.6), [exact], rtol=1e-9)
    for centre in (0.0, 0.3, 2.0, 50.0):
        assert np.allclose(crossings_around(A, B, C, D, P, G, 0.6, centre), [exact], rtol=1e-8)
    assert crossing_frequencies(A, B, C, D, P, G, 0.9) is None
    for centre in (0.0, 0.3, 2.0):
        found = crossings_around(A, B, C, D, P, G, 0.9, centre)
        assert found is not None and np.all(found > 1e6)  # infinity, as near as rounding puts it


def test_the_turned_axis_covers_the_intervals_when_the_plain_test_never_applies(monkeypatch):
    """so101's cells at low frequency: scalings over many decades and a large feedthrough make Φ(∞) singular for
    every end, so the plain Hamiltonian test never runs; with the axis turned at each end the check holds
    without the perturbation radii or the scalings' powers, and without it nothing is covered."""
    import polyrob.analysis.mu.between as mb

    monkeypatch.setattr(mb, "crossing_frequencies", lambda *a: None)
    monkeypatch.setattr(mb, "covering_radius", lambda *a: 0.0)
    monkeypatch.setattr(mb, "TEMPERED", ())
    G = control.tf([1], [1, 0.02, 1])
    sweep = mu_bounds(G, [[1, 1]], progress=False)
    ok = verify_between(G, sweep, max_points=40)
    assert ok.holds and ok.by_radius == 0 and ok.level >= sweep.peak_upper
    monkeypatch.setattr(mb, "crossings_around", lambda *a: None)
    stuck = verify_between(G, sweep, max_points=40)
    assert not stuck.holds and stuck.intervals == 0


def test_a_resonance_the_grid_misses_is_found_and_a_fine_grid_is_verified():
    G = control.tf([1], [1, 0.02, 1])  # peak 1 / (2 ζ sqrt(1 - ζ²)) = 50.0025 at ω ≈ 1
    coarse = mu_bounds(G, [[1, 1]], [0.1, 0.5, 2.0, 10.0], refine_peak=False, progress=False)
    miss = verify_between(G, coarse, level=1.4)
    assert not miss.holds and miss.peak_upper > 1.4 and miss.failed_at is not None
    assert "rad/s" in miss.reason and "not verified" in miss.sentence()
    # without a level, the level rises to what lies between the points: the true peak
    found = verify_between(G, coarse)
    assert found.holds and 50.0025 <= found.level <= 50.0025 * (1 + 1.5e-2)
    assert found.points_added > 0
    fine = mu_bounds(G, [[1, 1]], progress=False)
    ok = verify_between(G, fine)
    assert ok.holds, ok.reason
    assert ok.level >= 50.0025 > 0.985 * ok.level  # the level is the true peak, 1 % above it
    assert "every frequency" in ok.sentence()


@pytest.mark.parametrize("seed", [0, 1])
def test_mixed_structure_level_bounds_a_dense_sweep(seed):
    """A random stable 4x4 system, blocks [real, real, complex 2x2]: a verified level bounds μ on a dense grid."""
    rng = np.random.default_rng(seed)
    sys = control.rss(6, 4, 4, strictly_proper=False)
    while np.max(np.linalg.eigvals(sys.A).real) > -0.05:
        sys = control.rss(6, 4, 4, strictly_proper=False)
    sys = control.ss(sys.A, sys.B, sys.C, 0.3 * rng.standard_normal((4, 4)))
    blk = [[-1, 0], [-1, 0], [2, 2]]
    sweep = mu_bounds(sys, blk, np.logspace(-2, 2, 12), refine_peak=False, progress=False)
    res = verify_between(sys, sweep, level=1.05 * sweep.peak_upper, max_points=400)
    dense = mu_bounds(sys, blk, np.logspace(-2.5, 2.5, 400), refine_peak=False, progress=False)
    if res.holds:
        assert dense.peak_upper <= res.level * (1 + 1e-6)
    else:  # the only way to fail: a point between the grid's with a larger bound
        assert res.failed_at is not None and res.peak_upper >= res.level
    assert res.peak_upper >= sweep.peak_upper


def test_unstable_system_is_not_verified():
    G = control.ss(control.tf([1], [1, -1]))
    sweep = mu_bounds(G, [[1, 1]], [0.1, 1.0, 10.0], refine_peak=False, progress=False)
    assert not verify_between(G, sweep).holds


def test_a_hamiltonian_that_misses_a_crossing_is_caught(monkeypatch):
    """If the eigenvalues hide a crossing (rounding on a badly scaled loop), the spot checks refute that interval:
    it is left to the perturbation radii, which do not reach across the resonance, and the peak is found."""
    import polyrob.analysis.mu.between as mb

    G = control.tf([1], [1, 0.02, 1])
    coarse = mu_bounds(G, [[1, 1]], [0.1, 0.5, 2.0, 10.0], refine_peak=False, progress=False)
    monkeypatch.setattr(mb, "crossing_frequencies", lambda *a, **k: np.zeros(0))
    res = mb.verify_between(G, coarse, level=1.4)
    assert not res.holds and res.refuted >= 1 and ">= 1.4" in res.reason
    assert 0.5 < res.failed_at < 2.0 and "left to the radii" in res.sentence()


def test_with_between_extends_a_certificate_and_skips_a_peak_above_one():
    from polyrob.analysis.mu.between import with_between

    below = control.tf([0.5], [1, 1])  # |M| <= 0.5
    sweep = with_between(below, mu_bounds(below, [[1, 1]], [0.1, 1.0, 10.0], refine_peak=False, progress=False))
    # the grid misses the peak 0.5 at ω = 0; the level (1 % above the grid peak 0.4975) still covers it
    assert sweep.between.holds and 0.5 <= sweep.upper_everywhere <= 0.5 * 1.011
    assert "every frequency" in sweep.covers
    above = control.tf([2.0], [1, 1])
    sweep = with_between(above, mu_bounds(above, [[1, 1]], [0.1, 1.0, 10.0], refine_peak=False, progress=False))
    assert not sweep.between.holds and "not below 1" in sweep.between.reason and sweep.upper_everywhere is None


def _slow_pole_loop(tiny: float = 0.0):
    """A 2x2 loop with a PID-like near-cancelled pole-zero pair at 1e-10 rad/s: flat from there to ~1e-4 rad/s.

    ``tiny`` puts ``tiny s / (s + 1e-6)`` in the (0, 1) entry, which is otherwise zero.
    """
    s = control.tf("s")
    lag = (s + 1.00000001e-10) / (s + 1e-10)
    rows = [[0.5 * lag / (s + 1), tiny * s / (s + 1e-6)], [0.1 + 0 * s, 0.3 / (s / 10 + 1)]]
    num = [[r.num[0][0] for r in row] for row in rows]
    den = [[r.den[0][0] for r in row] for row in rows]
    return control.ss(control.tf(num, den))


def test_flat_ends_are_thinned_to_a_point_per_decade_and_the_level_is_unchanged():
    from polyrob.analysis.mu.frequency import default_grid, thin_flat_ends

    M = _slow_pole_loop()
    full = default_grid(M, per_decade=12)
    thin = thin_flat_ends(M, full)
    assert np.all(np.isin(thin, full)) and thin[0] == full[0] and thin[-1] == full[-1]
    # below 1e-5 rad/s the response is flat to 1e-4 of each entry: about one point per decade is left there
    assert np.sum(thin < 1e-5) <= 8 < np.sum(full < 1e-5) // 8
    assert np.array_equal(thin[thin > 1e-3], full[full > 1e-3])  # where the loop moves, every point is kept
    blk = [[1, 1], [1, 1]]
    levels = []
    for grid in (full, thin):
        sweep = mu_bounds(M, blk, grid, progress=False)
        check = verify_between(M, sweep)
        assert check.holds, check.reason
        levels.append(check.level)
    assert levels[1] == pytest.approx(levels[0], rel=1e-6)


def test_a_small_entry_that_moves_keeps_its_points():
    """The flatness is judged per entry on its own scale: 1e-8 s/(s + 1e-6) is not flat near 1e-6 rad/s."""
    from polyrob.analysis.mu.frequency import default_grid, thin_flat_ends

    M = _slow_pole_loop(tiny=1e-8)
    full = default_grid(M, per_decade=12)
    thin = thin_flat_ends(M, full)
    near = (full > 1e-7) & (full < 1e-5)
    assert np.array_equal(thin[(thin > 1e-7) & (thin < 1e-5)], full[near])
    assert len(thin) < len(full)  # the decades below 1e-8 are still thinned


def test_a_certificate_on_its_default_grid_skips_the_flat_decades_and_proves_the_same_bound():
    from polyrob.analysis.certificate import POINTS_PER_DECADE, certify_loop
    from polyrob.analysis.mu.frequency import default_grid

    M = _slow_pole_loop()
    # P with P11 = M and no control channel used (K = 0): the closed loop is M itself
    A, B, C, D = (np.asarray(x) for x in control.ssdata(M))
    P = control.ss(A, np.hstack([B, np.zeros((A.shape[0], 1))]), np.vstack([C, np.zeros((1, A.shape[0]))]),
                   np.block([[D, np.zeros((2, 1))], [np.zeros((1, 3))]]))  # fmt: skip
    blk = [[1, 1], [1, 1]]
    full = default_grid(M, per_decade=POINTS_PER_DECADE)
    thinned = certify_loop(P, 0.0, blk, n_u=1, n_y=1)
    everywhere = certify_loop(P, 0.0, blk, full, n_u=1, n_y=1)
    assert thinned.certified and everywhere.certified
    assert len(thinned.mu.omega) < 0.6 * len(full) and thinned.default_grid
    assert thinned.bound == pytest.approx(everywhere.bound, rel=1e-9)


#: The closed loop of panda's PID start on its default task (`polyrob synth panda`: the per-joint PID tuned to
#: the weights, certified before any D-K step) and the μ sweep of its certificate, saved from that command
#: (``M``'s state space, the structure, the grid with its bounds and D-G scalings).
PANDA_PID_START = Path(__file__).parent / "fixtures" / "panda_pid_start_sweep.npz"


def _panda_pid_start():
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.results import MuBoundsResult

    z = np.load(PANDA_PID_START)
    M = control.ss(z["A"], z["B"], z["C"], z["D"])
    mu = MuBoundsResult(
        omega=z["omega"],
        upper=z["upper"],
        lower=z["lower"],
        D=z["Dscale"],
        G=z["Gscale"],
        peak_upper=float(z["peak_upper"]),
        peak_upper_frequency=float(z["peak_upper_frequency"]),
        peak_lower=float(z["peak_lower"]),
        critical_frequency=float(z["critical_frequency"]),
        worst_delta=z["worst_delta"],
        structure=as_block_structure(z["blk"].tolist()),
        method=str(z["method"]),
    )
    return M, mu


#: What the check found on that sweep under the normal clock (`polyrob synth panda --max-iter 1`, 245 s of it at
#: load 5-7 on a 2-core x86_64; the certificate: CERTIFIED, mu <= 0.9699 at every frequency, as README quotes).
PANDA_NORMAL_CLOCK = {"level": 0.969904759132365, "points_added": 14, "intervals": 152}


@pytest.mark.slow  # minutes on 2 cores; tests/test_time_limits.py covers the same behaviour fast (below)
@pytest.mark.timeout(3600)  # a hang guard only
def test_panda_pid_start_has_the_same_certificate_under_a_clock_1000x_faster(monkeypatch):
    """Before: the check between the grid points gave up after 120 s of wall clock, so `polyrob synth panda`'s
    PID start was CERTIFIED on an idle machine and GRID_ONLY (bound 0.9603, the grid's peak) at load 5-10.
    Here every second of work reads as 1000 s (a machine 1000 times as loaded): the same points, the same
    level as under the normal clock, CERTIFIED.

    Slow (the whole panda check between the grid points): the default run has the same behaviour on a
    small loop, tests/test_time_limits.py::test_the_check_between_grid_points_is_the_same_under_a_clock_1000x_faster
    (same points, level and intervals under the slowed clock) and ::test_no_give_up_that_decides_a_status_has_a_default_in_seconds
    (no default limit in seconds)."""
    from clocks import slowed_clock

    from polyrob.analysis.certificate import Status, certificate_of_sweep

    M, mu = _panda_pid_start()
    assert mu.peak_upper == pytest.approx(0.9603, abs=5e-5)
    slowed_clock(monkeypatch, 1000.0)
    loaded = certificate_of_sweep(M, mu)
    assert loaded.status is Status.CERTIFIED, loaded.reasons
    between = loaded.mu.between
    found = {"level": between.level, "points_added": between.points_added, "intervals": between.intervals}
    assert found == pytest.approx(PANDA_NORMAL_CLOCK, rel=1e-9)
    assert loaded.bound == pytest.approx(0.9699, abs=5e-5)
    assert between.seconds > 120.0  # as the loaded clock reads it: past the old limit of 120 s


def test_a_peak_just_below_one_is_checked_at_a_level_below_one():
    """A grid peak of 0.995 with the default 1 % margin would be checked at 1.005: μ <= 1.005 everywhere
    decides nothing.  The level between the peak and 1 is checked instead, and it holds (the true peak, at
    ω = 0, is 0.995), so the check's level certifies μ < 1 at every frequency; a true peak above 1 between the
    points still lifts the level over 1."""
    from polyrob.analysis.mu.between import LEVEL_MARGIN

    G = control.tf([0.995], [1, 1])
    sweep = mu_bounds(G, [[1, 1]], np.logspace(-3, 3, 30), refine_peak=False, progress=False)
    assert sweep.peak_upper < 1.0 <= sweep.peak_upper * (1.0 + LEVEL_MARGIN)
    r = verify_between(G, sweep)
    assert r.holds and sweep.peak_upper < r.level < 1.0
    resonant = 37.3125 * control.tf([0.02], [1, 0.02, 1])  # peak 37.3 at ω ≈ 1; the coarse grid sees 0.995 at 0.5
    coarse = mu_bounds(resonant, [[1, 1]], [0.1, 0.5, 2.0, 10.0], refine_peak=False, progress=False)
    assert coarse.peak_upper < 1.0 <= coarse.peak_upper * (1.0 + LEVEL_MARGIN)
    lifted = verify_between(resonant, coarse)
    assert lifted.holds and lifted.level > 30.0
