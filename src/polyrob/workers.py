"""The process layer every polyrob pool shares: spawned workers, their set-up, and how they end.

Two pools run polyrob's work in other processes:
:class:`polyrob.bounds.parallel.WorkerPool` (one per bound, the shared state
sent once) and :class:`polyrob.fleet.executors.LocalExecutor` (a
:class:`concurrent.futures.ProcessPoolExecutor` for a batch); the CLI's
Ctrl-C watchdog (:mod:`polyrob.cli.interrupt`) stops whatever children are
left.  What they have in common lives here, once:

* :func:`spawn_context`: workers are fresh interpreters (``spawn``), never
  forks (a forked child inherits locks held by BLAS threads and can block on
  a futex for ever).
* :func:`init_worker`: what a worker does first.  It ignores SIGINT (a
  terminal sends Ctrl-C to the whole process group; the parent handles it and
  stops the workers), keeps the default SIGTERM (a terminated worker ends at
  once, without a traceback), limits BLAS to one thread, also in the BLAS
  copies it loads later (many small problems: more threads only spin-wait,
  beside the other workers), and exits quietly as soon as its parent is
  gone (a parent killed by SIGTERM or SIGKILL runs no clean-up; an orphaned
  worker would finish its task and then print a BrokenPipeError traceback
  when it sends the result).
* :func:`stop_processes`: SIGTERM, a grace period, then SIGKILL.
* :func:`available_cores`: the default number of workers.

Nothing here switches module globals or ``os.environ`` of the parent.

Examples
--------
>>> available_cores() >= 1
True
>>> spawn_context().get_start_method()
'spawn'
"""

from __future__ import annotations

import os
import signal
import threading

__all__ = [
    "available_cores",
    "spawn_context",
    "init_worker",
    "stop_processes",
    "TERMINATE_GRACE",
    "EXIT_PARENT_GONE",
]

#: Seconds a terminated worker gets to exit before it is killed.
TERMINATE_GRACE = 2.0
#: Exit status of a worker that ended because its parent was gone.
EXIT_PARENT_GONE = 0
#: Seconds between checks of the parent, once its sentinel cannot tell any more.
_PARENT_POLL = 1.0


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def spawn_context():
    """The ``spawn`` multiprocessing context all polyrob pools start their workers with."""
    import multiprocessing

    return multiprocessing.get_context("spawn")


def init_worker() -> None:
    """Set up a worker process (a pool's ``initializer``, or the first call of a worker's main).

    SIGINT ignored, SIGTERM at its default (end now, quietly), BLAS limited to
    one thread, and a daemon thread that ends the process quietly when its
    parent is gone.
    """
    from polyrob._threads import single_blas_thread_for_life

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # even if the parent's SIGTERM was ignored
    single_blas_thread_for_life()  # also the BLAS copies the worker loads later
    _exit_with_parent()


def _exit_with_parent() -> None:
    """Start a thread that ends this (spawned) process when its parent is gone."""
    import multiprocessing

    parent = multiprocessing.parent_process()
    if parent is None:  # not a multiprocessing child: nothing to watch
        return
    ppid = os.getppid()
    threading.Thread(target=_watch_parent, args=(parent, ppid), name="polyrob-parent-watch", daemon=True).start()


def _watch_parent(parent, ppid: int) -> None:
    from multiprocessing.connection import wait

    # The sentinel (a pipe the parent holds) is ready at once when the parent exits; the
    # parent's pid check guards against the pipe closing while the parent lives on.
    try:
        wait([parent.sentinel])
    except (OSError, ValueError):  # no usable sentinel: poll only
        pass
    while os.getppid() == ppid:  # re-parented (to init or a subreaper): the parent is gone
        threading.Event().wait(_PARENT_POLL)
    os._exit(EXIT_PARENT_GONE)


def stop_processes(procs, grace: float = TERMINATE_GRACE, *, settle=None) -> None:
    """End processes now: SIGTERM to each live one, up to ``grace`` seconds each to exit, then SIGKILL.

    ``settle``, if given, is called between the SIGTERMs and the joins (the
    process pool executor's own thread reaps its workers and must finish
    first: ``Popen.poll`` is not thread-safe).
    """
    procs = list(procs)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    if settle is not None:
        settle()
    for proc in procs:
        proc.join(grace)
        if proc.is_alive():
            proc.kill()
            proc.join()
