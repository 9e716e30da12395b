"""polyrob.fleet: batch runs (in this process, a Dask LocalCluster), spawned workers, files, CLI, weights.

The robots are one-joint pendulums written here (bounds and a 1-iteration
D-K synthesis take about a second each) and a name that does not exist.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import pickle
import re
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import process_running

from polyrob.fleet import Job, Settings, automatic_hyperparameters, domain_level, run_batch, run_job
from polyrob.fleet.executors import LocalExecutor
from polyrob.plant.weights import PAPER_HYPERPARAMETERS

PENDULUM = """<?xml version="1.0"?>
<robot name="{name}">
  <link name="base"/>
  <link name="link1">
    <inertial>
      <origin xyz="0.5 0 0" rpy="0 0 0"/>
      <mass value="{mass}"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/>
    </inertial>
  </link>
  <joint name="joint1" type="revolute">
    <parent link="base"/>
    <child link="link1"/>
    <axis xyz="0 1 0"/>
    <limit lower="-0.5" upper="0.5" velocity="1.0" effort="10.0"/>
    <dynamics damping="0.5" friction="0.0"/>
  </joint>
</robot>
"""

#: small settings: a few seconds per robot
FAST = dict(
    bound_options={"samples": 64, "verify_rounds": 0, "starts_per_direction": 1},
    synthesis={"max_iter": 1},
    omega=(1e-2, 1e3, 8),
    mc=5,
    validate_time=2.0,
)
MISSING = "no_such_robot_urdf_xyz"


@pytest.fixture(scope="module")
def pendulums(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fleet_robots")
    paths = []
    for name, mass in (("pendulum_a", 1.0), ("pendulum_b", 2.0)):
        path = folder / f"{name}.urdf"
        path.write_text(PENDULUM.format(name=name, mass=mass))
        paths.append(str(path))
    return paths


@pytest.fixture(scope="module")
def reference(pendulums):
    """The batch in this process: the results the other executors must reproduce."""
    return run_batch([*pendulums, MISSING], workers=1, progress=False, **FAST)


#: how each status reads in a verdict line (NOT_CERTIFIED reads "NOT certified")
STATUS_WORD = {
    "CERTIFIED": "CERTIFIED",
    "GRID_ONLY": "GRID_ONLY",
    "NOT_CERTIFIED": "NOT certified",
    "VIOLATED": "VIOLATED",
}


def _row_agrees(r):
    """A fleet row and its verdict never disagree: one status, its word in the verdict, "certified" only for CERTIFIED."""
    row = r.row()
    assert row["status"] in STATUS_WORD, row["status"]
    assert row["certified"] is (row["status"] == "CERTIFIED") is r.certified
    assert row["verdict"].startswith("verdict: ") and STATUS_WORD[row["status"]] in row["verdict"]
    assert bool(re.search(r"(?<![A-Za-z_])CERTIFIED(?![A-Za-z_])", row["verdict"])) is row["certified"]
    # the certificate the row stores is the one it reads (its bound null when not finite)
    cert = r.certificate["certificate"]
    assert (cert["status"], cert["certified"]) == (row["status"], row["certified"])
    assert "verdict: " + cert["verdict"] == row["verdict"]
    # mu_upper is the bound proved at every frequency (null when none was), mu_upper_grid the grid peak
    assert row["mu_upper"] == cert["mu_upper"] and row["mu_upper_grid"] == pytest.approx(cert["mu_upper_grid"])
    if row["certified"]:
        assert row["mu_upper"] == pytest.approx(cert["bound"]) and row["mu_upper"] < 1
    return row


def _same(a, b):
    assert (a.name, a.ok, a.error, a.message) == (b.name, b.ok, b.error, b.message)
    if not a.ok:
        return
    assert (a.joints, a.entries, a.parameters, a.order, a.certified) == (
        b.joints,
        b.entries,
        b.parameters,
        b.order,
        b.certified,
    )
    assert a.mu_upper_grid == pytest.approx(b.mu_upper_grid, rel=1e-9)
    assert a.mu_lower == pytest.approx(b.mu_lower, rel=1e-9)
    for key in "ABCD":
        np.testing.assert_allclose(a.controller[key], b.controller[key], rtol=1e-8, atol=1e-10)


def test_reference_batch_records_the_failure_and_finishes_the_others(reference):
    ok = [r for r in reference.results if r.ok]
    assert [r.name for r in ok] == ["pendulum_a", "pendulum_b"]
    bad = reference[MISSING]
    assert not bad.ok and bad.error == "RobotError" and MISSING in bad.message and "\n" not in bad.message
    for r in ok:
        # one joint: q, qdot -> one varying entry of A (d qddot / d q) in the box model
        assert r.joints == 1 and r.parameters >= 1 and r.order >= 1
        assert math.isfinite(r.mu_upper_grid) and r.mu_lower <= r.mu_upper_grid * (1 + 1e-6)
        _row_agrees(r)
        assert set(r.timings) >= {"bounds", "synthesis", "analysis", "validation"}
        assert r.validation  # the nonlinear step ran and said something
        # a robot left without a certificate says why, one that has one does not
        assert (r.reason is None) == r.certified and (r.certified or "\n" not in r.reason)
    assert reference.failed == (bad,)
    # what a worker process sends back must survive pickling (python-control systems do not)
    back = pickle.loads(pickle.dumps(reference.results))
    for a, b in zip(back, reference.results):
        _same(a, b)


def test_dask_local_cluster_gives_the_local_results(pendulums, reference):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, processes=False, threads_per_worker=1, dashboard_address=None) as cl:
        res = run_batch([*pendulums, MISSING], scheduler=cl, progress=False, **FAST)
    assert res.executor.startswith("Dask")
    for a, b in zip(res.results, reference.results):
        _same(a, b)


def test_cli_batch_writes_files_and_a_summary(pendulums, tmp_path, capsys):
    from polyrob.cli import PolyrobParser
    from polyrob.cli import batch as batch_cli
    from polyrob.cli.common import HelpFormatter
    from polyrob.io.controller import load_controller

    # the parser as polyrob.cli.build_parser makes it (the module's own register())
    parser = PolyrobParser(prog="polyrob")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=PolyrobParser)
    sub.add_parser = functools.partial(sub.add_parser, formatter_class=HelpFormatter)
    batch_cli.register(sub)
    out = tmp_path / "fleet"
    args = parser.parse_args(
        [
            "batch",
            pendulums[0],
            MISSING,
            "-j",
            "1",
            "-o",
            str(out),
            "--json",
            "--quiet",
            "--samples",
            "64",
            "--max-iter",
            "1",
            "--omega",
            "0.01:1000:8",
            "--mc",
            "5",
            "--true-robots",
            "2",
        ]
    )
    status = args.func(args)
    assert status == 1  # one robot failed; the other ran
    doc = json.loads(capsys.readouterr().out)
    assert doc["total"] == 2 and doc["done"] == 2 and doc["failed"] == 1
    assert doc["executor"] == "this process"
    assert doc["settings"]["synthesis"] == {"structure": "full", "max_iter": 1}
    rows = {r["name"]: r for r in doc["rows"]}
    assert rows[MISSING]["error"] == "RobotError" and rows["pendulum_a"]["ok"]
    a = rows["pendulum_a"]
    assert a["certified"] is (a["status"] == "CERTIFIED") and STATUS_WORD[a["status"]] in a["verdict"]
    assert doc["certified"] == int(a["certified"])
    # the validation at the rate on 2 drawn true robots: a step and the task's trajectory on each
    at_rate = a["validation_at_rate"]
    assert [at_rate["by_reference"][k]["runs"] for k in ("step", "trajectory")] == [2, 2]
    assert "a simulation, not a certificate" in at_rate["verdict"] and isinstance(at_rate["meets_bar"], bool)
    cert = json.loads((out / "pendulum_a" / "certificate.json").read_text())
    assert cert["row"] == rows["pendulum_a"]
    # traceability: the URDF's bytes hashed, in the certificate and the controller file (polyrob.provenance)
    urdf_sha256 = hashlib.sha256(Path(pendulums[0]).read_bytes()).hexdigest()
    assert cert["provenance"]["urdf_sha256"] == urdf_sha256
    assert json.loads((out / "pendulum_a" / "controller.json").read_text())["provenance"]["urdf_sha256"] == urdf_sha256
    K = load_controller(out / "pendulum_a" / "controller.json")
    assert np.asarray(K.A).shape == (rows["pendulum_a"]["order"],) * 2
    assert json.loads((out / MISSING / "certificate.json").read_text())["row"]["ok"] is False
    md = (out / "summary.md").read_text()
    assert "| pendulum_a | 1 |" in md and "FAILED: RobotError" in md
    assert json.loads((out / "summary.json").read_text())["rows"] == doc["rows"]


def test_cli_batch_registered_in_main_when_integrated(capsys):
    from polyrob.cli import main

    try:
        status = main(["batch", "--json", "--quiet", MISSING, "--no-analysis", "--no-validate"])
    except SystemExit as exc:  # argparse's exit on an unknown command
        status = exc.code
    err = capsys.readouterr()
    assert status == 1, err.err  # 2 with "invalid choice: 'batch'" if batch is not registered
    assert json.loads(err.out)["rows"][0]["error"] == "RobotError"


def test_bandwidth_search_certifies_at_the_found_factor(pendulums):
    settings = Settings(**dict(FAST, synthesis={"max_iter": 2}), search_bandwidth=True, alphas=(1.0, 2.0, 4.0, 8.0))
    r = run_job(Job(robot=pendulums[0]), settings)
    assert r.ok, r.message
    hist = r.certificate["bandwidth_scaling"]["history"]
    # the search's own evidence: the factor returned is the largest tried with mu < 1
    assert r.alpha == max(a for a, mu in hist if mu < 1)
    # the analysis ran on the scaled weights: the weights recorded are the base ones times alpha
    base = automatic_hyperparameters(1, None)
    assert r.problem["weights"]["omega_b"][0] != base["omega_b"][0]
    _row_agrees(r)


# --------------------------------------------------------------------------- executor mechanics


def test_local_pool_yields_every_result_with_its_index():
    got = {i: (ok, v) for i, ok, v in LocalExecutor(2).run(pow, [(2, 3), (3, 2), (5, 1)])}
    assert got == {0: (True, 8), 1: (True, 9), 2: (True, 5)}


def test_local_pool_reports_a_dead_worker_instead_of_raising():
    import os
    from concurrent.futures.process import BrokenProcessPool

    got = list(LocalExecutor(2).run(os._exit, [(3,), (3,)]))
    assert sorted(i for i, _, _ in got) == [0, 1]
    assert all(not ok and isinstance(v, BrokenProcessPool) for _, ok, v in got)


def test_local_pool_stops_running_workers_at_once_on_interrupt():
    import multiprocessing

    # Children that other tests left (e.g. a timed AB13MD worker) are not this pool's.
    before = {p.pid for p in multiprocessing.active_children()}
    gen = LocalExecutor(2).run(time.sleep, [(0.01,), (600.0,), (600.0,)])
    assert next(gen)[0] == 0
    t0 = time.perf_counter()
    workers = [p for p in multiprocessing.active_children() if p.is_alive() and p.pid not in before]
    assert workers
    with pytest.raises(KeyboardInterrupt):
        gen.throw(KeyboardInterrupt)
    assert time.perf_counter() - t0 < 300  # not a timing: the workers sleep 600 s unless stopped
    # the OS's view: Process.is_alive can lag when the executor's thread reaps a worker
    alive = [p for p in workers if process_running(p.pid)]
    assert not alive, f"pool workers still running: {alive}"


# --------------------------------------------------------------------------- weights and jobs


def test_automatic_weights_are_the_papers_for_two_joints_on_its_domain():
    import polyrob
    from polyrob.domains.torque_box import Domain

    robot = polyrob.load_robot("paper_2r")
    domain = Domain.from_robot(robot, "paper")
    assert domain_level(domain) == pytest.approx(1.0, rel=1e-12)
    h = automatic_hyperparameters(2, domain)
    for key, paper in PAPER_HYPERPARAMETERS.items():
        assert h[key] == pytest.approx(paper, rel=1e-12)


def test_automatic_weights_shape_over_seven_joints_and_domain_level():
    h = automatic_hyperparameters(7)
    wb = np.array(h["omega_b"])
    assert wb[0] == 0.5 and wb[-1] == 0.1
    # geometric steps: constant ratio (0.1/0.5)^(1/6)
    np.testing.assert_allclose(wb[1:] / wb[:-1], 0.2 ** (1 / 6), rtol=1e-12)
    assert h["M_s"][0] == 2.0 and h["M_s"][-1] == 3.0 and all(len(v) == 7 for v in h.values())
    assert automatic_hyperparameters(1)["omega_b"] == (0.5,)
    # a domain twice as fast relative to its range (every joint) doubles both bandwidths
    from types import SimpleNamespace

    paper = {
        "q": {"a": [-math.pi, math.pi], "b": [-math.pi, math.pi]},
        "qdot": {"a": [-3.9564, 3.9564], "b": [-9.9561, 9.9561]},
    }
    fast = {"q": paper["q"], "qdot": {k: [2 * lo, 2 * hi] for k, (lo, hi) in paper["qdot"].items()}}
    h2 = automatic_hyperparameters(2, SimpleNamespace(to_dict=lambda: fast))
    assert h2["omega_b"] == pytest.approx((1.0, 0.2)) and h2["omega_bt"] == pytest.approx((20.0, 24.0))
    assert h2["M_s"] == (2.0, 3.0)
    # overrides win, unlevelled
    assert automatic_hyperparameters(2, SimpleNamespace(to_dict=lambda: fast), {"omega_b": [0.3]})["omega_b"] == (
        0.3,
        0.3,
    )


def test_jobs_get_unique_names_and_bad_options_are_refused(pendulums):
    from polyrob.errors import ArgumentError

    res = run_batch([MISSING, MISSING, {"robot": MISSING, "label": "third"}], progress=False)
    assert [r.name for r in res.results] == [MISSING, f"{MISSING}#2", "third"]
    with pytest.raises(ArgumentError):
        run_batch([Job(robot="a", label="x"), Job(robot="b", label="x")])
    with pytest.raises(ArgumentError):
        run_batch([MISSING], no_such_option=1)
    with pytest.raises(ArgumentError):
        run_batch([{"robot": "a", "colour": "red"}])
    assert Job(robot=pendulums[0]).name == "pendulum_a"


def test_cli_jobs_from_all_serial_and_a_jobs_file(tmp_path):
    from polyrob.cli import PolyrobParser
    from polyrob.cli import batch as batch_cli
    from polyrob.errors import ArgumentError
    from polyrob.fleet import SERIAL_ARMS, serial_arms

    parser = PolyrobParser(prog="polyrob")
    batch_cli.register(parser.add_subparsers(dest="command", required=True, parser_class=PolyrobParser))
    jobs_file = tmp_path / "jobs.json"
    jobs_file.write_text(json.dumps(["planar_2r", {"robot": "paper_2r", "domain": "paper", "label": "paper"}]))
    args = parser.parse_args(["batch", "--all-serial", "--jobs", str(jobs_file), "--qdot-max", "2", "--paper-weights"])
    jobs = batch_cli.jobs_from_args(args)
    # every serial arm once (those installed), then the file's jobs; command-line domain options on each
    assert [j["robot"] for j in jobs] == [*serial_arms(), "planar_2r", "paper_2r"]
    assert set(serial_arms()) <= set(SERIAL_ARMS) and "panda" in serial_arms()
    assert all(j["qdot_max"] == 2.0 and j["auto_weights"] is False for j in jobs)
    assert jobs[-1]["domain"] == "paper" and jobs[-1]["label"] == "paper"
    with pytest.raises(ArgumentError):
        batch_cli.jobs_from_args(parser.parse_args(["batch"]))
    jobs_file.write_text("{}")
    with pytest.raises(ArgumentError):
        batch_cli.jobs_from_args(parser.parse_args(["batch", "--jobs", str(jobs_file)]))


def test_the_reason_why_not_names_the_performance_limit_when_it_excludes_mu_below_one():
    """paper_2r at a quarter of the paper's bandwidths: its 7.5 rad/s pole puts the floor above 1."""
    import polyrob
    from polyrob.fleet.diagnosis import why_not_certified
    from polyrob.pipeline import build_problem, default_hyperparameters

    robot = polyrob.load_robot("paper_2r")
    domain = polyrob.Domain.from_robot(robot, "paper")
    slow = build_problem(
        robot,
        domain,
        hyperparameters=default_hyperparameters(2, bandwidth_scale=0.25),
        progress=False,
        bound_options={"samples": 256, "coverage": 0},
    )
    details = {}
    reason = why_not_certified(slow, details)
    assert reason.startswith("performance limit") and details["performance_limit"]["bound"] >= 1
    assert details["input_definiteness"]["fraction"] == 0.0 and "not positive definite" not in reason
    # at the paper's bandwidths the floor (0.65) excludes nothing and the tight model keeps M^-1 definite
    paper = build_problem(robot, domain, progress=False, bound_options={"samples": 256, "coverage": 0})
    assert why_not_certified(paper, {}).startswith("mu >= 1 is the synthesis' best")
    # mu < 1 on the grid but no certificate (kinova's inner-gain model covered 0.16 of its fresh Jacobians):
    # the certificate's own reason, not "mu >= 1" (the row said that of mu 0.75)
    from types import SimpleNamespace

    gap = SimpleNamespace(
        mu_upper_grid=0.74, reasons=("the 'inner-gain' model contains only 0.1585 of 2000 fresh Jacobians",)
    )
    assert why_not_certified(paper, {}, gap) == gap.reasons[0]
    assert why_not_certified(paper, {}, SimpleNamespace(mu_upper_grid=1.2, reasons=("x",))).startswith("mu >= 1")


