"""The D-G upper bound of μ by descent on the scalings (polyrob.analysis.mu.gradient)."""

import numpy as np
import pytest
from scipy import optimize

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.bounds import mu_bounds, mussv
from polyrob.analysis.mu.gradient import GradientUpper
from polyrob.analysis.mu.upper import certified_beta

MIXED = [[-3, 0], [2, 0], [-1, 0], [1, 2], [-2, 0]]


def _random(st, rng):
    return rng.standard_normal(st.m_shape) + 1j * rng.standard_normal(st.m_shape)


@pytest.mark.parametrize(
    "blk, hermitian",
    [(MIXED, ()), (MIXED + [[3, 3], [-2, 0], [1, 1], [-1, 0]], (5,))],
    ids=["mixed", "with-hermitian-and-repeated-blocks-of-one-size"],
)
def test_the_gradient_of_the_smoothed_bound_matches_finite_differences(blk, hermitian):
    """Every parameter's derivative, read by index arrays from whole products (full ``T`` blocks of one size inverted
    together, scalar blocks' traces summed per block, a Hermitian block's ``G``), against finite differences."""
    rng = np.random.default_rng(1)
    st = as_block_structure(blk)
    gu = GradientUpper(st, hermitian=hermitian)
    Ms = st.pad(_random(st, rng))
    x = gu.initial(Ms) + 0.1 * rng.standard_normal(gu.size)
    f, g = gu._objective(x, Ms, 0.1)
    err = optimize.check_grad(lambda y: gu._objective(y, Ms, 0.1)[0], lambda y: gu._objective(y, Ms, 0.1)[1], x)
    assert err < 1e-4 * np.linalg.norm(g)


def test_the_scalings_are_block_diagonal_with_the_parameters_in_their_blocks():
    """``P = T^* T`` and ``G`` assembled by index arrays: zero off the blocks, each block from its own parameters."""
    rng = np.random.default_rng(3)
    st = as_block_structure(MIXED + [[3, 3], [-2, 0]])
    gu = GradientUpper(st, hermitian=(5,))
    x = rng.standard_normal(gu.size)
    P, G = gu.scalings(x)
    T, Ti, Gt = gu._unpack(x)
    assert np.allclose(T @ Ti, np.eye(st.padded_size), atol=1e-10)
    for sl, n, full_t, st_t, st_g in gu._layout:
        v = x[st_t]
        Tb = (v[: n * n] + 1j * v[n * n :]).reshape(n, n) if full_t else np.exp(v[0]) * np.eye(n)
        assert np.allclose(P[sl, sl], Tb.conj().T @ Tb)
        off = np.ones(st.padded_size, bool)
        off[sl] = False
        assert not np.any(P[sl][:, off]) and not np.any(G[sl][:, off])
        if st_g.stop == st_g.start:
            assert not np.any(G[sl, sl])
        else:
            assert np.allclose(Gt[sl, sl], Gt[sl, sl].conj().T)  # G~ Hermitian on the block


@pytest.mark.parametrize("seed", range(4))
def test_descent_reaches_the_lmi_optimum_and_its_scalings_certify_it(seed):
    """The LMI (convex, solved by an interior-point method) is the reference; descent must come within 1 %."""
    rng = np.random.default_rng(seed)
    st = as_block_structure(MIXED)
    M = _random(st, rng)
    lmi = mussv(M, st, method="lmi")
    beta, D, G, _ = GradientUpper(st)(st.pad(M))
    assert lmi.lower * (1 - 1e-9) <= beta <= lmi.upper * 1.01
    # the returned scalings certify the returned value (a generalized eigenvalue, no optimiser involved)
    assert certified_beta(st.pad(M), D @ D, G)[0] == pytest.approx(beta, rel=1e-6)


def test_scalings_many_orders_apart_certify_what_they_prove():
    """``M = [[0, 1e8], [1e-8, 0]]`` against two complex scalars has μ = 1, reached by ``D = diag(1e-8, 1)``: its
    ``P = D^2`` is 1e16 times ill-conditioned but definite, and the bound re-derived from it is 1 (it was 3162 when a
    conditioning test took such a ``P`` for a barely definite one and shifted it); the descent reaches it too."""
    M = np.array([[0.0, 1e8], [1e-8, 0.0]], complex)
    zero = np.zeros((2, 2), complex)
    assert certified_beta(M, np.diag([1e-16, 1.0]).astype(complex), zero)[0] == pytest.approx(1.0, rel=1e-9)
    assert certified_beta(M, np.diag([1e-12, 1.0]).astype(complex), zero)[0] == pytest.approx(100.0, rel=1e-9)
    st = as_block_structure([[1, 0], [1, 0]])
    assert GradientUpper(st)(st.pad(M))[0] == pytest.approx(1.0, rel=1e-6)
    # a P that is barely definite in every coordinate is still shifted (an SDP solver's noise): never below μ
    assert certified_beta(M, np.diag([1.0, 1.0]).astype(complex) * 1e-30 + np.diag([0.0, 1.0]), zero)[0] >= 1.0


def test_a_repeated_real_scalar_with_real_eigenvalues_gives_the_real_spectral_radius():
    """μ against δ I is max |real eigenvalue|; with real eigenvalues a full D reaches it."""
    rng = np.random.default_rng(3)
    V = rng.standard_normal((5, 5))
    M = V @ np.diag([0.3, -2.5, 1.0, 0.7, -0.1]) @ np.linalg.inv(V)
    beta = GradientUpper(as_block_structure([[-5, 0]]))(M.astype(complex))[0]
    assert beta == pytest.approx(2.5, rel=1e-3)
    assert beta >= 2.5 * (1 - 1e-9)  # an upper bound never falls below mu


