"""The bounds stage's process model: spawned workers, errors relayed, Ctrl-C ends everything."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from conftest import default_sigint, describe_processes

from polyrob.bounds.parallel import WorkerPool
from polyrob.errors import BoundsError


def scaled(state, item):
    return state * item


def failing(state, item):
    if item == 3:
        raise ValueError(f"item {item} is bad")
    return item


def dying(state, item):
    os._exit(7)


def test_workers_compute_what_one_process_computes_and_relay_errors():
    items = list(range(20))
    with WorkerPool(3, workers=1) as serial:
        expected = serial.map(scaled, items)
    assert expected == [3 * i for i in items]
    with WorkerPool(3, workers=2) as pool:
        assert pool.map(scaled, items) == expected
        with pytest.raises(ValueError, match="item 3 is bad"):
            pool.map(failing, items)
        # the pool was stopped by the error; a new map starts it again
        assert pool.map(scaled, items) == expected
        with pytest.raises(BoundsError, match=r"worker process died \(exit code 7\)"):
            pool.map(dying, items)
        assert pool.fallback is None


def test_off_a_terminal_a_long_map_logs_its_progress_with_an_eta(monkeypatch):
    """tqdm prints nothing off a terminal: a pipe or a log file gets a line per interval instead."""
    import logging

    import polyrob.bounds.parallel as parallel

    class Lines(logging.Handler):
        def __init__(self):
            super().__init__(logging.INFO)
            self.lines = []

        def emit(self, record):
            self.lines.append(record.getMessage())

    log, handler = logging.getLogger("polyrob"), Lines()
    monkeypatch.setattr(parallel, "LOG_EVERY", 0.0)
    monkeypatch.setattr(log, "level", logging.INFO)  # as the CLI sets it without --quiet
    log.addHandler(handler)
    try:
        with WorkerPool(2, workers=1) as pool:
            assert pool.map(scaled, range(4), progress=False, label="bounding") == [0, 2, 4, 6]
        lines, handler.lines = handler.lines, []
        with WorkerPool(2, workers=1) as pool:
            pool.map(scaled, range(4), progress=True, label="bounding")  # the bar shows it: no lines
    finally:
        log.removeHandler(handler)
    assert len(lines) == 3 and lines[0].startswith("bounding: 1 of 4 tasks (25 %) in ") and "s left" in lines[0]
    assert handler.lines == []


def test_a_map_that_is_one_step_of_a_reporting_loop_leaves_the_job_s_line_to_it():
    """The factors' proof shares each batch of boxes between the workers: the map's own count (1 of 2 parts done)
    claimed the proof's whole span, so `analyze panda --certify` showed 36 % of the job from its first batch on,
    and logged 'tasks: 1 of 2' lines.  A map with ``own_progress=False`` neither moves the line nor logs."""
    import io

    from polyrob.progress import JobProgress, report, span

    job = JobProgress(["bounds"], stream=io.StringIO(), clock=lambda: 0.0).start()
    try:
        job._stop.set()  # no ticking thread: the share is read directly
        job.begin(1, "bounds")
        with span(0.0, 0.8), WorkerPool(2, workers=1) as pool:
            assert pool.map(scaled, range(2), own_progress=False) == [0, 2]
            assert job.share == 0.0
            report(0.25, 1.0)  # the loop's own fraction of work done
            assert job.share == pytest.approx(0.2)
            pool.map(scaled, range(2))  # a map that is the loop itself fills the span
            assert job.share == pytest.approx(0.8)
    finally:
        job.stop()


def test_a_state_that_cannot_be_pickled_runs_here_and_says_so():
    state = lambda: 2  # noqa: E731  (a closure cannot be sent to another process)
    with WorkerPool(state, workers=2) as pool:
        assert pool.map(lambda_free_call, [1, 2]) == [2, 4]
        assert "one process" in pool.fallback


def lambda_free_call(state, item):
    return state() * item


def _children(pid: int) -> set[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return {int(x) for x in path.read_text().split()} if path.exists() else set()


def _workers(pid: int) -> set[int]:
    """The spawned worker processes among ``pid``'s children (not multiprocessing's resource tracker)."""
    out = set()
    for child in _children(pid):
        try:
            cmdline = Path(f"/proc/{child}/cmdline").read_bytes()
        except OSError:
            continue
        if b"spawn_main" in cmdline:
            out.add(child)
    return out


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="reads child processes from /proc (Linux)")
@pytest.mark.timeout(180)  # 120 s for the workers to start, then 10 s for one SIGINT to end them
def test_one_sigint_ends_a_bound_and_its_workers_within_seconds(tmp_path):
    script = textwrap.dedent(
        """
        from polyrob import Domain, bound_pldi, load_robot
        robot = load_robot("planar_2r")
        # a screen of 2^24 points keeps two workers busy for minutes
        bound_pldi(robot, Domain.from_robot(robot), workers=2, screen=2**24, coverage=0, progress=False)
        """
    )
    # stderr to a file, not a pipe nobody reads before the end: a full pipe would block the writers
    err_file = (tmp_path / "stderr.txt").open("w")
    # SIGINT given back: launched from a shell without job control (two `.ci/run` suites) the child inherited
    # SIGINT ignored and sat in poll with both workers running 10 s after the SIGINT
    proc = subprocess.Popen([sys.executable, "-c", script], stderr=err_file, text=True, preexec_fn=default_sigint)
    try:
        deadline = time.monotonic() + 120
        workers: set[int] = set()
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            # the workers only: the resource tracker is a child too, and counting it sent the SIGINT
            # while the second worker was still being started (one CI run: not ended within 10 s)
            workers = _workers(proc.pid)
        assert len(workers) >= 2, "the bound never started its workers"
        time.sleep(3.0)  # let the workers load the robot and compute
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pytest.fail(f"one SIGINT did not end the bound within 10 s ({describe_processes(proc.pid)})")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        err_file.close()
    err = (tmp_path / "stderr.txt").read_text()
    assert proc.returncode != 0 and "KeyboardInterrupt" in err
    time.sleep(0.5)
    alive = [pid for pid in workers if Path(f"/proc/{pid}").exists() and "Z" not in _state(pid)]
    assert not alive, f"workers still running after Ctrl-C: {alive}"
    # one traceback, the parent's: the workers ignore SIGINT
    assert err.count("Traceback") == 1


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return "Z"


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="reads child processes from /proc (Linux)")
@pytest.mark.timeout(120)  # a worker that outlived its parent would sleep 60 s, then print a traceback
@pytest.mark.parametrize("how", [signal.SIGTERM, signal.SIGKILL])
def test_workers_whose_parent_died_exit_at_once_and_quietly(tmp_path, how):
    """Before: a parent killed by SIGTERM ran no clean-up; each worker finished its task and printed a
    BrokenPipeError traceback when it sent the result."""
    (tmp_path / "slow_tasks.py").write_text("import time\n\ndef slow(state, item):\n    time.sleep(60)\n")
    script = textwrap.dedent(
        f"""
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        from slow_tasks import slow
        from polyrob.bounds.parallel import WorkerPool
        with WorkerPool(0, workers=2) as pool:
            pool.map(slow, [1, 2, 3, 4])
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        workers: set[int] = set()
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            workers = _children(proc.pid)
        assert len(workers) >= 2, "the pool never started its workers"
        time.sleep(2.0)  # the workers are in their tasks
        proc.send_signal(how)
        assert proc.wait(timeout=10) == -how
        err = proc.stderr.read()  # returns once every holder of the pipe, the workers too, has exited
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert "Traceback" not in err, err
    time.sleep(0.5)  # a process that closed its files may still be exiting
    alive = [pid for pid in workers if Path(f"/proc/{pid}").exists() and "Z" not in _state(pid)]
    assert not alive, f"workers still running after their parent died: {alive}"