def test_the_bandwidth_search_is_skipped_when_the_model_reverses_inputs(pendulums, monkeypatch):
    """No bandwidth can certify a model whose B = M^-1 loses definiteness: one synthesis, and the row says so."""
    import polyrob.plant.coverage as coverage

    monkeypatch.setattr(
        coverage,
        "input_definiteness",
        lambda unc, *a, **k: {"fraction": 0.5, "least": -1.0, "centre": 1.0, "samples": 2},
    )
    settings = Settings(**dict(FAST, synthesis={"max_iter": 2}), search_bandwidth=True, alphas=(1.0, 2.0))
    r = run_job(Job(robot=pendulums[0]), settings)
    assert r.ok, r.message
    assert r.alpha is None and "bandwidth_scaling" not in r.certificate
    assert r.details["bandwidth_search"].startswith("bandwidth search skipped: 50 %")
    _row_agrees(r)
    # nor do the analysis sweeps run: the synthesis certificate is the row's figure
    assert "analysis" not in r.timings and r.details["analysis"].startswith("skipped: 50 %")
    # the pendulum certifies at its base weights (mu < 1): no reason then; otherwise the reason names the skip
    assert (r.reason is None) if r.certified else ("(bandwidth search skipped)" in r.reason)


def test_a_certified_controller_is_reduced_while_mu_stays_below_one(pendulums):
    def job(order):
        settings = Settings(
            **dict(FAST, synthesis={"max_iter": 2}), search_bandwidth=True, alphas=(4.0, 8.0), reduce_max_order=order
        )
        return run_job(Job(robot=pendulums[0]), settings)

    r = job(4)  # the full-order controller has 8 states; 4 keep mu < 1
    assert r.ok and r.certified and "reduction" in r.timings, (r.message, r.mu_upper)
    assert _row_agrees(r)["status"] == "CERTIFIED"
    assert r.certificate["structure"] == f"reduced:{r.order}" and r.order <= 4 < r.certificate["full_order"]
    assert r.mu_upper < 1 and r.certificate["full_peak_mu_upper"] < 1
    kept = job(1)  # one state is not enough: the full-order controller stays, and the row says why
    assert kept.certified and kept.order == kept.certificate["order"] == 8
    assert _row_agrees(kept)["status"] == "CERTIFIED"
    assert kept.details["reduction"].startswith("kept order 8: ")


