"""The ``inertia`` uncertainty model (polyrob.plant.models.inertia_plant, inertia_factors): M stays positive definite.

The six- and seven-joint arms are bounded quickly here (few samples, no
refinement): the properties tested (definiteness of every member, the exact
inverse, the axes model's indefinite members) do not depend on how tight
the PLDI is.  Coverage on fresh samples, which does, is tested on the
paper's arm and on the inertia factors of ur5 and panda.
"""

import dataclasses

import numpy as np
import pytest
from conftest import cached_robot

from polyrob._threads import single_blas_thread
from polyrob.bounds.pldi import bound_pldi
from polyrob.domains.torque_box import Domain
from polyrob.plant.coverage import coverage_fraction, input_definiteness
from polyrob.plant.models import MODELS, model_of
from polyrob.plant.models.inertia_factors import factor_ranges, ldl
from polyrob.plant.uncertainty import uncertain_plant, upper_lft

QUICK = {
    "samples": 64,
    "screen": 0,
    "refine": False,
    "verify_rounds": 0,
    "coverage": 0,
    "progress": False,
    "workers": 1,
}


@pytest.fixture(scope="module", autouse=True)
def _one_blas_thread():
    """Many small matrices: a threaded BLAS on the shared 2-core machine only spin-waits (50x slower)."""
    with single_blas_thread():
        yield


def _inertias(robot, n, seed):
    q, _, _ = Domain.from_robot(robot).sample(n, method="uniform", seed=seed)
    return np.array([robot.mass_matrix(x) for x in q])


@pytest.fixture(scope="module", params=["ur5", "panda"])
def factors(request):
    robot = cached_robot(request.param)
    return robot, factor_ranges(robot, Domain.from_robot(robot), samples=1000, verify=1000)


@pytest.fixture(scope="module")
def ur5():
    """ur5's PLDI (quick), its inertia model (12 directions for N) and its axes model."""
    robot = cached_robot("ur5")
    pldi = bound_pldi(robot, **QUICK)
    inertia = MODELS["inertia"].build(
        pldi, robot=robot, n_directions=12, bound_options=QUICK, factor_options={"samples": 1000, "verify": 1000}
    )
    axes = uncertain_plant(pldi, model="axes", n_directions=12, coverage=0, volume_samples=0)
    return robot, pldi, inertia, axes


@pytest.fixture(scope="module")
def paper(pldi):
    return uncertain_plant(pldi, model="inertia", coverage=3000, volume_samples=0)


def _shrunk(unc, factor):
    """The inertia model with its factor ranges and its N model's ranges (and residual) scaled by ``factor``."""
    sub = unc.info["N_plant"]
    W_l = sub.info["W_l"]
    sub = dataclasses.replace(
        sub, info=dict(sub.info, z_rad=factor * sub.info["z_rad"], W_l=None if W_l is None else factor * W_l)
    )
    return dataclasses.replace(unc, info=dict(unc.info, factors=unc.info["factors"].scaled(factor), N_plant=sub))


def test_every_member_inertia_is_positive_definite(factors):
    robot, f = factors
    # the structure: D > 0 on its whole range, L unit lower triangular
    assert f.d_lower.min() > 0
    rng = np.random.default_rng(0)
    k = len(f.index)
    deltas = np.vstack([rng.choice([-1.0, 1.0], size=(3000, k)), rng.uniform(-1, 1, size=(1000, k))])
    M = np.array([f.matrix(d) for d in deltas])
    np.testing.assert_allclose(M, np.swapaxes(M, 1, 2), atol=1e-14)
    assert np.linalg.eigvalsh(M)[:, 0].min() > 0
    assert np.linalg.eigvalsh(np.linalg.inv(M))[:, 0].min() > 0


def test_a_principal_axes_box_on_m_itself_is_indefinite(factors):
    """What issue 21 proposed first: the box on the principal directions of vech M(q) has indefinite corners."""
    robot, _ = factors
    Ms = _inertias(robot, 2000, 1)
    m = robot.m
    iu = np.triu_indices(m)
    V = Ms[:, iu[0], iu[1]]
    c = V.mean(axis=0)
    _, s, Vt = np.linalg.svd(V - c, full_matrices=False)
    basis = Vt[s > 1e-9 * s[0]]
    z = (V - c) @ basis.T
    corners = np.where(np.random.default_rng(0).random((2000, len(basis))) < 0.5, z.min(axis=0), z.max(axis=0))
    P = np.zeros((len(corners), m, m))
    P[:, iu[0], iu[1]] = c + corners @ basis
    P = P + np.triu(P, 1).swapaxes(1, 2)
    assert np.linalg.eigvalsh(Ms)[:, 0].min() > 0
    assert (np.linalg.eigvalsh(P)[:, 0] <= 0).mean() > 0.5


