"""The values the factors attain at a task box's vertices (bounds/certified/factors/attained.py), and what they do for the proof."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from polyrob import load_robot
from polyrob.bounds.certified.factors import FactorProblem, factor_directions, prove_factor_ranges, vertex_ascent
from polyrob.bounds.certified.factors.attained import extremes_over_accelerations
from polyrob.domains.default_task import default_task_domain, default_task_robot
from polyrob.errors import CertificationError


@pytest.fixture(scope="module")
def finger():
    robot = load_robot("finger_edu")
    loops = factor_directions(default_task_robot(robot))
    return loops, FactorProblem.from_loops(loops), default_task_domain(robot)


def _box(domain):
    x_lo = np.concatenate([domain.q_lower, domain.qdot_lower])
    x_hi = np.concatenate([domain.q_upper, domain.qdot_upper])
    return x_lo, x_hi, np.asarray(domain.qddot_lower, float), np.asarray(domain.qddot_upper, float)


def test_the_ascent_finds_the_vertex_extremes_and_never_more(finger):
    _, problem, domain = finger
    x_lo, x_hi, a_lo, a_hi = _box(domain)
    lo, hi = vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi)
    # every vertex of finger_edu's (q, qdot) box: 2^6
    vertices = np.array(list(itertools.product([False, True], repeat=len(x_lo))))
    low, high = extremes_over_accelerations(problem, np.where(vertices, x_hi, x_lo), a_lo, a_hi)
    v_lo, v_hi = low.min(0), high.max(0)
    scale = np.abs(v_hi).max()
    assert np.all(hi <= v_hi + 1e-12 * scale) and np.all(lo >= v_lo - 1e-12 * scale)  # attained values, never more
    found = np.isclose(hi, v_hi, rtol=1e-9, atol=1e-12 * scale).mean()
    found_low = np.isclose(lo, v_lo, rtol=1e-9, atol=1e-12 * scale).mean()
    assert found > 0.9 and found_low > 0.9  # measured 0.94 and 0.96


def test_the_ascent_on_some_sides_finds_what_the_whole_ascent_finds_there(finger):
    _, problem, domain = finger
    x_lo, x_hi, a_lo, a_hi = _box(domain)
    lo, hi = vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi)
    sides = np.random.default_rng(3).random(lo.shape + (2,)) < 0.2
    some_lo, some_hi = vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi, sides=sides)
    # each side's path is its own (the vertices shared are evaluated once): the same values where searched
    assert np.array_equal(some_lo[sides[..., 0]], lo[sides[..., 0]]) and np.all(some_lo[~sides[..., 0]] == np.inf)
    assert np.array_equal(some_hi[sides[..., 1]], hi[sides[..., 1]]) and np.all(some_hi[~sides[..., 1]] == -np.inf)


def test_extremes_over_the_accelerations_are_the_values_at_their_best_vertex(finger):
    _, problem, domain = finger
    x_lo, x_hi, a_lo, a_hi = _box(domain)
    rng = np.random.default_rng(3)
    x = rng.uniform(x_lo, x_hi, (4, len(x_lo)))
    low, high = extremes_over_accelerations(problem, x, a_lo, a_hi)
    m = problem.m
    corners = np.array(list(itertools.product([False, True], repeat=m)))
    values = np.stack(
        [problem.values(x[:, :m], x[:, m:], np.tile(np.where(c, a_hi, a_lo), (len(x), 1))) for c in corners]
    )
    scale = np.abs(values).max()
    assert np.allclose(high, values.max(0), atol=1e-12 * scale) and np.allclose(low, values.min(0), atol=1e-12 * scale)


def test_the_proof_closes_with_the_ascent_where_the_pilot_alone_cannot(finger):
    loops, problem, domain = finger
    small = domain.scaled(0.1)
    # the pilot's random points stay tolerances below the extremes at the box's corners: the branch and bound must
    # reach each corner (a face at a time, monotone.py: 28 boxes) before its values close the sides
    with pytest.raises(CertificationError, match="limit of 10 boxes"):
        prove_factor_ranges(loops, small, max_boxes=10, ascent_rounds=0)  # measured: 40 boxes
    enclosure = prove_factor_ranges(loops, small, max_boxes=10)
    assert enclosure.boxes <= 3  # measured 1
    # the boxes' own ascent, on their sides near closing, finds the corners too (without the task's)
    assert prove_factor_ranges(loops, small, max_boxes=10, ascent_rounds=0, box_ascent_rounds=4).boxes <= 5  # 3
    x_lo, x_hi, a_lo, a_hi = _box(small)
    lo, hi = vertex_ascent(problem, x_lo, x_hi, a_lo, a_hi)
    assert np.all(enclosure.lower <= lo) and np.all(enclosure.upper >= hi)  # the proof holds what is attained


def test_the_inner_gain_model_rests_on_the_proved_factor_ranges_alone(finger, monkeypatch):
    """finger_edu's computed-torque task (a tenth of the default box), its factor ranges proved: the inner-gain
    model's centres are the proof's, it covers 300 fresh true-robot points, and a problem built on it says its
    enclosure is certified though the PLDI's A, B intervals are sampled; without the proof it is sampled.

    The PLDIs' sampled supports are the model's to ignore: they are sampled with the search's cheap effort (64
    positions, no local refinement, screening or verification rounds), and build_problem's uncertain plant checks
    its coverage on 300 points as the one above does (its default 2000 were most of the test's time; no assertion
    reads them)."""
    from polyrob import bound_pldi
    from polyrob.pipeline.problem import build_problem
    from polyrob.plant import uncertainty as uncertainty_module
    from polyrob.plant.models.registry import enclosure_inputs, model_of
    from polyrob.plant.uncertainty import uncertain_plant

    _, problem, domain = finger
    small = domain.scaled(0.1)
    robot = default_task_robot(load_robot("finger_edu"))
    cheap = {"samples": 64, "refine": False, "screen": 0, "verify_rounds": 0, "coverage": 0, "workers": 1,
             "progress": False}  # fmt: skip
    pldi = bound_pldi(robot, small, certify=True, **cheap)
    assert pldi.enclosure == "sampled"  # the A, B intervals: the model does not read them
    unc = uncertain_plant(pldi, model="inner-gain", coverage=300, volume_samples=0)
    assert model_of(unc).enclosure(unc) == "certified" and enclosure_inputs(unc) == {"factors": "certified"}
    assert unc.info["enclosure"] == "certified"
    proof = pldi.info["certify"]["factors"]
    for k, name in enumerate(unc.info["factors"]):
        lo, hi = np.asarray(proof[name]["lower"]), np.asarray(proof[name]["upper"])
        assert np.allclose(unc.info["K_centres"][k], 0.5 * (lo + hi), rtol=0, atol=1e-12 * np.abs(hi).max())
    assert unc.coverage == 1.0 and unc.coverage_points == 300  # true robots at fresh task points are members
    # what a certificate on it covers: proved, though the PLDI's own A, B intervals are sampled
    monkeypatch.setattr(
        uncertainty_module,
        "uncertain_plant",
        lambda pldi, **kw: uncertain_plant(pldi, **{"coverage": 300, "volume_samples": 0, **kw}),
    )
    problem = build_problem(robot, pldi=pldi, progress=False)
    assert problem.model == "inner-gain"  # auto's choice for a computed-torque task
    assert problem.unc.coverage == 1.0 and problem.unc.coverage_points == 300
    scope = problem.scope()
    assert scope.enclosure == "certified" and "proved (interval arithmetic)" in scope.sentence()
    # the PLDI's sampled intervals are named as what they are: not what the certificate rests on
    assert "are not what the model rests on" in scope.sentence() and "; bounds sampled at" not in scope.sentence()
    # the proof closed every side: within 1 + 2 rel_tol of the values attained; stopped at its work limit, the
    # certificate would name it (its ranges hold, wider than the tolerance)
    proof_info = pldi.info["certify"]
    assert proof_info["done"] == 1.0 and proof_info["tightness"]["max"] <= 1.0801
    from polyrob.pipeline.reports import pldi_report

    reported = pldi_report(pldi)["factor_proof"]  # `bounds --json`: how far the proof got, not its ranges
    assert reported["done"] == 1.0 and reported["boxes"] == proof_info["boxes"] and "factors" not in reported
    assert "work limit" not in scope.sentence()
    proof_info.update(done=0.42, tightness={**proof_info["tightness"], "max": 3.5})
    sentence = problem.scope().sentence()
    assert "factor ranges proved at the proof's work limit" in sentence and "42.0 %" in sentence and "3.5x" in sentence
    # without the proof the same model is sampled, and says it rests on the PLDI too
    sampled = uncertain_plant(bound_pldi(robot, small, **cheap), model="inner-gain", coverage=0, volume_samples=0)
    assert model_of(sampled).enclosure(sampled) == "sampled" and "PLDI" in enclosure_inputs(sampled)
    # the commands' summary line names what the model rests on (it said "sampled PLDI" on proved ranges)
    from types import SimpleNamespace

    from polyrob.cli.plant import bounds_words

    assert bounds_words(problem) == "proved factor ranges"
    assert bounds_words(SimpleNamespace(unc=sampled, pldi=SimpleNamespace(enclosure="sampled"))) == "sampled PLDI"


def test_synth_certify_is_refused_in_one_line_where_it_cannot_run(tmp_path, capsys):
    from polyrob.cli import main

    assert main(["synth", "finger_edu", "--max-boxes", "3", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--max-boxes and --proof-dir set the interval-arithmetic proof: use them with --certify" in err
    assert err.count("\n") == 1
    assert main(["synth", "finger_edu", "--proof-dir", str(tmp_path), "--quiet"]) == 2
    assert "use them with --certify" in capsys.readouterr().err
    assert main(["synth", "finger_edu", "--certify", "--pldi", str(tmp_path / "p.json"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "--pldi holds its bounds already" in err and err.count("\n") == 1
    # an arm's proof at its work limit is not refused: its ranges are taken (test_cli_progress.py)
    # a torque box's proof keeps no state: --proof-dir there is refused in one line (it was a traceback)
    assert main(["bounds", "planar_2r", "--certify", "--proof-dir", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "a torque box's proof keeps no state: drop it" in err and err.count("\n") == 1
    # a torque box's proof names the options of `polyrob bounds`, which this command does not have: it says so
    assert main(["synth", "planar_2r", "--certify", "--max-boxes", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert (
        "--rel-tol and --time-limit are options of `polyrob bounds --certify -o STEM`" in err and err.count("\n") == 1
    )