def test_cli_validation_and_reduction_options_reach_the_settings():
    from polyrob.cli import PolyrobParser
    from polyrob.cli import batch as batch_cli

    parser = PolyrobParser(prog="polyrob")
    batch_cli.register(parser.add_subparsers(dest="command", required=True, parser_class=PolyrobParser))
    defaults = batch_cli.settings_from_args(parser.parse_args(["batch", "planar_2r"]))
    assert {k: defaults[k] for k in ("validate_move", "validate_budget", "reduce_max_order")} == {
        "validate_move": Settings().validate_move,
        "validate_budget": Settings().validate_budget,
        "reduce_max_order": Settings().reduce_max_order,
    }
    args = ["batch", "planar_2r", "--validate-move", "0", "--validate-budget", "30", "--reduce-max-order", "0"]
    given = batch_cli.settings_from_args(parser.parse_args(args))
    assert (given["validate_move"], given["validate_budget"], given["reduce_max_order"]) == (0.0, 30.0, None)
    Settings(**given)  # every key is a field


def test_cli_certify_reaches_every_job_s_bounds_and_max_boxes_needs_it():
    """`batch --certify` proves each job's bounds (an arm's factor ranges to its work limit); a row then says
    "certified" where its certificate rests on them (`polyrob batch finger_edu --certify --max-boxes 4`)."""
    from polyrob.cli import PolyrobParser
    from polyrob.cli import batch as batch_cli
    from polyrob.errors import ArgumentError

    parser = PolyrobParser(prog="polyrob")
    batch_cli.register(parser.add_subparsers(dest="command", required=True, parser_class=PolyrobParser))
    given = batch_cli.settings_from_args(parser.parse_args(["batch", "ur5", "--certify", "--max-boxes", "64"]))
    assert given["bound_options"] == {"certify": True, "certify_options": {"max_boxes": 64}}
    assert batch_cli.settings_from_args(parser.parse_args(["batch", "ur5"]))["bound_options"] == {}
    with pytest.raises(ArgumentError, match="--max-boxes sets the interval-arithmetic proof: use it with --certify"):
        batch_cli.settings_from_args(parser.parse_args(["batch", "ur5", "--max-boxes", "64"]))
    Settings(**given)


