"""Tests of the uncertainty models (polyrob.plant.uncertainty: box, axes, lft): coverage, shrinking, μ."""

import dataclasses

import numpy as np
import pytest
from conftest import cached_robot

from polyrob.errors import ArgumentError
from polyrob.plant.coverage import coverage_fraction, det_b_range, model_contains
from polyrob.plant.models.box import box_plant
from polyrob.plant.models.inertia_lft import NotApplicable, affine_inertia
from polyrob.plant.uncertainty import uncertain_plant, upper_lft


@pytest.fixture(scope="module")
def lft(pldi):
    return uncertain_plant(pldi, model="lft")


@pytest.fixture(scope="module")
def axes(pldi):
    return uncertain_plant(pldi, model="axes")


@pytest.fixture(scope="module")
def torque(pldi):
    return uncertain_plant(pldi, model="lft-torque")


def _shrunk(unc, factor):
    """The same model with every parameter range (and residual gain) scaled by ``factor``."""
    if unc.model == "box":
        mid, rad = 0.5 * (unc.channel_lower + unc.channel_upper), 0.5 * (unc.channel_upper - unc.channel_lower)
        return dataclasses.replace(unc, channel_lower=mid - factor * rad, channel_upper=mid + factor * rad)
    if unc.model in ("lft", "lft-torque"):
        lo, hi = unc.parameter_lower, unc.parameter_upper
        mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
        return dataclasses.replace(unc, parameter_lower=mid - factor * rad, parameter_upper=mid + factor * rad)
    info = dict(unc.info, z_rad=factor * unc.info["z_rad"], W_l=factor * unc.info["W_l"])
    return dataclasses.replace(unc, info=info)


def test_default_model_is_the_tight_lft_on_the_paper_arm(pldi):
    unc = uncertain_plant(pldi, coverage=0, volume_samples=0)
    assert unc.model == "lft" and "affine" in unc.info["auto"]
    # the paper's six A entries, and B = M(q)^-1 moving with cos q2 only (two rank-one pieces)
    assert unc.parameter_names == ("a32", "a33", "a34", "a42", "a43", "a44", "cos(q2)#1", "cos(q2)#2")
    assert unc.ranges["cos(q2)#1"] == (-1.0, 1.0)
    assert unc.n_params < 10


def test_inertia_of_a_2r_is_affine_in_cos_q2():
    robot = cached_robot("paper_2r")
    from polyrob.domains.torque_box import Domain

    names, joints, kinds, M0, Mf, ranges = affine_inertia(robot, Domain.from_robot(robot, "paper"))
    a1, a2, a3 = 48.125, 13.125, 6.25
    assert names == ["cos(q2)"]
    np.testing.assert_allclose(M0, [[a1, a2], [a2, a2]], atol=1e-9)
    np.testing.assert_allclose(Mf[0], a3 * np.array([[2.0, 1.0], [1.0, 0.0]]), atol=1e-9)
    np.testing.assert_allclose(ranges, [[-1.0, 1.0]])


@pytest.mark.parametrize("name", ["box", "lft", "axes", "lft-torque"])
def test_coverage_on_fresh_samples_is_one_and_a_shrunk_model_fails(pldi, unc, lft, axes, torque, name):
    model = {"box": unc, "lft": lft, "axes": axes, "lft-torque": torque}[name]
    robot = cached_robot("paper_2r")
    assert coverage_fraction(model, robot, pldi.domain, 3000, seed=777) == 1.0
    # the check can fail: 0.9x the ranges leaves Jacobians of the real arm outside
    assert coverage_fraction(_shrunk(model, 0.9), robot, pldi.domain, 3000, seed=777) < 0.99


def test_coverage_fields(lft, axes, torque):
    assert torque.model == "lft-torque" and torque.n_params == 6
    for model in (lft, axes, torque):
        assert model.coverage == 1.0 and model.coverage_points == 2000


@pytest.mark.parametrize("name", ["lft", "axes"])
def test_lft_members_are_in_the_model_and_match_the_state_space(lft, axes, name):
    model = {"lft": lft, "axes": axes}[name]
    M = model.lft_system()
    rng = np.random.default_rng(3)
    for delta in model.delta_samples(5, seed=4):
        res = model.residual_samples(1, seed=int(rng.integers(1000)))[0]
        A, B = model.matrices_at(delta, residual=res or None)
        # axes: the membership test splits p by projection (z = W (p - c)), a
        # sufficient test; members with a residual outside that split may fail it
        A0, B0 = model.matrices_at(delta)
        assert model_contains(model, A0, B0)[0]
        G = upper_lft(M, model.delta_matrix(delta, res or None))
        np.testing.assert_allclose(G.A, A, atol=1e-9 * (1 + np.abs(A).max()))
        np.testing.assert_allclose(G.B, B, atol=1e-12)


def test_lft_torque_variant_and_repeated_scalar(pldi):
    from polyrob.plant.models.inertia_lft import inertia_lft_contains, inertia_lft_plant

    tq = inertia_lft_plant(pldi, a_part="torque", repeated=True)
    assert tq.parameter_names == ("n32", "n34", "n42", "n43", "cos(q2)")
    assert tq.block_structure.tolist()[-1] == [-2, 0]
    robot = cached_robot("paper_2r")
    A, B = robot.jacobians_batch(*pldi.domain.sample(500, method="uniform", seed=99))
    assert inertia_lft_contains(tq, A, B).all()
    # the exact curve: B at δ = ±1 of cos(q2) is M(±1)^-1
    d = np.zeros(tq.n_params)
    d[-1] = 1.0
    a1, a2, a3 = 48.125, 13.125, 6.25
    np.testing.assert_allclose(
        tq.matrices_at(d)[1][2:], np.linalg.inv([[a1 + 2 * a3, a2 + a3], [a2 + a3, a2]]), rtol=1e-12
    )


