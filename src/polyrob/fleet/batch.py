"""A fleet of robots through the pipeline: :func:`run_batch`.

Each job (a robot and its domain / weight options) runs bounds, automatic
weights, μ-synthesis (or the bandwidth search), μ analysis and a nonlinear
closed-loop check through :func:`polyrob.fleet.jobs.run_job`, in local worker
processes by default or on a Dask cluster (``scheduler``).  One robot's
failure is recorded (its error class and one-line message) and does not
stop the others; Ctrl-C cancels the queued robots and ends the workers.

Examples
--------
>>> from polyrob.fleet import run_batch
>>> res = run_batch(["no_such_robot"], progress=False)
>>> res.results[0].ok, res.results[0].error
(False, 'RobotError')
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from polyrob.errors import ArgumentError
from polyrob.fleet.jobs import RobotResult, Settings, as_job, run_job, with_label

__all__ = ["BatchResult", "run_batch", "SERIAL_ARMS"]

#: The serial arms ``polyrob batch --all-serial`` runs (bundled and example-robot-data names).
SERIAL_ARMS = (
    "planar_2r",
    "double_pendulum",
    "TwoDofs",
    "finger_edu",
    "so101",
    "ur5",
    "ur10",
    "kinova",
    "z1",
    "talos_left_arm",
    "panda",
    "xarm7",
)


@dataclass(frozen=True, eq=False)
class BatchResult:
    """What :func:`run_batch` did.

    Attributes
    ----------
    results : tuple of RobotResult
        One row per robot, in the order the jobs were given.
        In the order of the jobs.
    settings : Settings
    executor : str
        Where the jobs ran.
    seconds : float
        Wall-clock time of the batch.
    files : dict
        ``name -> {"certificate": path, "controller": path}`` and
        ``"summary" -> {"json", "markdown"}`` when ``out_dir`` was given.
    """

    results: tuple
    settings: Settings
    executor: str
    seconds: float
    files: dict

    @property
    def failed(self) -> tuple:
        return tuple(r for r in self.results if not r.ok)

    @property
    def certified(self) -> tuple:
        return tuple(r for r in self.results if r.ok and r.certified)

    def rows(self) -> list:
        return [r.row() for r in self.results]

    def summary(self) -> dict:
        """The summary document (also ``summary.json``)."""
        return _summary(self.results, len(self.results), self.settings, self.executor, self.seconds)

    def __getitem__(self, name: str) -> RobotResult:
        for r in self.results:
            if r.name == name:
                return r
        raise KeyError(name)


def _summary(results, total: int, settings: Settings, executor: str, seconds: float) -> dict:
    done = [r for r in results if r is not None]
    return {
        "format": "polyrob.batch/1",
        "executor": executor,
        "total": total,
        "done": len(done),
        "certified": sum(1 for r in done if r.ok and r.certified),
        "failed": sum(1 for r in done if not r.ok),
        "seconds": round(seconds, 2),
        "settings": settings.to_dict(),
        "rows": [r.row() for r in done],
    }


def _labelled(jobs) -> list:
    """Jobs with unique names: a robot given twice becomes ``robot``, ``robot#2``, ..."""
    out, seen = [], {}
    for job in (as_job(j) for j in jobs):
        if job.label is not None:
            if job.label in seen:
                raise ArgumentError(f"two jobs are labelled {job.label!r}: labels must be unique")
            seen[job.label] = 1
            out.append(job)
            continue
        n = seen.get(job.name, 0) + 1
        seen[job.name] = n
        out.append(job if n == 1 else with_label(job, f"{job.name}#{n}"))
    if not out:
        raise ArgumentError("a batch needs at least one robot")
    return out


def _settings(settings, options) -> Settings:
    if settings is not None and options:
        raise ArgumentError("give either settings or keyword options, not both")
    if settings is not None:
        return settings
    unknown = sorted(set(options) - set(Settings.__dataclass_fields__))
    if unknown:
        raise ArgumentError(f"unknown batch option(s) {unknown}; known: {sorted(Settings.__dataclass_fields__)}")
    if options.get("alphas") is not None:
        options["alphas"] = tuple(float(a) for a in options["alphas"])
    if options.get("omega") is not None:
        options["omega"] = tuple(options["omega"])
    return Settings(**options)


def _lost(job, exc: BaseException, where: str) -> RobotResult:
    """The failure row of a job whose worker did not return (it died, or the pool broke)."""
    text = " ".join(str(exc).split()) or "no message"
    return RobotResult(
        name=job.name,
        robot=str(job.robot),
        ok=False,
        error=type(exc).__name__,
        message=f"the worker did not return ({where}): {text}",
    )


def _progress_printer(progress):
    if callable(progress):
        return progress
    if not progress:
        return None
    import logging

    log = logging.getLogger(__name__)

    def show(result: RobotResult, done: int, total: int) -> None:
        if result.ok:
            what = f"{result.status}, mu peak on the grid {result.mu_upper_grid:.4g}, order {result.order}"
        else:
            what = f"FAILED: {result.error}: {result.message}"
        log.info(f"[{done}/{total}] {result.name}: {what} ({result.seconds:.1f} s)")

    return show