def test_a_task_job_with_an_inner_layer_says_domain_inner_layer_and_reflected_inertia(pendulums):
    job = Job(robot=pendulums[0], q_radius=0.2, qdot_max=0.5, qddot_max=1.0, inner="gravity", model_error=0.1)
    r = run_job(job, Settings(**dict(FAST, validate=False, analyze=False)))
    assert r.ok, r.message
    row = r.row()
    assert row["domain"].startswith("task around") and "qddot ±1" in row["domain"]
    assert row["inner"].startswith("inner layer: gravity") and "±10 %" in row["inner"]
    assert row["reflected_inertia"].startswith("not modelled")
    assert r.problem["domain"]["kind"] == "task" and "inner" in r.problem
    # without a domain field a one-joint robot keeps the torque box and no inner layer
    bare = run_job(Job(robot=pendulums[0]), Settings(**dict(FAST, validate=False, analyze=False)))
    assert bare.row()["inner"] == "none" and not bare.row()["domain"].startswith("task")


def test_the_robots_with_the_most_work_start_first_and_rows_keep_their_order():
    """Longest-first scheduling (the batch of every serial arm went past 30 min with xarm7 and panda started
    last, then with planar_2r's D-K search started last); a robot that does not load counts as 0 and fails
    in its own job."""
    from polyrob.fleet.batch import DK_SEARCH_WORK_PER_JOINT, longest_first
    from polyrob.fleet.jobs import Settings, as_job

    jobs = [as_job(x) for x in ("planar_2r", "ur5", "no_such_robot", "so101", "TwoDofs")]
    assert longest_first(jobs) == [1, 3, 0, 4, 2]  # joints: 6, 5, 2, 2, 0
    # a bandwidth search: the 2-joint torque boxes search with D-K (2 x 3 = 6), the arms a PID per factor
    assert DK_SEARCH_WORK_PER_JOINT == 3
    assert longest_first(jobs, Settings(search_bandwidth=True)) == [0, 1, 4, 3, 2]


