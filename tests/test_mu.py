"""Tests of polyrob.analysis.mu.bounds / polyrob.analysis.mu.blocks against published and exact values."""

import time

import control
import numpy as np
import pytest

import polyrob.analysis.mu.upper as mu_upper
from polyrob.analysis.mu.blocks import BlockStructure, as_block_structure
from polyrob.analysis.mu.bounds import mu_bounds, mussv
from polyrob.analysis.timelimit import TimeLimitedCall
from polyrob.errors import PolyrobError


# ------------------------------------------------------------------ data
def slicot_ab13md_example():
    """SLICOT AB13MD documentation example (AB13MD.dat, read row by row)."""
    Z = np.array(
        [
            [-1 + 6j, 2 - 3j, 3 + 8j, 3 + 8j, -5 - 9j, -6 + 2j],
            [4 + 2j, -2 + 5j, -6 - 7j, -4 + 11j, 8 - 7j, 12 - 1j],
            [5 - 4j, -4 - 8j, 1 - 3j, -6 + 14j, 2 - 5j, 4 + 16j],
            [-1 + 6j, 2 - 3j, 3 + 8j, 3 + 8j, -5 - 9j, -6 + 2j],
            [4 + 2j, -2 + 5j, -6 - 7j, -4 + 11j, 8 - 7j, 12 - 1j],
            [5 - 4j, -4 - 8j, 1 - 3j, -6 + 14j, 2 - 5j, 4 + 16j],
        ]
    )
    # nblock = [1, 1, 2, 1, 1], itype = [1, 1, 2, 2, 2] in MATLAB encoding
    blk = [[-1, 0], [-1, 0], [2, 2], [1, 1], [1, 1]]
    return Z, blk


