"""Synthesis never runs silently, stops at its time limit, and does not start when the limit rules it out."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest
from conftest import paper_pldi

from polyrob.cli import main
from polyrob.errors import SynthesisError


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_problem_the_performance_limit_rules_out_stops_with_one_line(capsys):
    """TwoDofs' unstable pole (135 rad/s) puts every controller's mu above 4 at these weights."""
    code, out, _ = _run(capsys, "synth", "TwoDofs", "--json", "--quiet")
    doc = json.loads(out)
    assert code == 1 and doc["performance_limit"]["excludes_mu_below_one"]
    assert doc["verdict"].startswith("stopped: the performance limit proves mu >= ")
    assert "synthesis" not in doc  # nothing was synthesised


@pytest.mark.timeout(900)  # a hang guard; the time limit below runs on a fake clock
def test_fixed_structure_progress_off_a_terminal_and_its_time_limit(capsys, tmp_path, monkeypatch):
    """A line per iteration on stderr although stderr is not a terminal; no new iteration after --time-limit,
    and the output names the limit.  The clock moves 1 s per reading, so the limit fires after a few
    iterations of the first start, whatever the machine's load."""
    from clocks import FakeClock

    paper_pldi().save(tmp_path / "paper.json")
    argv = [
        "synth",
        "paper_2r",
        "--pldi",
        tmp_path / "paper.npz",
        "--uncertainty",
        "box",
        "--complex",
        "--structure",
        "tf3",
    ]
    FakeClock(step=1.0).install(monkeypatch)
    code, out, err = _run(capsys, *argv, "--init", "paper", "--starts", "2", "--max-iter", "40", "--time-limit", "10")
    monkeypatch.undo()
    assert "[fixed " in err and "peak mu" in err  # the library's progress lines, shown by the CLI
    stopped = re.search(r"stopped by the time limit of 10 s you set after (\d+) iteration", out)
    assert stopped and 1 <= int(stopped.group(1)) < 40, out
    assert code in (0, 1)
    # --quiet: no progress lines.  Only the iteration's lines matter here, so the run stops where its
    # certificate would start (the certificate's own sweep is what made this test the suite's slowest)
    import polyrob.synthesis.fixed.synthesis as fixed

    def no_certificate(*args, **kwargs):
        raise SynthesisError("stopped by the test before the certificate")

    monkeypatch.setattr(fixed, "certify_loop", no_certificate)
    code, out, err = _run(capsys, *argv, "--init", "paper", "--starts", "1", "--max-iter", "1", "--quiet")
    assert code != 0 and "stopped by the test" in out + err  # the iteration ran up to the certificate
    assert "[fixed " not in err


def test_run_into_a_place_for_no_results_names_the_file_it_would_write(capsys):
    code, _, err = _run(capsys, "run", "planar_2r", "-o", "/proc/polyrob_run")
    assert code == 2 and "K.json" in err and "controller.json" not in err


# ---- one progress line for the whole job (polyrob.progress), on a fake clock ----------------------------


def _job(titles, clock, **kw):
    import io

    from polyrob.progress import JobProgress

    out = io.StringIO()
    return JobProgress(titles, stream=out, clock=clock, **kw), out


def _lines(out):
    return [x for x in out.getvalue().splitlines() if x.startswith("progress: ")]


