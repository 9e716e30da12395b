"""Tests of polyrob.plant.uncertainty: the PLDI as an LFT in normalised real parameters."""

import dataclasses

import control
import numpy as np
import pytest

from polyrob.analysis.mu.blocks import BlockStructure
from polyrob.errors import ArgumentError, BoundsError, PolyrobError
from polyrob.plant.coverage import model_contains
from polyrob.plant.models import MODELS, UncertaintyModel, model_of
from polyrob.plant.uncertainty import CHOICES, UncertainPlant, uncertain_plant, upper_lft

#: Models of a computed-torque inner loop only (their own test files build them).
INNER_LOOP_MODELS = ("inner-gain", "inner-links", "inner-links-real", "inner-links-moving")

PAPER_ENTRIES = ("a32", "a33", "a34", "a42", "a43", "a44", "b31", "b32", "b41", "b42")


@pytest.fixture(scope="module")
def unc_merged(pldi):
    return uncertain_plant(pldi, model="box", merge_symmetric=True)


def _entries(unc, A, B):
    """Values of the channels' entries in (A, B)."""
    return np.array([(A if mat == 0 else B)[r, c] for mat, r, c in unc.channel_index])


def test_parameters_are_the_pldi_entries(pldi, unc):
    assert isinstance(unc, UncertainPlant)
    assert unc.parameter_names == PAPER_ENTRIES == unc.channel_names
    assert (unc.n_params, unc.n_delta, unc.m, unc.n_x) == (10, 10, 2, 4)
    assert unc.block_structure.tolist() == [[-1, 0]] * 10
    np.testing.assert_array_equal(unc.parameter_lower, pldi.lower)
    np.testing.assert_array_equal(unc.parameter_upper, pldi.upper)
    assert unc.ranges["b31"] == pldi.interval("b31")
    assert unc.merged == ()


def test_nominal_system_is_the_paper_G_n(pldi, unc):
    G = unc.nominal_system()
    np.testing.assert_array_equal(G.A, pldi.A0)
    np.testing.assert_array_equal(G.B, pldi.B0)
    np.testing.assert_array_equal(G.C, [[1, 0, 0, 0], [0, 1, 0, 0]])
    np.testing.assert_array_equal(G.D, np.zeros((2, 2)))
    assert G.isctime() and G.input_labels == ["u[0]", "u[1]"] and G.output_labels == ["y[0]", "y[1]"]


def test_lft_centre_is_the_midpoint_and_offsets_are_exact(pldi, unc):
    mid = 0.5 * (pldi.lower + pldi.upper)
    M = unc.lft_system()
    G0 = upper_lft(M, np.zeros((10, 10)))  # Δ = 0
    np.testing.assert_allclose(_entries(unc, G0.A, G0.B), mid, rtol=0, atol=1e-15)
    np.testing.assert_allclose(unc.offset, mid - pldi.nominal, rtol=0, atol=1e-15)
    # the paper's 2R at q = 0: b31, b42 at their upper bound, b32 = b41 at the lower one;
    # a42's interval is asymmetric around its nominal 0
    np.testing.assert_allclose(unc.nominal_delta[6:], [1.0, -1.0, -1.0, 1.0], atol=1e-12)
    assert unc.offset[3] == pytest.approx(0.5 * (pldi.upper[3] + pldi.lower[3]))
    assert unc.offset[3] > 7.0
    assert unc.nominal_inside