def test_lft_nominal_delta_gives_the_nominal(pldi, lft):
    A, B = lft.matrices_at(lft.nominal_delta)
    np.testing.assert_allclose(A, pldi.A0, atol=1e-9)
    np.testing.assert_allclose(B, pldi.B0, atol=1e-15)


def test_tight_models_keep_det_b_in_range(unc, lft):
    # the box lets det B fall to about 12 % of its midpoint value; the arm never does
    lo_box, _ = det_b_range(unc, 500)
    lo_lft, _ = det_b_range(lft, 500)
    assert lo_box < 0.2 and lo_lft > 0.5


def test_volume_ratio_of_the_box_is_its_size_over_the_polytope(pldi):
    box = uncertain_plant(pldi, model="box", coverage=0, volume_samples=20_000)
    vol = box.info["volume"]
    assert box.volume_ratio == pytest.approx(vol["box_over_polytope"]) and box.volume_ratio > 20


def test_box_model_is_the_paper_box_unchanged(pldi, unc):
    ref = box_plant(pldi)
    for attr in ("A_mid", "B_mid", "B_d", "C_v", "D_vu", "D_vd", "parameter_lower", "parameter_upper"):
        np.testing.assert_array_equal(getattr(unc, attr), getattr(ref, attr))
    mid = 0.5 * (pldi.lower + pldi.upper)
    assert unc.block_structure.tolist() == [[-1, 0]] * 10
    np.testing.assert_allclose(np.abs(unc.B_d).sum(axis=0), 0.5 * (pldi.upper - pldi.lower), rtol=0, atol=0)
    A, B = unc.matrices_at(np.zeros(10))
    np.testing.assert_allclose(pldi.entry_values(A, B)[0], mid, rtol=0, atol=1e-15)


def test_axes_directions_can_be_set(pldi):
    one = uncertain_plant(pldi, model="axes", n_directions=1, coverage=300, volume_samples=0)
    assert one.n_params == 1 and one.info["n_directions"] == 1 and one.full_blocks
    assert one.coverage == 1.0
    with pytest.raises(Exception):
        uncertain_plant(pldi, model="axes", n_directions=99, coverage=0)


def test_options_of_another_model_are_refused(pldi):
    with pytest.raises(ArgumentError):
        uncertain_plant(pldi, model="lft", merge_symmetric=True)
    with pytest.raises(ArgumentError):
        uncertain_plant(pldi, model="cube")


def test_lft_does_not_apply_to_a_non_affine_inertia_and_auto_falls_back():
    from polyrob.model.analytic import AnalyticRobot

    def M(q):
        c = np.cos(q[:, 1])
        out = np.zeros(q.shape[:1] + (2, 2), dtype=np.result_type(q, float))
        out[:, 0, 0] = 3.0 + c * c  # cos^2: not affine in cos q2 / sin q2 alone
        out[:, 1, 1] = 1.0
        return out

    robot = AnalyticRobot(
        name="sq",
        joint_names=("a", "b"),
        M=M,
        C=lambda q, qd: np.zeros(q.shape[:1] + (2, 2)),
        position_lower=[-1, -1],
        position_upper=[1, 1],
        velocity_limit=[1, 1],
        effort_limit=[1, 1],
    )
    from polyrob.domains.torque_box import Domain

    with pytest.raises(NotApplicable):
        affine_inertia(robot, Domain.from_robot(robot))


def test_tight_model_mu_of_k_star_is_below_the_box(unc, lft):
    from polyrob.analysis.robust import robperf
    from polyrob.plant.generalized import generalized_plant, paper_controller
    from polyrob.plant.weights import paper_weights

    W_S, W_T = paper_weights()
    omega = np.logspace(-2, 2, 9)
    mus = {}
    for name, model in (("box", unc), ("lft", lft)):
        r = robperf(generalized_plant(model, W_S, W_T), paper_controller(), omega, refine_peak=False)
        mus[name] = r.mu_upper_grid
    # the lft model is the box with B on its true curve: a subset, and μ of K* drops
    # (full sweeps: box 2.43, lft 2.12, see docs/uncertainty.md)
    assert mus["lft"] < 0.95 * mus["box"]
    assert mus["box"] > 2.0


def test_the_residual_lps_fall_back_on_another_highs_method(pldi, axes, monkeypatch):
    """A HiGHS method that stops with "Not Set" (seen on z1) is retried with the next; the bounds are the same."""
    from scipy import optimize

    import polyrob.plant.models.axes as axes_module

    real, tried = optimize.linprog, []

    def flaky(c, *args, method="highs", **kwargs):
        tried.append(method)
        if method == "highs":
            return optimize.OptimizeResult(status=4, message="HiGHS Status 0: Not Set", x=None)
        return real(c, *args, method=method, **kwargs)

    from types import SimpleNamespace

    monkeypatch.setattr(axes_module, "optimize", SimpleNamespace(linprog=flaky))  # this module's LPs only
    again = uncertain_plant(pldi, model="axes")
    assert "highs-ipm" in tried
    np.testing.assert_allclose(again.D_vd, axes.D_vd, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(again.B_d, axes.B_d, rtol=1e-6, atol=1e-9)