def test_the_batch_search_bisects_to_its_own_tolerance_and_time_limit(monkeypatch):
    """A batch wants each robot's bandwidth factor to 25 %, not to the 5 % of synth --max-bandwidth."""
    from types import SimpleNamespace

    import polyrob.pipeline
    from polyrob.fleet import stages
    from polyrob.fleet.jobs import Settings

    seen = {}

    def search(problem, **kwargs):
        seen.update(kwargs)
        raise RuntimeError("stop here")

    monkeypatch.setattr(polyrob.pipeline, "design_max_bandwidth", search)
    monkeypatch.setattr(stages, "search_skipped", lambda problem, details: None)
    with pytest.raises(RuntimeError, match="stop here"):
        stages.design_stage(SimpleNamespace(), Settings(search_bandwidth=True), {}, {})
    # the search is bounded by its factors and its bisection: no wall-clock limit unless the user sets one
    assert seen["rtol"] == 0.25 and seen["search_time_limit"] is None
    assert Settings().validate_budget is None and Settings().validate_evaluations >= 10**6


def test_the_batch_noise_weight_uses_the_validation_encoder(monkeypatch):
    """`batch --encoder-bits 12`: the weights' encoder noise is 12-bit too (before: always 18 bits)."""
    import polyrob.fleet.autoweights as autoweights
    from polyrob.fleet.jobs import Job, Settings, _problem

    seen = {}

    class Stop(Exception):
        pass

    def fake(m, domain, overrides=None, *, robot=None, encoder_bits=None):
        seen["bits"] = encoder_bits
        raise Stop

    monkeypatch.setattr(autoweights, "automatic_hyperparameters", fake)
    for at_rate, bits in (({"encoder_bits": 12, "rate": 1000.0}, 12), ({}, None)):
        with pytest.raises(Stop):
            _problem(Job(robot="planar_2r"), Settings(at_rate=at_rate), {})
        assert seen["bits"] == bits