def test_plant_at_nominal_delta_is_the_nominal(pldi, unc):
    G = unc.plant_at(unc.nominal_delta)
    np.testing.assert_allclose(G.A, pldi.A0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(G.B, pldi.B0, rtol=0, atol=1e-15)


def test_midpoint_nominal(pldi):
    u = uncertain_plant(pldi, model="box", nominal="midpoint")
    G = u.nominal_system()
    np.testing.assert_allclose(_entries(u, G.A, G.B), 0.5 * (pldi.lower + pldi.upper), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(u.nominal_delta, np.zeros(10))
    np.testing.assert_array_equal(u.offset, np.zeros(10))
    np.testing.assert_array_equal(G.A, u.midpoint_system().A)


@pytest.mark.parametrize("merge", [False, True])
def test_upper_lft_reproduces_plant_at(pldi, merge):
    u = uncertain_plant(pldi, model="box", merge_symmetric=merge)
    M = u.lft_system()
    assert M.ninputs == M.noutputs == u.n_delta + 2
    assert M.input_labels[: u.n_delta] == [f"d_{n}" for n in u.channel_names]
    assert M.output_labels[-2:] == ["y[0]", "y[1]"]
    np.testing.assert_array_equal(M.D[: u.n_delta, : u.n_delta], 0)  # D_vd = 0: always well posed
    rng = np.random.default_rng(7)
    deltas = np.vstack([rng.uniform(-1, 1, (20, u.n_params)), u.delta_samples(8, kind="corners", seed=1)])
    for d in deltas:
        G_lft = upper_lft(M, u.delta_matrix(d))
        G = u.plant_at(d)
        for X, Y in ((G_lft.A, G.A), (G_lft.B, G.B), (G_lft.C, G.C), (G_lft.D, G.D)):
            np.testing.assert_allclose(X, Y, rtol=1e-13, atol=1e-15)
        # and it is an affine function of δ: entry = mid + rad δ
        mid = 0.5 * (u.channel_lower + u.channel_upper)
        rad = 0.5 * (u.channel_upper - u.channel_lower)
        np.testing.assert_allclose(_entries(u, G.A, G.B), mid + rad * d[u.channel_parameter], rtol=1e-13, atol=1e-15)


def test_each_channel_is_rank_one(unc):
    for j, (mat, r, c) in enumerate(unc.channel_index):
        assert np.count_nonzero(unc.B_d[:, j]) == 1 and unc.B_d[r, j] > 0
        sel = unc.C_v[j] if mat == 0 else unc.D_vu[j]
        assert np.count_nonzero(sel) == 1 and sel[c] == 1.0
        assert not np.any((unc.D_vu if mat == 0 else unc.C_v)[j])


def test_corners_hit_the_interval_endpoints_exactly(pldi, unc):
    systems, deltas = unc.corners(return_delta=True)
    assert len(systems) == 1024 and deltas.shape == (1024, 10)
    assert len({tuple(d) for d in deltas}) == 1024 and set(np.unique(deltas)) == {-1.0, 1.0}
    vals = np.array([_entries(unc, G.A, G.B) for G in systems])
    for i in range(10):
        np.testing.assert_array_equal(vals[deltas[:, i] == -1, i], pldi.lower[i])
        np.testing.assert_array_equal(vals[deltas[:, i] == 1, i], pldi.upper[i])
    assert np.all(pldi.contains(np.array([G.A for G in systems]), np.array([G.B for G in systems])))


def test_usample_stays_in_the_box_and_is_reproducible(pldi, unc):
    systems, deltas = unc.usample(50, seed=3, return_delta=True)
    assert len(systems) == 50 and np.all(np.abs(deltas) <= 1)
    A = np.array([G.A for G in systems])
    B = np.array([G.B for G in systems])
    vals = pldi.entry_values(A, B)
    assert np.all(vals >= pldi.lower) and np.all(vals <= pldi.upper)
    assert np.all(pldi.contains(A, B))
    again = unc.usample(50, seed=3)
    np.testing.assert_array_equal(again[17].A, systems[17].A)
    assert not np.array_equal(unc.usample(1, seed=4)[0].A, systems[0].A)
    # uniform: the sample mean of δ is near 0, the extremes near ±1
    d = unc.delta_samples(4000, seed=0)
    assert np.all(np.abs(d.mean(axis=0)) < 0.05) and d.min() < -0.99 and d.max() > 0.99


def test_merge_symmetric_shares_one_repeated_parameter(pldi, unc_merged):
    u = unc_merged
    assert u.n_params == 9 and u.n_delta == 10
    assert u.merged == (("b32", "b41"),)
    assert u.parameter_names[7] == "b32=b41"
    assert u.block_structure.tolist() == [[-1, 0]] * 7 + [[-2, 0]] + [[-1, 0]]
    assert u.channel_names == PAPER_ENTRIES
    np.testing.assert_array_equal(u.channel_parameter, [0, 1, 2, 3, 4, 5, 6, 7, 7, 8])
    np.testing.assert_array_equal(
        np.diag(u.delta_matrix(np.arange(9) / 10)), [0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.7, 0.8]
    )
    for d in u.delta_samples(10, seed=2):
        G = u.plant_at(d)
        assert G.B[2, 1] == G.B[3, 0]  # b32 = b41: B stays symmetric
    assert len(u.corners()) == 2**9
    # the merged range is the hull of b32's and b41's (equal to rounding)
    assert u.ranges["b32=b41"] == pytest.approx(pldi.interval("b32"), rel=1e-12)
    assert u.ranges["b32=b41"] == pytest.approx(pldi.interval("b41"), rel=1e-12)


def test_merge_requires_identical_bounds(pldi):
    B_upper = pldi.B_upper.copy()
    B_upper[3, 0] += 1e-3  # b41's upper bound no longer equals b32's
    other = dataclasses.replace(pldi, B_upper=B_upper)
    u = uncertain_plant(other, model="box", merge_symmetric=True)
    assert u.n_params == 10 and u.merged == ()
    assert u.block_structure.tolist() == [[-1, 0]] * 10


def test_block_structure_is_a_valid_matlab_blk(unc, unc_merged):
    st = BlockStructure.from_matlab(unc.block_structure)
    assert st.delta_shape == (10, 10) and st.m_shape == (10, 10)
    st = BlockStructure.from_matlab(unc_merged.block_structure)
    assert st.delta_shape == (10, 10) and [b.kind for b in st.blocks] == ["real"] * 9
    assert st.blocks[7].rows == 2


def test_bad_inputs_raise_clear_errors(pldi, unc):
    with pytest.raises(PolyrobError, match="one value per parameter"):
        unc.plant_at(np.zeros(9))
    with pytest.raises(PolyrobError, match=r"\[-1, 1\]"):
        unc.plant_at(np.full(10, 1.5))
    G = unc.plant_at(np.full(10, 2.0), strict=False)  # extrapolation on request
    assert G.B[2, 0] == pytest.approx(pldi.upper[6] + (pldi.upper[6] - pldi.lower[6]) / 2)
    with pytest.raises(PolyrobError, match="max_corners"):
        unc.corners(max_corners=512)
    assert unc.delta_samples(5, kind="corners", seed=0).shape == (5, 10)
    with pytest.raises(PolyrobError, match="unknown δ sampling"):
        unc.delta_samples(3, kind="sobol")
    with pytest.raises(PolyrobError, match="needs a number"):
        unc.delta_samples()
    with pytest.raises(PolyrobError, match="unknown nominal"):
        uncertain_plant(pldi, model="box", nominal="equilibrium")
    A_lower = pldi.A_lower.copy()
    A_lower[2, 1] = pldi.A_upper[2, 1] + 1.0
    with pytest.raises(BoundsError, match="a32"):
        uncertain_plant(dataclasses.replace(pldi, A_lower=A_lower), model="box")
    with pytest.raises(PolyrobError, match="ill posed"):
        upper_lft(control.ss([], [], [], [[1.0]]), [[1.0]])


def test_input_definiteness_holds_on_the_paper_models_and_fails_on_a_widened_box(pldi, unc):
    """Every member of the 2R's box keeps M^-1 positive definite; widen its b12/b21 channels and it does not."""
    from polyrob.plant.coverage import input_definiteness

    ok = input_definiteness(unc, 400)
    assert ok["fraction"] == 0.0 and ok["least"] > 0.0 and ok["centre"] > ok["least"]
    idx = np.asarray(unc.channel_index)
    lo, hi = np.asarray(unc.channel_lower, float).copy(), np.asarray(unc.channel_upper, float).copy()
    off = [k for k, (mat, r, c) in enumerate(idx) if mat == 1 and r - unc.m != c]
    assert off  # the 2R's b12 = b21 entries vary
    lo[off], hi[off] = lo[off] - 10.0, hi[off] + 10.0
    wide = dataclasses.replace(unc, channel_lower=lo, channel_upper=hi)
    bad = input_definiteness(wide, 400)
    assert bad["fraction"] > 0.5 and bad["least"] < 0.0


# ---------------------------------------------------------------- the models' interface
@pytest.fixture(scope="module")
def built(pldi):
    """Every registered model built on the paper_2r PLDI through its own ``build`` (inner-gain, inner-links: an inner loop only)."""
    return {name: model.build(pldi) for name, model in MODELS.items() if name not in INNER_LOOP_MODELS}


def _building_jacobians(pldi, n=300):
    """The Jacobians the PLDI was built from: the nominal pair, each bound's witness, and fresh domain points."""
    robot = pldi.robot
    m = pldi.m
    pts = np.vstack([pldi.witness_lower, pldi.witness_upper])
    A, B = robot.jacobians_batch(pts[:, :m], pts[:, m : 2 * m], pts[:, 2 * m :])
    q, qd, u = pldi.domain.sample(n, method="uniform", seed=11)
    A2, B2 = robot.jacobians_batch(q, qd, u)
    return np.concatenate([[pldi.A0], A, A2]), np.concatenate([[pldi.B0], B, B2])


def test_every_model_contains_the_jacobians_it_was_built_from(pldi, built):
    assert list(MODELS) == [
        "box", "axes", "lft", "lft-torque", "inertia", "inner-gain", "inner-links", "inner-links-real", "inner-links-moving"
    ]  # fmt: skip
    A, B = _building_jacobians(pldi)
    for name, unc in built.items():
        model = model_of(unc)
        assert isinstance(model, UncertaintyModel) and model is MODELS[name] and model.name == unc.model == name
        inside = model.contains(unc, A, B)
        assert inside.shape == (len(A),) and inside.dtype == bool and inside.all(), name
        np.testing.assert_array_equal(model_contains(unc, A, B), inside)
        # and not everything: a B far outside the robot's is refused by every model
        assert not model.contains(unc, A[:1], 3.0 * B[:1]).any(), name


def test_each_model_describes_its_set_in_one_sentence(built):
    for name, unc in built.items():
        text = model_of(unc).describe(unc)
        assert text.startswith(f"{name}: ") and text.endswith(".") and "\n" not in text
        assert "sampled enclosure" in text
    assert "interval box" in model_of(built["box"]).describe(built["box"])
    assert "N = M(q) A_low" in model_of(built["lft-torque"]).describe(built["lft-torque"])


def test_enclosure_is_the_weakest_of_the_inputs(pldi, built):
    """axes is sampled even on a certified PLDI (its ranges are sampled supports); lft-torque as weak as N's PLDI."""
    assert pldi.enclosure == "sampled"
    for unc in built.values():
        assert model_of(unc).enclosure(unc) == unc.info["enclosure"] == "sampled"
    assert built["axes"].info["enclosure_inputs"] == {"PLDI": "sampled", "directions": "sampled"}
    assert built["lft-torque"].info["enclosure_inputs"] == {"PLDI": "sampled", "N PLDI": "sampled"}
    # the same bounds labelled certified: only the models built on nothing else follow
    proved = dataclasses.replace(pldi, enclosure="certified")
    expected = {
        "box": "certified",
        "lft": "certified",
        "axes": "sampled",
        "lft-torque": "sampled",
        "inertia": "sampled",
    }
    for name, model in MODELS.items():
        if name in INNER_LOOP_MODELS:  # computed-torque inner loops only (their own test files)
            continue
        unc = model.build(proved)
        assert model.enclosure(unc) == unc.info["enclosure"] == expected[name], name


def test_unknown_models_give_clear_errors(pldi, unc):
    assert CHOICES == (
        "auto", "box", "axes", "lft", "lft-torque", "inertia", "inner-gain", "inner-links", "inner-links-real",
        "inner-links-moving",
    )  # fmt: skip
    msg = (
        "unknown uncertainty model 'cube': use one of auto, box, axes, lft, lft-torque, inertia, inner-gain, "
        "inner-links, inner-links-real, inner-links-moving"
    )
    with pytest.raises(ArgumentError, match=msg):
        uncertain_plant(pldi, model="cube")
    cube = dataclasses.replace(unc, model="cube")
    with pytest.raises(PolyrobError, match="unknown uncertainty model 'cube' of the plant"):
        model_of(cube)
    with pytest.raises(PolyrobError, match="no membership test for the model 'cube'"):
        model_contains(cube, np.zeros((1, 4, 4)), np.zeros((1, 4, 2)))
    with pytest.raises(ArgumentError, match="merge_symmetric applies to model='box' only"):
        uncertain_plant(pldi, model="axes", merge_symmetric=True)
    with pytest.raises(ArgumentError, match="n_directions and residual_tol apply to model='axes' or 'inertia' only"):
        uncertain_plant(pldi, model="lft", residual_tol=0.2)


def test_uncertain_plant_builds_through_the_registry(pldi, built):
    """uncertain_plant = the model's build plus the coverage figures; auto resolves to one registered model."""
    for name in ("box", "axes"):
        unc = uncertain_plant(pldi, model=name, coverage=200, volume_samples=0)
        assert unc.coverage == 1.0 and model_of(unc).name == name
        np.testing.assert_array_equal(unc.B_d, built[name].B_d)
    auto = uncertain_plant(pldi, coverage=0, volume_samples=0)
    assert auto.model == "lft" and auto.info["auto"].startswith("lft: ")
    np.testing.assert_array_equal(auto.B_d, built["lft"].B_d)