def test_factor_ranges_cover_fresh_inertias_and_shrinking_fails(factors):
    robot, f = factors
    Ms = _inertias(robot, 3000, 777)
    assert f.locate(Ms)[0].all()
    assert f.scaled(0.97).locate(Ms)[0].mean() < 0.99


def test_ldl_reproduces_the_matrix():
    A = np.random.default_rng(2).standard_normal((5, 4, 4))
    M = A @ A.swapaxes(1, 2) + 4 * np.eye(4)
    L, D = ldl(M)
    np.testing.assert_allclose((L * D[:, None, :]) @ L.swapaxes(1, 2), M, atol=1e-12)
    assert np.allclose(np.triu(L, 1), 0) and np.allclose(np.diagonal(L, axis1=1, axis2=2), 1)


def test_inertia_model_has_definite_inputs_where_axes_does_not(ur5):
    robot, _, inertia, axes = ur5
    assert input_definiteness(inertia, 300)["fraction"] == 0.0
    # the model that issue 21 replaces: two thirds of its members push the wrong way
    assert input_definiteness(axes, 300)["fraction"] > 0.3
    m = robot.m
    for d in inertia.delta_samples(50, kind="corners", seed=3):
        B = inertia.matrices_at(d)[1][m:]
        np.testing.assert_allclose(B, B.T, atol=1e-12 * np.abs(B).max())
        assert np.linalg.eigvalsh(B).min() > 0


def test_lft_is_the_exact_inverse_inertia_times_n(ur5):
    robot, _, unc, _ = ur5
    m = robot.m
    f, sub = unc.info["factors"], unc.info["N_plant"]
    pN = sub.n_params
    G = unc.lft_system()
    rng = np.random.default_rng(5)
    for d in unc.delta_samples(6, seed=6):
        res = unc.residual_samples(1, seed=int(rng.integers(1000)))[0]
        A, B = unc.matrices_at(d, residual=res)
        Minv = np.linalg.inv(f.matrix(d[pN:]))
        np.testing.assert_allclose(B[m:], Minv, rtol=0, atol=1e-10 * np.abs(Minv).max())
        N = sub.matrices_at(d[:pN], residual=res)[0][m:]
        np.testing.assert_allclose(A[m:], Minv @ N, rtol=0, atol=1e-10 * np.abs(A).max())
        closed = upper_lft(G, unc.delta_matrix(d, res))
        np.testing.assert_allclose(closed.B, B, rtol=0, atol=1e-10 * np.abs(B).max())
        # members with the residual at zero pass the membership test
        assert model_of(unc).contains(unc, *unc.matrices_at(d)).all()


def test_coverage_on_fresh_samples_is_one_and_a_shrunk_model_fails(pldi, paper):
    robot = cached_robot("paper_2r")
    assert paper.coverage == 1.0 and paper.coverage_points == 3000
    assert coverage_fraction(paper, robot, pldi.domain, 3000, seed=777) == 1.0
    assert coverage_fraction(_shrunk(paper, 0.9), robot, pldi.domain, 3000, seed=777) < 0.99


def test_paper_arm_model_size_nominal_and_description(pldi, paper):
    # N on 4 principal directions, L D L^T of a 2x2 inertia: l21, d1, d2
    assert paper.parameter_names[-3:] == ("l21", "d1", "d2") and paper.n_params <= 8
    assert paper.block_structure.tolist()[-3:] == [[-2, 0], [-1, 0], [-1, 0]]
    A, B = paper.matrices_at(paper.nominal_delta)
    np.testing.assert_allclose(A, pldi.A0, atol=1e-9 * np.abs(pldi.A0).max())
    np.testing.assert_allclose(B, pldi.B0, atol=1e-12)
    text = model_of(paper).describe(paper)
    assert text.startswith("inertia: M(q) = L D L^T") and "positive definite in every member" in text
    assert model_of(paper).enclosure(paper) == "sampled"
    assert input_definiteness(paper, 200)["fraction"] == 0.0


def test_torque_jacobians_stand_in_survives_pickling():
    """The N PLDI's bounds workers unpickle it (a RecursionError in every worker before)."""
    import pickle

    from polyrob.plant.models.inertia_lft import TorqueJacobians

    copy = pickle.loads(pickle.dumps(TorqueJacobians(cached_robot("planar_2r"))))
    A, B = copy.jacobians([0.1, 0.2], [0.0, 0.0], [0.0, 0.0])
    assert copy.name == "planar_2r/N" and copy.m == 2 and np.array_equal(B[2:], np.eye(2))