def test_the_summary_table_has_the_validation_at_the_rate():
    """summary.md had no column for the validation at the rate (only the JSON rows had it)."""
    from polyrob.fleet.outputs import markdown_table

    row = {"robot": "ur5", "ok": True, "status": "CERTIFIED", "validation": "settles"}
    verdict = "1000 Hz, one sample of delay: 20 of 20 settle; chatter <= 5 %: yes"
    lines = markdown_table([dict(row, validation_at_rate={"verdict": verdict}), row]).splitlines()
    assert lines[0].endswith("| validation | validation at the rate |")
    assert lines[2].endswith(f"| settles | {verdict} |") and lines[3].endswith("| settles | - |")


def test_the_moving_robot_certificate_is_a_column_and_decides_the_row(pendulums, monkeypatch):
    """`batch --moving`: each row carries the moving-robot certificate; once computed it decides `certified`.

    Four runs of one job: the frozen stages at their cheapest (bounds sampled without local refinement, no
    analysis: the design's certificate is the row's frozen status), the moving-robot stage computed in the first."""
    import polyrob.fleet.jobs as jobs
    from polyrob.fleet.outputs import markdown_table

    bounds = {"samples": 16, "refine": False, "screen": 0, "verify_rounds": 0}
    fast = dict(FAST, bound_options=bounds, validate=False, analyze=False)
    job = Job(robot=pendulums[0], q_radius=0.2, qdot_max=0.5, qddot_max=1.0, inner="computed-torque", model_error=0.1)
    r = run_job(job, Settings(**fast, moving=True))
    assert r.ok, r.message
    row = r.row()
    assert r.model == "inner-gain" and row["moving"]["computed"]  # the masses constant, the state at any rate
    assert "at any rate" in r.details["moving"]["verdict"] or "any rate" in str(r.details["moving"]["scope"])
    assert row["certified"] == (row["status"] == "CERTIFIED" and row["moving"]["certified"])
    assert "| moving robot |" in markdown_table([row]).splitlines()[0]
    # a frozen certificate with a moving one that does not hold: the row is not certified
    refused = {"computed": True, "certified": False, "status": "NOT_CERTIFIED", "gamma": 1.3, "verdict": "stub"}
    monkeypatch.setattr(jobs, "moving_stage", lambda problem, K, scalings=None: dict(refused))
    r2 = run_job(job, Settings(**fast, moving=True))
    assert r2.status == "CERTIFIED" and not r2.certified and r2.row()["certified"] is False
    assert "NOT_CERTIFIED (1.3 on its grid)" in markdown_table([r2.row()])  # no bound: its test's grid figure
    # a moving-robot test that cannot run is said in the row, which keeps its frozen certificate
    from polyrob.errors import SolverError

    def broken(problem, K, scalings=None):
        raise SolverError("the LMI solver gave up (a stand-in)")

    monkeypatch.setattr(jobs, "moving_stage", broken)
    r4 = run_job(job, Settings(**fast, moving=True))
    assert r4.ok and r4.moving["computed"] is False and r4.certified == (r4.status == "CERTIFIED")
    assert r4.moving["verdict"] == "moving robot: not computed: SolverError: the LMI solver gave up (a stand-in)"
    assert "not computed" in markdown_table([r4.row()])
    # not asked: no column value, and the row is the frozen certificate's
    r3 = run_job(job, Settings(**fast))
    assert r3.moving is None and r3.certified == (r3.status == "CERTIFIED")