def test_a_large_sweep_uses_descent_warm_started_and_stays_above_the_lower_bound():
    """An 8-block structure of 41 padded channels: method="auto" takes the descent route."""
    import control

    from polyrob.analysis.mu.frequency import freqresp

    blk = [[-4, 0]] * 8 + [[3, 6]]
    st = as_block_structure(blk)
    np.random.seed(7)  # control.rss draws from numpy's global generator
    sys = control.rss(6, st.m_shape[0], st.m_shape[1], strictly_proper=False)
    sys = control.ss(sys.A - 0.5 * np.eye(6) * (np.abs(np.linalg.eigvals(sys.A)).max() + 1), sys.B, sys.C, sys.D)
    omega = np.logspace(-1, 1, 6)
    res = mu_bounds(sys, st, omega, refine_peak=False, progress=False)
    assert res.method == "gradient"
    assert np.all(res.upper >= res.lower)
    # each frequency's bound is the one its own scalings certify
    H = st.pad(freqresp(sys, res.omega))
    for k in range(res.omega.size):
        assert certified_beta(H[k], res.D[k] @ res.D[k], res.G[k])[0] <= res.upper[k] * (1 + 1e-6)


def _hermitian_destabiliser(M, rng, tries=300):
    """The smallest Hermitian ``Delta`` found with ``I - M Delta`` singular: ``Delta M w = w`` with ``(M w)^* w`` real.

    A Hermitian ``Delta`` maps ``a = M w`` to ``b = w`` only if ``a^* b`` is real; then
    ``Delta = (b a^* + a b^*)/|a|^2 - (a^* b) a a^*/|a|^4`` does, and ``M Delta a = a``.
    """
    K = (M - M.conj().T) / 2j  # w^* M^* w is real exactly when w^* K w = 0
    best = np.inf
    for _ in range(tries):
        u, v = (rng.standard_normal(len(M)) + 1j * rng.standard_normal(len(M)) for _ in range(2))
        ku, kv, kuv = (u.conj() @ K @ u).real, (v.conj() @ K @ v).real, (u.conj() @ K @ v).real
        if ku * kv >= 0:
            continue
        s = (-kuv + np.sqrt(kuv**2 - ku * kv)) / kv  # (u + s v)^* K (u + s v) = 0, s real
        w = u + s * v
        a, b = M @ w, w
        r = (a.conj() @ b).real
        D = (np.outer(b, a.conj()) + np.outer(a, b.conj())) / (a.conj() @ a).real - r * np.outer(a, a.conj()) / (
            a.conj() @ a
        ).real ** 2
        assert abs(np.linalg.det(np.eye(len(M)) - M @ D)) < 1e-8 * max(1.0, np.linalg.norm(M @ D, 2)) ** len(M)
        best = min(best, np.linalg.norm(D, 2))
    assert np.isfinite(best), "no direction w with a real (M w)^* w was found"
    return best


def test_a_hermitian_block_s_bound_lies_between_its_hermitian_destabilisers_and_the_complex_bound():
    """A full block whose members are Hermitian takes a G-scaling too: a smaller bound, still above every Hermitian Delta."""
    rng = np.random.default_rng(3)
    one = as_block_structure([[3, 3]])
    for _ in range(3):
        M = rng.standard_normal((3, 3)) + 1j * rng.standard_normal((3, 3))
        complex_bound = GradientUpper(one)(M)[0]
        hermitian_bound, D, G, _ = GradientUpper(one, hermitian=[0])(M)
        lower = 1.0 / _hermitian_destabiliser(M, rng)
        assert lower <= hermitian_bound * (1 + 1e-9)
        assert hermitian_bound < complex_bound
        assert certified_beta(M, D @ D, G)[0] == pytest.approx(hermitian_bound, rel=1e-6)
    # with other blocks beside it the bound still holds its own scalings, and never exceeds the complex block's
    st = as_block_structure([[3, 3], [-1, 0], [1, 2]])
    M = st.pad(_random(st, rng))
    hermitian_bound, D, G, _ = GradientUpper(st, hermitian=[0])(M)
    assert hermitian_bound <= GradientUpper(st)(M)[0] * (1 + 1e-6)
    assert certified_beta(M, D @ D, G)[0] == pytest.approx(hermitian_bound, rel=1e-6)
    # a Hermitian M: its spectral radius is reached by a Hermitian Delta, so the G-scaling cannot go below it
    H = rng.standard_normal((3, 3))
    H = H + H.T
    assert GradientUpper(one, hermitian=[0])(H.astype(complex))[0] == pytest.approx(
        np.abs(np.linalg.eigvalsh(H)).max(), rel=1e-3
    )


def test_only_square_full_blocks_can_be_hermitian():
    from polyrob.errors import ArgumentError

    with pytest.raises(ArgumentError, match="not a square full block"):
        GradientUpper(as_block_structure([[-2, 0], [1, 2]]), hermitian=[1])


def test_the_descent_counts_its_evaluations(monkeypatch):
    """``evaluations``: one per evaluation of the smoothed bound and its gradient (what a benchmark divides by)."""
    rng = np.random.default_rng(4)
    st = as_block_structure(MIXED)
    gu = GradientUpper(st, maxiter=20)
    raw, seen = gu._objective_raw, []
    monkeypatch.setattr(gu, "_objective_raw", lambda *a: seen.append(1) or raw(*a))
    assert gu.evaluations == 0
    Ms = st.pad(_random(st, rng))
    x = gu(Ms)[3]
    first = gu.evaluations
    gu(Ms, x)
    assert 0 < first < gu.evaluations == len(seen)
