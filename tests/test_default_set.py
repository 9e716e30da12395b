"""``--robot-uncertainty default``: the set an arm engineer states (issue 38), and what the model says of it."""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from polyrob import load_robot
from polyrob.cli.options import robot_uncertainty_from_args
from polyrob.domains.default_task import DEFAULT_TASK, default_task_domain
from polyrob.model.inner import inner_loop_of_set
from polyrob.plant.models.inner_links import carried
from polyrob.uncertainty_set.default_set import default_set
from polyrob.uncertainty_set.draw import draw_true_robots, model_of_set


def _args(**kw):
    return SimpleNamespace(**{"robot_uncertainty": None, "link_error": None, **kw})


def test_the_default_set_is_each_link_on_its_own_and_the_instrument_off_the_flange():
    ur5 = load_robot("ur5")
    spec = robot_uncertainty_from_args(_args(robot_uncertainty="default"), ur5)
    assert spec.link_error == pytest.approx(0.10)
    body = spec.payload
    assert (body.mass_lower, body.mass_upper, body.com_radius) == (0.0, 1.5, 0.1)
    assert spec.robot == "ur5" and "rated 5 kg" in spec.source
    # --link-error replaces the percentage, the instrument stays
    wider = robot_uncertainty_from_args(_args(robot_uncertainty="default", link_error="20"), ur5)
    assert wider.link_error == pytest.approx(0.20) and wider.payload == body


def test_the_instrument_is_capped_at_the_rating_and_absent_where_the_rating_is_unknown():
    so101 = default_set(load_robot("so101"))
    assert so101.payload is None
    assert "no instrument" in so101.source and "no payload" in so101.words()


def test_a_set_the_model_cannot_hold_says_how_far_the_inertia_moves_and_the_draws_agree(light_models_once):
    """ur10 with the 1.5 kg instrument: refused, with the range of eig(M_hat^-1 M) over the set; true robots
    drawn at random from the set fall inside that range and reach far outside the old common factor's.

    (The set is measured once a session: the CLI's refusal below poses the same loop and task.)"""
    ur10 = load_robot("ur10")
    spec = default_set(ur10)
    loop = inner_loop_of_set(ur10, "computed-torque", spec)
    domain = default_task_domain(loop, DEFAULT_TASK)
    why = carried(loop, domain)
    found = re.search(r"inertia ranges from ([\d.e-]+) to ([\d.e-]+) times the model's", why or "")
    assert found, why
    lo, hi = float(found.group(1)), float(found.group(2))
    model = model_of_set(ur10, spec)
    q = domain.split(domain.sample_box(6, method="uniform", seed=1))[0]
    seen = []
    for true in draw_true_robots(ur10, spec, 12, seed=4):
        for qq in q:
            M_hat, M = model.mass_matrix(qq), true.robot.mass_matrix(qq)
            seen.extend(np.linalg.eigvals(np.linalg.solve(M_hat, M)).real)
    # two significant digits in the words: the draws lie within them, and spread well beyond ±10 %
    assert lo * 0.95 <= min(seen) and max(seen) <= hi * 1.05
    assert min(seen) < 0.5 and max(seen) > 1.5


def test_the_cli_refuses_it_in_one_line(tmp_path, capsys, light_models_once):
    from polyrob.cli import main

    out = tmp_path / "K.json"
    rc = main(["synth", "ur10", "--robot-uncertainty", "default", "-o", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and not out.exists()
    assert err[-1].startswith("polyrob: error: --robot-uncertainty default (per-link ±10 %")
    assert "not carried on ur10's default task" in err[-1] and "times the model's" in err[-1]


def test_a_batch_job_takes_the_default_set_by_name():
    from polyrob.errors import ArgumentError
    from polyrob.fleet.jobs import Job, job_robot_and_domain

    loop, domain, _ = job_robot_and_domain(Job(robot="ur5", robot_uncertainty="default"))
    assert loop.uncertainty.link_error == pytest.approx(0.10) and loop.uncertainty.payload.mass_upper == 1.5
    assert domain.kind == "task"
    with pytest.raises(ArgumentError, match="robot_uncertainty is a set's mapping"):
        job_robot_and_domain(Job(robot="ur5", robot_uncertainty="ur5.yaml"))