def test_the_batch_tunes_for_the_moving_robot_and_checks_the_tuned_pid(pendulums):
    """`batch --tune-moving N`: the row's PID is the tuned one, its frozen certificate made anew, and the moving-robot
    stage runs on it from the tuning's scalings; a model with no constants keeps its design and says why."""
    from polyrob.analysis.lpv.constant import constant_parameter_certificate
    from polyrob.fleet.jobs import _problem
    from polyrob.fleet.results import controller_system

    bounds = {"samples": 16, "refine": False, "screen": 0, "verify_rounds": 0}
    fast = dict(FAST, bound_options=bounds, validate=False, analyze=False)
    job = Job(robot=pendulums[0], q_radius=0.2, qdot_max=0.5, qddot_max=1.0, inner="computed-torque", model_error=0.1)
    plain = run_job(job, Settings(**fast))
    tuned = run_job(job, Settings(**fast, tune_moving=1))
    assert plain.ok and tuned.ok, (plain.message, tuned.message)
    tuning = tuned.details["moving_tuning"]
    assert len(tuning["history"]) == 1 and len(tuning["scalings"]) >= 1 and tuned.moving["computed"]
    assert "moving-robot tuning" in tuned.timings
    K_plain, K_tuned = controller_system(plain.controller), controller_system(tuned.controller)
    assert not np.allclose(np.asarray(K_plain.D), np.asarray(K_tuned.D))  # the row carries the tuned PID
    # the row's moving figure is the tuned PID's, and no worse than the untuned PID's on the same problem
    problem = _problem(job, Settings(**fast), {})
    before = constant_parameter_certificate(problem, K_plain, search=True)
    assert tuned.moving["gamma"] <= before.gamma * 1.001
    assert tuned.row()["certified"] == (tuned.status == "CERTIFIED" and tuned.moving["certified"])
    # no model of constants (the robot bare, on its torque box): the design kept, the reason in the row
    bare = run_job(Job(robot=pendulums[0]), Settings(**fast, tune_moving=1))
    assert bare.ok and bare.details["moving_tuning"].startswith("not tuned: ")


