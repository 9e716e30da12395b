"""μ below a level by branch and bound on the real scalars (:mod:`polyrob.analysis.mu.partition`)."""

import numpy as np
import pytest

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.analysis.mu.bounds import mussv
from polyrob.analysis.mu.gradient import GradientUpper
from polyrob.analysis.mu.partition import partition_mu
from polyrob.errors import ArgumentError

TWO_REPEATED = [[-2, 0], [-2, 0]]


def real_mu(M, reps, grid=401):
    """μ of a real matrix against repeated real scalars, by brute force: the largest real eigenvalue of ``M Δ`` on the box's faces.

    ``ρ_R(M Δ(t δ)) = t ρ_R(M Δ(δ))``, so the largest over the box is on its
    boundary, where some scalar is ``±1``.
    """
    k, best = len(reps), 0.0
    g = np.linspace(-1.0, 1.0, grid)
    mesh = np.stack(np.meshgrid(*([g] * (k - 1)), indexing="ij"), -1).reshape(-1, k - 1)
    for face in range(k):
        for side in (-1.0, 1.0):
            for rest in mesh:
                d = np.insert(rest, face, side)
                ev = np.linalg.eigvals(M * np.repeat(d, reps)[None, :])
                real = np.abs(ev[np.abs(ev.imag) < 1e-9].real)
                if real.size:
                    best = max(best, float(real.max()))
    return best


def test_partition_closes_the_dg_gap_of_repeated_real_scalars():
    st = as_block_structure(TWO_REPEATED)
    M = np.random.default_rng(21).standard_normal((4, 4))
    mu = real_mu(M, [2, 2])
    assert mu == pytest.approx(1.8526, abs=2e-3)
    dg = GradientUpper(st)(M + 0j)[0]
    assert dg > 1.3 * mu  # the D-G bound of the whole box is far above μ
    above = partition_mu(M + 0j, st, level=1.05 * mu)
    assert above.verdict == "proved" and above.proved_fraction == 1.0
    assert above.root_upper > 1.0 and above.worst_leaf < 1.0 and sum(above.splits) >= 1
    assert all(type(s) is int for s in above.splits)  # a JSON document takes them
    below = partition_mu(M + 0j, st, level=0.97 * mu)
    assert below.verdict == "member"
    # the member's cell centre lies in the box
    assert np.all(np.abs(below.member) <= 1.0)


@pytest.mark.parametrize("seed", range(8))
def test_partition_never_proves_below_mu_and_never_finds_a_member_above_it(seed):
    st = as_block_structure(TWO_REPEATED)
    M = np.random.default_rng(seed).standard_normal((4, 4))
    mu = real_mu(M, [2, 2], grid=201)
    for factor in (0.9, 1.1):
        res = partition_mu(M + 0j, st, level=factor * mu, max_cells=64)
        if factor < 1:
            assert res.verdict != "proved"
        else:
            assert res.verdict != "member"


def test_mixed_structure_agrees_with_mussv_bounds():
    """Real, complex and full blocks at a frequency: a proof never sits below μ's lower bound, a member never above its upper."""
    st = as_block_structure([[-2, 0], [1, 0], [2, 2]])
    rng = np.random.default_rng(5)
    for _ in range(4):
        M = rng.standard_normal((5, 5)) + 1j * rng.standard_normal((5, 5))
        bounds = mussv(M, st, method="gradient")
        for level in (0.95 * bounds.lower, 1.01 * bounds.upper):
            res = partition_mu(st.pad(M), st, level=level, max_cells=32)
            assert not (res.proved and level <= bounds.lower)
            assert not (res.verdict == "member" and level > bounds.upper)
        assert partition_mu(st.pad(M), st, level=1.01 * bounds.upper).proved  # the root's bound already proves it


def test_without_real_scalars_it_is_the_dg_bound():
    st = as_block_structure([[2, 2], [1, 1]])
    M = np.random.default_rng(2).standard_normal((3, 3)) + 0j
    dg = GradientUpper(st)(st.pad(M))[0]
    assert partition_mu(st.pad(M), st, level=1.001 * dg).proved
    res = partition_mu(st.pad(M), st, level=0.999 * dg)
    assert res.verdict == "unknown" and res.cells == 1


def test_bad_level_and_shape_are_refused():
    st = as_block_structure(TWO_REPEATED)
    with pytest.raises(ArgumentError, match="level"):
        partition_mu(np.eye(4), st, level=0.0)
    with pytest.raises(ArgumentError, match="max_cells"):
        partition_mu(np.eye(4), st, max_cells=0)
    with pytest.raises(ArgumentError, match="4 x 4"):
        partition_mu(np.eye(3), st)