def run_batch(
    jobs, *, workers: int = 1, scheduler=None, out_dir=None, progress=None, settings: Settings | None = None, **options
) -> BatchResult:
    """Run the pipeline for many robots (and domain / weight variants), side by side.

    Parameters
    ----------
    jobs : iterable of str, dict or Job
        Robot names (``"panda"``), mappings of :class:`~polyrob.fleet.jobs.Job`
        fields (``{"robot": "paper_2r", "domain": "paper"}``) or jobs.  A robot
        given twice is named ``robot#2``.
    workers : int
        Local worker processes (spawned; 1: in this process).  Ignored with ``scheduler``.
    scheduler : str, distributed.Client or cluster, optional
        Run on this Dask distributed cluster instead.
    out_dir : str or Path, optional
        Write per robot a controller file and a JSON certificate, and
        ``summary.json`` / ``summary.md`` (see :mod:`polyrob.fleet.outputs`).
    progress : bool or callable, optional
        A line on stderr per finished robot (``True``), or
        ``progress(result, done, total)``.
    settings : Settings, optional
        Shared options; or give them as keyword ``options`` (the fields of
        :class:`~polyrob.fleet.jobs.Settings`: ``bound_options``,
        ``synthesis``, ``omega``, ``search_bandwidth``, ``alphas``,
        ``analyze``, ``mc``, ``validate``, ...).

    Returns
    -------
    BatchResult

    Raises
    ------
    ArgumentError
        Bad options, duplicate labels, an unreachable scheduler.  A robot's
        own failure is not raised: it is in its :class:`RobotResult`.
    KeyboardInterrupt
        After cancelling the queued robots and ending the workers.
    """
    from polyrob.fleet.executors import make_executor
    from polyrob.fleet.outputs import write_robot, write_summary

    jobs = _labelled(jobs)
    settings = _settings(settings, options)
    executor = make_executor(workers, scheduler)
    where = executor.describe()
    show = _progress_printer(progress)
    if out_dir is not None:
        from pathlib import Path

        from polyrob.io.paths import check_output_path

        out_dir = Path(out_dir)
        check_output_path(out_dir / "summary.json", "out_dir")
    results: list = [None] * len(jobs)
    files: dict = {}
    t0 = time.perf_counter()
    order = longest_first(jobs, settings)  # rows stay in the jobs' order; only the start order changes
    calls = [(jobs[i], settings) for i in order]
    for done, (k, ok, value) in enumerate(executor.run(run_job, calls), start=1):
        i = order[k]
        results[i] = result = value if ok else _lost(jobs[i], value, where)
        if out_dir is not None:
            files[result.name] = write_robot(out_dir, result)
            write_summary(out_dir, _summary(results, len(jobs), settings, where, time.perf_counter() - t0))
        if show is not None:
            show(result, done, len(jobs))
    seconds = time.perf_counter() - t0
    if out_dir is not None:
        files["summary"] = write_summary(out_dir, _summary(results, len(jobs), settings, where, seconds))
    return BatchResult(results=tuple(results), settings=settings, executor=where, seconds=seconds, files=files)


#: A D-K bandwidth search costs about this many times a PID search per joint: planar_2r's whole job took
#: 243-289 s, a 6-joint arm's (bounds and a tuned PID per factor) 232-367 s (docs/fleet.md, 2026-11-27).
DK_SEARCH_WORK_PER_JOINT = 3


def longest_first(jobs, settings: Settings | None = None) -> list:
    """Indices of ``jobs``, the longest expected first (ties in the given order).

    Longest-processing-time-first scheduling: the cost of a robot grows with
    its joints (bounds, μ sweeps), and starting the long ones first keeps a
    worker from taking a 7-joint arm last while the other idles.  A robot
    whose synthesis is D-K (no computed-torque inner layer) in a bandwidth
    search counts :data:`DK_SEARCH_WORK_PER_JOINT` times its joints (the
    second run of the batch of every serial arm had planar_2r start last and
    run alone).  A robot that does not load counts as 0 (it fails at once in
    its job).
    """
    from polyrob.fleet.jobs import job_robot_and_domain
    from polyrob.pipeline.design import starts_from_tuned_pid

    search = settings is not None and settings.search_bandwidth

    def work(job) -> int:
        try:
            robot = job_robot_and_domain(job)[0]
        except Exception:  # noqa: BLE001 - the job itself reports why the robot does not load
            return 0
        dk = not starts_from_tuned_pid(robot)
        return int(robot.m) * (DK_SEARCH_WORK_PER_JOINT if dk and search else 1)

    w = [work(job) for job in jobs]
    return sorted(range(len(jobs)), key=lambda i: -w[i])


def serial_arms() -> tuple:
    """:data:`SERIAL_ARMS` that this installation can load by name (others would fail as jobs)."""
    from polyrob.model.robots import available_robots

    names = {name for name, _ in available_robots()}
    return tuple(n for n in SERIAL_ARMS if n in names)
