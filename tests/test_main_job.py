"""`polyrob run` without a robot: the main job (README's first command) poses the task and certifies."""

from __future__ import annotations

import json

import pytest

from polyrob.cli import build_parser
from polyrob.cli.run import MAIN_JOB, main_job_defaults


class _Lines:
    def __init__(self):
        self.lines = []

    def line(self, text):
        self.lines.append(text)


def _args(*argv):
    return build_parser().parse_args(["run", *argv])


def test_no_robot_is_the_main_job_task_domain():
    args, out = _args(), _Lines()
    main_job_defaults(args, out)
    assert (args.robot, args.pose, args.q_radius, args.qdot_max, args.qddot_max, args.target) == (
        "planar_2r",
        "0,1.5708",
        "0.5",
        "1",
        "2",
        0.95,
    )
    assert args.reduce and args.bandwidth_scale == 1.0  # the paper's bandwidths, a reduced controller
    assert "main job" in out.lines[0] and "|qddot| <= 2" in out.lines[0]


def test_a_given_robot_or_domain_is_not_overridden():
    args, out = _args("paper_2r"), _Lines()
    main_job_defaults(args, out)
    assert args.robot == "paper_2r" and args.pose is None and args.target is None and not out.lines
    args = _args("--qddot-max", "5", "--target", "0.9")
    main_job_defaults(args, _Lines())
    # a domain option replaces the main job's task; the robot and the rest stay the main job's
    assert (args.robot, args.qddot_max, args.pose, args.q_radius, args.target) == ("planar_2r", "5", None, None, 0.9)
    assert set(MAIN_JOB) >= {"robot", "pose", "q_radius", "qdot_max", "qddot_max", "target"}


def test_full_order_opts_out_of_the_reduction():
    assert not _args("--full-order").reduce and _args().reduce


@pytest.mark.slow
def test_the_main_job_ends_certified_with_an_implementable_controller(capsys):
    """The whole main job (about a minute on 2 idle cores; `benchmarks/main_job.py` times it)."""
    from polyrob.cli import main

    code = main(["run", "--json", "--quiet", "--no-time-varying"])
    doc = json.loads(capsys.readouterr().out)
    cert = doc["analysis"]["robust_performance"]["certificate"]
    assert code == 0 and cert["status"] == "CERTIFIED" and cert["bound"] < 1
    assert doc["analysis"]["controller_order"] <= 20