def test_off_a_terminal_a_line_at_least_every_30_s_with_stage_fraction_and_eta():
    """Before: progress restarted per phase ("refining 304 tasks (about 510 s left)" twice) and `synth` was
    silent for 5 min 20 s after "certificate of the PID start".  Now: stage k of n, a fraction of the whole
    job that never decreases, and a line at least every 30 s of (fake) time while a stage runs."""
    from clocks import FakeClock

    from polyrob.progress import report

    clock = FakeClock(now=0.0)
    job, out = _job(["bounds", "synthesis", "analysis", "validation"], clock)
    seen = []  # (time, stage, fraction) at each line
    plan = [(1, "bounds: ur5 (6 joints)", 120, 304), (2, "synthesis (full, then order reduction)", 540, 0),
            (3, "analysis: mu sweeps", 200, 0), (4, "validation and report into DIR", 60, 0)]  # fmt: skip
    job.start()  # the current job: the library's report() reaches it
    job._stop.set()  # no real-time ticks in a test: the test ticks on its clock
    try:
        for k, title, seconds, tasks in plan:
            job.begin(k, title)
            for s in range(seconds):
                clock.advance(1.0)
                if tasks:  # a library loop reports its tasks, twice over (two phases: it restarts)
                    report((s * 2 * tasks // seconds) % tasks + 1, tasks)
                before = len(_lines(out))
                job.tick()
                if len(_lines(out)) > before:
                    seen.append((clock.now, k, job.fraction))
    finally:
        job.stop()
    lines = _lines(out)
    times = [0.0] + [t for t, _, _ in seen] + [clock.now]
    assert max(b - a for a, b in zip(times, times[1:])) <= 30.0  # never silent for more than 30 s
    fractions = [f for _, _, f in seen]
    assert fractions == sorted(fractions) and 0 < fractions[0] and fractions[-1] < 1
    assert lines[0].startswith("progress: stage 1 of 4 (bounds), 0 % of the job")
    assert any(x.startswith("progress: stage 2 of 4 (synthesis), ") for x in lines)
    assert any(x.startswith("progress: stage 4 of 4 (validation and report), ") for x in lines)
    for x in lines[1:]:
        assert " elapsed, about " in x and x.endswith(" left"), x
    # the bounds stage's share comes from its tasks: 95 % of the stage at most, before the stage ends
    bounds_last = [f for _, k, f in seen if k == 1][-1]
    assert 0.1 < bounds_last <= 0.2 * 0.95 / (0.2 + 0.45 + 0.25 + 0.1) + 1e-12


def test_on_a_terminal_the_job_is_one_bar():
    from clocks import FakeClock

    clock = FakeClock(now=0.0)
    job, out = _job(["bounds", "synthesis"], clock, terminal=True)
    job.begin(1, "bounds: planar_2r")
    clock.advance(10.0)
    job.within(0.5)
    job.tick()
    job.begin(2, "synthesis (full)")
    job.stop()
    text = out.getvalue()
    assert "stage 1 of 2 (bounds)" in text and "stage 2 of 2 (synthesis)" in text and "|" in text
    assert not _lines(out)  # a bar, not lines


def test_synth_shows_the_job_progress_off_a_terminal_and_not_with_quiet(capsys):
    """TwoDofs stops after its bounds (the performance limit): the job's line says stage 1 of 2."""
    code, _, err = _run(capsys, "synth", "TwoDofs")
    assert code == 1 and "progress: stage 1 of 2 (bounds), 0 % of the job" in err
    from polyrob.progress import current

    assert current() is None  # the command's end stopped it
    code, _, err = _run(capsys, "synth", "TwoDofs", "--quiet")
    assert code == 1 and "progress:" not in err


def test_an_arm_s_proof_moves_the_bounds_job_s_progress_line(capsys, monkeypatch):
    """`bounds ur5 --certify` ran for minutes with no line off a terminal: now the job's line starts with the
    stage and the proof's share of work done feeds it (here three boxes of finger_edu's task, then the work
    limit, where the ranges proved by then are taken, said to be wider than the tolerance, and the work is kept)."""
    import polyrob.bounds.pldi as pldi_module
    from polyrob.progress import current

    seen = []

    def spy(done, total):
        seen.append((done, total, current() is not None))

    monkeypatch.setattr(pldi_module, "job_report", spy)
    code, out, err = _run(capsys, "bounds", "finger_edu", "--certify", "--max-boxes", "2")
    assert code == 0 and "progress: stage 1 of 2 (bounds), 0 % of the job" in err
    assert seen and all(inside for _, _, inside in seen)  # reported while the command's job runs
    # the line follows the work limit (1 box of 2, then 3): the proof's call ends there, its refinement unfinished
    assert [d for d, _, _ in seen] == [0.5, 1.0]
    assert current() is None  # the command's end stopped it
    stopped = re.search(r"stopped at its work limit with ([\d.]+) % of its refinement done", out)
    assert stopped and 0.0 < float(stopped.group(1)) < 50.0
    assert "the same command again goes on from there" in out
    # the work is kept (conftest: this test's own cache folder; test_factor_proof_checkpoints.py goes on from it)
    (kept,) = (Path(os.environ["POLYROB_CACHE_DIR"]) / "proofs").glob("factor-proof-*.npz")
    assert kept.stat().st_size > 0


def test_a_loop_in_another_thread_neither_moves_nor_narrows_the_job_s_line():
    """The span was one global: a loop left running in another thread (an in-process worker, an abandoned call)
    narrowed the job's span and moved its line (two .ci/run runs: a moving-robot certificate's cells all reported
    0.5, musyn's ITERATIONS_SHARE).  Now each thread has its own span and only the job's own thread reports."""
    import threading

    from clocks import FakeClock

    from polyrob.progress import report, span

    job, _ = _job(["moving-robot certificate"], FakeClock(now=0.0))
    job.start()
    job._stop.set()
    shares, within = [], job.within
    job.within = lambda share: (shares.append(share), within(share))[1]
    inside, leave = threading.Event(), threading.Event()

    def stray():  # another thread enters a span and reports while the job's thread is inside its own
        with span(0.5, 0.5):
            report(1, 2)
            inside.set()
            leave.wait(5.0)

    try:
        job.begin(1, "moving-robot certificate")
        other = threading.Thread(target=stray)
        with span(0.2, 0.4):
            other.start()
            inside.wait(5.0)
            report(1, 4)  # a quarter of this thread's part: 0.25
            leave.set()
            other.join(5.0)
            report(2, 4)
    finally:
        job.stop()
    assert shares == pytest.approx([0.25, 0.3, 0.4]), shares  # the stray thread's report and span end are not counted


def test_analyze_shows_the_job_progress_and_the_mu_sweep_moves_it(capsys, monkeypatch, tmp_path):
    """`analyze ur5 ...` ran 5-20 min with no line off a terminal (its stages had no job).  Now the job's line
    starts with the first stage, and the μ sweep's points and the intervals between them report into it."""
    import polyrob.analysis.mu.between as between
    import polyrob.analysis.mu.sweep as sweep
    from polyrob.progress import current

    seen = []

    def spy(module):
        real = module.report

        def reported(done, total):
            job = current()
            seen.append((module.__name__, done, total, job is not None and job.stage == 2))
            real(done, total)

        monkeypatch.setattr(module, "report", reported)

    spy(sweep), spy(between)
    paper_pldi().save(tmp_path / "paper.json")
    argv = ["analyze", "paper_2r", "--pldi", tmp_path / "paper.npz", "--controller", "paper", "--uncertainty", "box"]
    code, _, err = _run(capsys, *argv, "--mc", "20", "--omega", "0.1:100:8", "--no-time-varying", "--no-moving")
    assert code in (0, 1)
    assert "progress: stage 1 of 2 (reading the PLDI" in err  # the stage before the analysis: the PLDI given
    assert "progress: stage 2 of 2 (analysis" in err
    points = [(done, total) for name, done, total, _ in seen if name.endswith(".sweep")]
    assert points and max(done / total for done, total in points) == 1.0  # every grid point reported
    assert any(name.endswith(".between") for name, *_ in seen)  # the check between the points reports too
    assert all(inside for *_, inside in seen)  # inside the analysis stage of the command's job
    assert current() is None


def test_a_stage_of_rounds_weighs_its_rounds():
    """`synth --tune-moving 3` showed 5 minutes left when 15 remained: its tuning stage weighed what any other
    stage does (0.1), while each of its rounds takes about a synthesis' minutes on an arm."""
    from polyrob.progress import STAGE_WEIGHTS, JobProgress

    one = JobProgress._weight("tuning for the moving robot (up to 1 round")
    three = JobProgress._weight("tuning for the moving robot (up to 3 rounds: scalings, then the PID on mu)")
    assert one == STAGE_WEIGHTS["tuning"] and three == pytest.approx(3 * one)
    assert three > JobProgress._weight("synthesis (pid)") and JobProgress._weight("bounds: ur5") == 0.2