def _crandn(rng, *shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def _check_delta(M, r, tol=1e-8):
    """The worst perturbation is structured, on the boundary, and singular."""
    st = r.structure
    assert st.contains(r.delta, tol=1e-9)
    if r.lower == 0:
        assert not np.any(r.delta)
        return
    assert np.linalg.norm(r.delta, 2) == pytest.approx(1 / r.lower, rel=1e-9)
    A = np.eye(M.shape[0]) - M @ r.delta
    assert np.linalg.svd(A, compute_uv=False)[-1] <= tol * np.linalg.norm(A, 2)


# ----------------------------------------------------------- structures
def test_block_structure_matlab_encoding_and_ab13md_mapping():
    _, blk = slicot_ab13md_example()
    st = as_block_structure(blk)
    assert [b.kind for b in st.blocks] == ["real", "real", "full", "complex", "complex"]
    nblock, itype = st.ab13md_args
    assert nblock.tolist() == [1, 1, 2, 1, 1]
    assert itype.tolist() == [1, 1, 2, 2, 2]
    assert st.m_shape == (6, 6)
    st2 = BlockStructure.from_matlab(np.array([[-3, 0], [2, 0], [2, 3]]))
    assert st2.delta_shape == (7, 8) and st2.has_repeated and st2.has_real
    assert str(st2) == "diag(R*I3, C*I2, C2x3)"
    with pytest.raises(PolyrobError):
        _ = st2.ab13md_args


@pytest.mark.parametrize("blk", [[[0, 0]], [[-2, 3]], [[1, -1]], [[1.5, 0]], [[1, 0, 0]], [], "abc", [[np.nan, 0]]])
def test_block_structure_rejects_bad_encodings(blk):
    with pytest.raises(PolyrobError):
        as_block_structure(blk)


def test_mussv_rejects_bad_input():
    with pytest.raises(PolyrobError):
        mussv(np.eye(3), [[1, 0], [1, 0]])  # wrong size
    with pytest.raises(PolyrobError):
        mussv(np.eye(2), [[2, 0]], method="ab13md")  # repeated scalar
    with pytest.raises(PolyrobError):
        mussv(np.eye(2), [[2, 2]], method="bogus")
    with pytest.raises(PolyrobError):
        mussv(np.array([[np.inf]]), [[1, 0]])


# -------------------------------------------------------- published values
def test_slicot_ab13md_documentation_example():
    Z, blk = slicot_ab13md_example()
    r = mussv(Z, blk)
    assert r.method == "ab13md"
    assert round(r.upper, 4) == 41.7475  # AB13MD.res: 0.4174753408e+02
    assert r.lower <= r.upper * (1 + 1e-12)
    assert r.lower > 0.99 * r.upper  # the power iteration finds the worst case
    assert r.lmi_residual(Z) < 1e-8  # D, G certify the upper bound
    _check_delta(Z, r)
    r_lmi = mussv(Z, blk, method="lmi")
    assert r_lmi.upper == pytest.approx(r.upper, rel=1e-3)
    assert r_lmi.upper >= r.upper * (1 - 1e-6)  # AB13MD's bound is optimal here
    assert r_lmi.lmi_residual(Z) < 1e-8


@pytest.mark.parametrize("method", ["ab13md", "lmi"])
def test_skogestad_postlethwaite_example_8_5(method):
    M = np.array([[2.0, 2.0], [-1.0, -1.0]])
    full = mussv(M, [[2, 2]], method=method)  # unstructured: sigma_max = sqrt(10)
    assert full.upper == pytest.approx(3.162, abs=5e-4)
    assert full.lower == pytest.approx(3.162, abs=5e-4)
    assert full.upper == pytest.approx(np.sqrt(10), rel=1e-4)
    diag = mussv(M, [[1, 0], [1, 0]], method=method)  # two complex scalars
    assert diag.upper == pytest.approx(3.000, abs=5e-4)
    assert diag.lower == pytest.approx(3.000, abs=5e-4)
    _check_delta(M, full)
    _check_delta(M, diag)


@pytest.mark.parametrize("seed, n", [(0, 3), (1, 4), (2, 5), (3, 6)])
def test_rank_one_complex_scalars_exact(seed, n):
    rng = np.random.default_rng(seed)
    a, b = _crandn(rng, n), _crandn(rng, n)
    M = np.outer(a, b.conj())
    exact = np.sum(np.abs(a * b))
    r = mussv(M, [[1, 0]] * n)
    assert r.upper == pytest.approx(exact, rel=1e-6)
    assert r.lower == pytest.approx(exact, rel=1e-6)
    _check_delta(M, r)


# --------------------------------------------------------------- real mu
def test_real_scalar_one_by_one():
    r = mussv(np.array([[-2.5]]), [[-1, 0]])
    assert r.upper == pytest.approx(2.5) and r.lower == pytest.approx(2.5)
    _check_delta(np.array([[-2.5]]), r)
    # a complex m admits no real destabilising delta: mu = 0
    m = np.array([[1.0 + 2.0j]])
    r = mussv(m, [[-1, 0]])
    assert r.upper == pytest.approx(0.0, abs=1e-12)
    assert r.lower == 0.0 and not np.any(r.delta)


@pytest.mark.parametrize("seed, n", [(0, 3), (1, 4), (2, 6)])
def test_rank_one_real_matrix_real_scalars_lower_bound_attained(seed, n):
    rng = np.random.default_rng(seed)
    a, b = rng.standard_normal(n), rng.standard_normal(n)
    M = np.outer(a, b)
    exact = np.sum(np.abs(a * b))
    r = mussv(M, [[-1, 0]] * n)
    assert r.upper >= exact * (1 - 1e-9)
    assert r.lower == pytest.approx(exact, rel=1e-9)
    assert np.all(np.isreal(r.delta))
    _check_delta(M, r)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_real_only_bounds_bracket(seed):
    rng = np.random.default_rng(seed)
    M = _crandn(rng, 4, 4)
    r = mussv(M, [[-1, 0]] * 4)
    assert 0 <= r.lower <= r.upper
    assert r.lmi_residual(M) < 1e-8
    _check_delta(M, r)


# ------------------------------------------------------- repeated scalars
def test_repeated_complex_scalar_gives_spectral_radius():
    r = mussv((2 - 1j) * np.eye(3), [[3, 0]])
    assert r.method == "gradient"  # "auto" on a repeated scalar: descent on the D-G scalings
    assert r.upper == pytest.approx(abs(2 - 1j), rel=1e-4)
    assert r.lower == pytest.approx(abs(2 - 1j), rel=1e-9)
    rng = np.random.default_rng(4)
    M = _crandn(rng, 4, 4)
    rho = np.max(np.abs(np.linalg.eigvals(M)))
    r = mussv(M, [[4, 0]])
    assert r.lower == pytest.approx(rho, rel=1e-9)
    assert r.upper == pytest.approx(rho, rel=1e-3)
    _check_delta(M, r)


def test_repeated_real_and_complex_mixed():
    rng = np.random.default_rng(5)
    M = _crandn(rng, 5, 5)
    r = mussv(M, [[2, 0], [-2, 0], [1, 0]])
    assert 0 < r.lower <= r.upper
    assert r.lower > 0.9 * r.upper
    assert r.lmi_residual(M) < 1e-7
    _check_delta(M, r)


# ----------------------------------------------------- general properties
MIXED = [
    [[-1, 0], [-1, 0], [-1, 0], [1, 0], [1, 0], [3, 3]],
    [[-1, 0], [2, 2], [1, 1], [1, 2]],
    [[1, 0]] * 4 + [[2, 2], [2, 2]],
]


@pytest.mark.parametrize("blk", MIXED)
@pytest.mark.parametrize("seed", [0, 1])
def test_bounds_ordered_and_certified(blk, seed):
    st = as_block_structure(blk)
    rng = np.random.default_rng(seed)
    M = _crandn(rng, *st.m_shape)
    r = mussv(M, st)
    assert 0 < r.lower <= r.upper
    assert r.lower >= 0.9 * r.upper  # typical gap on random problems is < 3 %
    assert r.lmi_residual(M) < 1e-8
    if st.is_complex:
        # classic D-scaling certificate: sigma_max(Dl M Dr^-1) = upper bound
        s = np.linalg.norm(r.Dl @ M @ np.linalg.inv(r.Dr), 2)
        assert s == pytest.approx(r.upper, rel=1e-6)
    _check_delta(M, r)


@pytest.mark.parametrize("blk", MIXED[:2])
def test_ab13md_and_lmi_agree(blk):
    st = as_block_structure(blk)
    M = _crandn(np.random.default_rng(7), *st.m_shape)
    a = mussv(M, st, method="ab13md", lower=False)
    b = mussv(M, st, method="lmi", lower=False)
    assert b.upper == pytest.approx(a.upper, rel=1e-3)


def test_non_square_full_block_padding():
    rng = np.random.default_rng(8)
    M = _crandn(rng, 5, 3)  # Delta: diag(1x2, 2x3) is 3x5
    r = mussv(M, [[1, 2], [2, 3]])
    assert r.delta.shape == (3, 5)
    assert r.upper == pytest.approx(r.lower, rel=1e-6)
    _check_delta(M, r)
    # one full block = maximum singular value
    r = mussv(M, [[3, 5]])
    assert r.upper == pytest.approx(np.linalg.norm(M, 2), rel=1e-9)
    assert r.lower == pytest.approx(np.linalg.norm(M, 2), rel=1e-9)


def test_zero_matrix():
    r = mussv(np.zeros((3, 3)), [[-1, 0], [2, 2]])
    assert r.upper == 0.0 and r.lower == 0.0


# ------------------------------------------------------------ mu_bounds
def test_mu_bounds_finds_sharp_resonance_peak():
    zeta, wn = 0.002, 3.0
    G = control.tf([wn**2], [1, 2 * zeta * wn, wn**2])
    r = mu_bounds(G, [[1, 1]])
    hinf, wpeak = control.linfnorm(G)
    assert r.peak_upper == pytest.approx(hinf, rel=1e-4)
    assert r.peak_lower == pytest.approx(hinf, rel=1e-4)
    assert r.peak_upper_frequency == pytest.approx(wpeak, rel=1e-4)
    Mc = G(1j * r.critical_frequency).reshape(1, 1)
    assert abs(1 - Mc[0, 0] * r.worst_delta[0, 0]) < 1e-8
    assert abs(r.worst_delta[0, 0]) == pytest.approx(1 / r.peak_lower)
    assert np.all(r.upper >= r.lower) and np.all(np.diff(r.omega) > 0)


def test_mu_bounds_mimo_full_block_is_hinf_norm():
    sys = control.ss(
        [[-0.1, 2.0, 0.0], [-2.0, -0.1, 0.0], [0.0, 0.0, -1.0]],
        [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
        [[1.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
        [[0.0, 0.1], [0.0, 0.0]],
    )
    r = mu_bounds(sys, [[2, 2]])
    hinf, _ = control.linfnorm(sys)
    assert r.peak_upper == pytest.approx(hinf, rel=1e-4)
    assert r.peak_lower == pytest.approx(hinf, rel=1e-4)
    M = sys(1j * r.critical_frequency)
    A = np.eye(2) - M @ r.worst_delta
    assert np.linalg.svd(A, compute_uv=False)[-1] < 1e-8
    assert r.D.shape == (r.omega.size, 2, 2)


def test_mu_bounds_mixed_structure_and_frd():
    rng = np.random.default_rng(0)
    sys = control.ss(
        -np.diag([0.5, 1.0, 2.0, 4.0]) + 0.3 * rng.standard_normal((4, 4)),
        rng.standard_normal((4, 3)),
        rng.standard_normal((3, 4)),
        np.zeros((3, 3)),
    )
    blk = [[-1, 0], [1, 0], [1, 0]]
    r = mu_bounds(sys, blk)
    assert r.peak_lower <= r.peak_upper and r.peak_lower > 0.8 * r.peak_upper
    st = as_block_structure(blk)
    assert st.contains(r.worst_delta)
    frd = control.frd(sys, np.logspace(-2, 2, 60))
    rf = mu_bounds(frd, blk)
    assert rf.omega.size == 60
    assert rf.peak_upper <= r.peak_upper * (1 + 1e-6)
    with pytest.raises(PolyrobError):
        mu_bounds(sys, [[1, 0], [1, 0]])  # 2x2 structure, 3x3 system


def test_mu_bounds_discrete_time_and_lmi_method():
    Gd = control.c2d(control.tf([1], [1, 0.1, 1]), 0.1)
    r = mu_bounds(Gd, [[1, 0]])
    hinf, wpeak = control.linfnorm(Gd)
    assert r.peak_upper == pytest.approx(hinf, rel=1e-4)
    assert r.peak_upper_frequency == pytest.approx(wpeak, rel=1e-4)
    assert r.omega.max() < np.pi / 0.1
    G = control.tf([[[1.0], [0.5]], [[-0.3], [2.0]]], [[[1, 0.4, 1], [1, 1]], [[1, 2], [1, 0.6, 4]]])
    blk = [[1, 0], [1, 0]]
    a = mu_bounds(G, blk, np.logspace(-1, 1, 25), method="lmi", refine_peak=False)
    b = mu_bounds(G, blk, np.logspace(-1, 1, 25), refine_peak=False)
    assert a.method == "lmi" and b.method == "ab13md"
    np.testing.assert_allclose(a.upper, b.upper, rtol=1e-3)


def test_mu_bounds_pole_on_the_grid_is_infinite():
    r = mu_bounds(control.tf([1], [1, 0, 1]), [[1, 0]])
    assert r.peak_upper == np.inf and r.peak_upper_frequency == pytest.approx(1.0)


# ------------------------------------------------------ warm-start guard
def _hang_on_warm_start(Z, nblock, itype, x=None):
    """Stand-in for AB13MD whose warm starts hang like the real one can."""
    if x is not None:
        time.sleep(600)
    import slycot

    return slycot.ab13md(Z, nblock, itype)


@pytest.mark.timeout(300)  # a hang guard: the call sleeps 600 s unless the guard kills it
def test_time_limited_call_kills_a_hanging_call():
    call = TimeLimitedCall(time.sleep, timeout=0.3)
    try:
        ok, why = call(600)
        assert not ok and why == "timeout"
        assert call._proc is None  # the hung worker was killed
    finally:
        call.close()


@pytest.mark.timeout(300)  # a hang guard: a hung warm start sleeps 600 s unless the guard falls back
def test_warm_start_guard_falls_back_to_cold_calls(monkeypatch):
    G = control.tf([[[1.0], [2.0]], [[0.5], [1.0, 1.0]]], [[[1, 0.3, 1], [1, 2]], [[1, 5], [1, 1, 4]]])
    blk = [[-1, 0], [1, 0]]
    omega = np.logspace(-1, 1, 8)
    cold = mu_bounds(G, blk, omega, refine_peak=False)
    # the stand-in really works cold and really hangs warm in the worker
    Z, nb_it = np.eye(2, dtype=complex), as_block_structure(blk).ab13md_args
    with TimeLimitedCall(_hang_on_warm_start, timeout=0.5) as call:
        ok, (bound, _, _, x) = call(Z, *nb_it)
        assert ok and bound == pytest.approx(1.0)
        assert call(Z, *nb_it, x) == (False, "timeout")
    monkeypatch.setattr(mu_upper, "ab13md_call", _hang_on_warm_start)
    warm = mu_bounds(G, blk, omega, refine_peak=False, warm_start=True, warm_timeout=0.5)
    assert warm.warm_start_fallbacks == 1  # hung once, then cold for the rest
    assert len(warm.notes) == 1 and "timeout" in warm.notes[0] and cold.notes == ()  # recorded, not silent
    np.testing.assert_allclose(warm.upper, cold.upper, rtol=1e-9)


def test_covers_names_the_grid_and_extended_precision_response():
    G = control.tf([1], [1, 0.2, 1])
    omega = np.logspace(-1, 1, 21)
    r = mu_bounds(control.ss(G), [[1, 1]], omega, refine_peak=False)
    assert r.covers.startswith("peak mu on a grid of 21 frequencies in [0.1, 10] rad/s")
    # 212-bit responses of a well-conditioned system agree with double precision
    re = mu_bounds(control.ss(G), [[1, 1]], omega, refine_peak=False, response_bits=212)
    np.testing.assert_allclose(re.upper, r.upper, rtol=1e-12)
    assert re.notes == ("frequency responses evaluated at 212 bits",)
    # |G(j omega)| analytic at the grid points: the "peak on the grid" is the grid maximum,
    # below the true peak 1/(2 zeta sqrt(1 - zeta^2)) = 5.0252 that lies between grid points
    mag = 1 / np.abs(1 - omega**2 + 0.2j * omega)
    assert r.peak_upper == pytest.approx(mag.max(), rel=1e-9) and r.peak_upper < 5.0252 - 0.02


def test_skogestad_distillation_column_robust_performance():
    """SP06 section 8.12: mu_RP of the inverse-based controller is about 5.77
    (the problem dkpy ships as example_skogestad2006_p325)."""
    from polyrob.examples import distillation_rp_response

    N = distillation_rp_response(np.logspace(-3, 3, 61))
    res = mu_bounds(N, [[1, 1], [1, 1], [2, 2]], progress=False)
    assert res.peak_upper == pytest.approx(5.77, abs=0.01)
    assert res.peak_lower == pytest.approx(res.peak_upper, rel=1e-3)


def test_relaxed_repeated_scalars_bound_mu_from_above():
    """Repeated scalars split into independent ones (a superset) give an upper bound by AB13MD."""
    import numpy as np

    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.sweep import DESCENT_ABOVE

    rng = np.random.default_rng(5)
    M = rng.normal(size=(4, 4)) + 1j * rng.normal(size=(4, 4))
    blk = [[-2, 0], [2, 0]]  # a repeated real and a repeated complex scalar
    exact = mussv(M, blk, method="lmi")
    relaxed = mussv(M, blk, method="relaxed")
    assert relaxed.upper >= exact.upper * (1 - 1e-6)  # a superset can only raise the bound
    assert relaxed.upper >= exact.lower and "relaxed structure" in relaxed.notes[0]
    # and it is a true bound of that superset: no larger than its unstructured norm
    assert relaxed.upper <= np.linalg.norm(M, 2) * (1 + 1e-9)
    # method="auto": descent on the scalings, the LMI's bound (tests/test_mu_gradient.py checks its values)
    auto = mussv(M, blk, lower=False)
    assert auto.method == "gradient" and auto.upper == pytest.approx(exact.upper, rel=1e-3)
    n_big = DESCENT_ABOVE // 3 + 1
    big = mussv(rng.normal(size=(3 * n_big, 3 * n_big)), [[-3, 0]] * n_big, lower=False)
    assert big.method == "gradient" and not big.notes


def test_a_lower_bound_whose_svd_does_not_converge_falls_back_and_stays_a_lower_bound(monkeypatch):
    """LAPACK's SVD can give up on a matrix scaled over hundreds of decades (panda's per-link loop): the search
    then starts from the unscaled matrix, and where that fails too the lower bound is 0, never a crash."""
    import polyrob.analysis.mu.lower as lower

    rng = np.random.default_rng(4)
    M = rng.standard_normal((4, 4)) + 1j * rng.standard_normal((4, 4))
    st = as_block_structure([[1, 1], [1, 1], [2, 2]])
    plain = lower.lower_bound(M, st, D=np.eye(4))[0]
    real_svd, calls = np.linalg.svd, []

    def failing(limit):
        def svd(*args, **kwargs):
            calls.append(1)
            if len(calls) <= limit:
                raise np.linalg.LinAlgError("SVD did not converge")
            return real_svd(*args, **kwargs)

        return svd

    monkeypatch.setattr(lower.np.linalg, "svd", failing(1))
    once = lower.lower_bound(M, st, D=np.diag([1e150, 1.0, 1.0, 1.0]))[0]
    assert once == pytest.approx(plain, rel=1e-6) and once <= mussv(M, st).upper * (1 + 1e-9)
    calls.clear()
    monkeypatch.setattr(lower.np.linalg, "svd", failing(2))
    lo, delta, _ = lower.lower_bound(M, st)
    assert lo == 0.0 and not np.any(delta)


def test_a_candidate_whose_check_overflows_is_not_verified_and_never_a_crash():
    """`analyze ur5` on proved factor ranges crashed: a candidate perturbation of 1e300 made ``I - M Delta``
    overflow, and the SVD that verifies ``det = 0`` raised.  Such a candidate is now not verified (the lower
    bound rests only on a singular matrix that was checked); a true one still is."""
    import polyrob.analysis.mu.lower as lower

    M = np.array([[0.5, 0.0], [0.0, 0.25]], complex)
    assert lower._singular(M, np.diag([2.0, 0.0]).astype(complex))  # det(I - M Delta) = 0
    assert not lower._singular(M, np.diag([1.0, 0.0]).astype(complex))
    assert not lower._singular(M, np.diag([np.inf, 1.0]).astype(complex))  # inf, nan: not verified
    assert not lower._singular(np.full((2, 2), 1e300, complex), np.full((2, 2), 1e300, complex))