def test_a_row_says_uncertainty_inner_layer_controller_and_bandwidth(pendulums, monkeypatch):
    """Issue 38's fleet table: robot, uncertainty, inner layer, frozen mu, moving robot, controller, bandwidth, time.

    The bandwidth is the nominal loop's crossover of the row's own controller; a job whose synthesis fails
    after its problem was built keeps what the problem says (before, such a row was all dashes)."""
    import polyrob.fleet.jobs as jobs
    from polyrob.errors import SynthesisError
    from polyrob.fleet.jobs import _problem
    from polyrob.fleet.outputs import markdown_table
    from polyrob.fleet.results import controller_system
    from polyrob.synthesis.bandwidth_stop import loop_crossover

    bounds = {"samples": 16, "refine": False, "screen": 0, "verify_rounds": 0}
    fast = dict(FAST, bound_options=bounds, validate=False, analyze=False)
    job = Job(robot=pendulums[0], q_radius=0.2, qdot_max=0.5, qddot_max=1.0, inner="computed-torque", model_error=0.1)
    r = run_job(job, Settings(**fast))
    assert r.ok, r.message
    row = r.row()
    assert (
        row["inner_layer"] == "computed-torque" and row["uncertainty"] == "links ±10 % (all by one factor); no payload"
    )
    assert row["structure"] == "pid"  # the arms' computed-torque loops start from (and keep) the tuned PID
    problem = _problem(job, Settings(**fast), {})
    assert row["bandwidth"] == pytest.approx(loop_crossover(problem.P, controller_system(r.controller)), rel=1e-9)
    assert 0 < row["bandwidth"] < math.inf
    header, _, line = markdown_table([row]).splitlines()
    for title in (
        "uncertainty",
        "inner layer",
        "mu bound",
        "moving robot",
        "controller",
        "bandwidth (rad/s)",
        "time (s)",
    ):
        assert f"| {title} |" in header
    assert "| computed-torque |" in line and "| per-joint PID |" in line and f"| {row['bandwidth']:.4g} |" in line
    # without an inner layer: no parameter set is stated (the model is the domain's Jacobians)
    bare = run_job(Job(robot=pendulums[0]), Settings(**fast)).row()
    assert bare["inner_layer"] == "none" and bare["uncertainty"] is None

    def fails(problem, settings, timings, details):
        raise SynthesisError("no bandwidth factor certifies (a stand-in)")

    monkeypatch.setattr(jobs, "design_stage", fails)
    lost = run_job(job, Settings(**fast)).row()
    assert not lost["ok"] and lost["error"] == "SynthesisError" and lost["order"] is None
    assert lost["uncertainty"] == row["uncertainty"] and lost["model"] == row["model"] and lost["joints"] == 1
    assert "| FAILED: SynthesisError: no bandwidth factor certifies (a stand-in) |" in markdown_table([lost])


def test_the_controller_cell_names_the_structure_and_order():
    from polyrob.fleet.outputs import controller_words, moving_words

    assert controller_words({"structure": "pid", "order": 2}) == "per-joint PID"
    assert controller_words({"structure": "full", "order": 14}) == "full, order 14"
    assert controller_words({"order": None}) is None
    assert moving_words(None) is None and moving_words({"computed": False}) == "not computed"
    assert (
        moving_words({"computed": True, "certified": True, "status": "CERTIFIED", "gamma": 0.91})
        == "CERTIFIED (<= 0.91)"
    )
    # a moving-robot test that does not hold gives no bound: finger_edu's read "NOT_CERTIFIED (<= 4.797)" before
    refused = {"computed": True, "certified": False, "status": "NOT_CERTIFIED", "gamma": 4.797}
    assert moving_words(refused) == "NOT_CERTIFIED (4.797 on its grid)"
