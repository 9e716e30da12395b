"""The process model of the bounds stage: one spawn-safe pool of workers per bound.

:class:`WorkerPool` starts its worker processes with the ``spawn`` method
(fresh interpreters: no inherited locks or BLAS threads, the cause of forked
workers blocked on a futex after a Ctrl-C), sends each of them the shared,
read-only state once (the robot, the domain and the entry layout, pickled),
and then hands out tasks: a top-level function and a picklable item, called
as ``fn(state, item)``.  Nothing in the parent is switched at run time: no
module globals, no ``os.environ``.

Each worker talks to the parent over its own pipe, so the parent waits on
the pipes and on the workers' process sentinels together: a worker that dies
is an error at once, not a hang.  Workers are set up by
:func:`polyrob.workers.init_worker` (SIGINT ignored: a terminal sends it to
the whole process group; one BLAS thread; a quiet exit when the parent is
gone); on KeyboardInterrupt, or any other exception, the parent terminates
them and re-raises, so one Ctrl-C ends a bound within a second or so.

With one worker, or a state that cannot be pickled (an analytic robot built
from closures), the tasks run in the calling process; :attr:`WorkerPool.fallback`
then says why, and :func:`polyrob.bounds.pldi.bound_pldi` records it.

Examples
--------
>>> def scaled(state, item):
...     return state * item
>>> with WorkerPool(10, workers=1) as pool:
...     pool.map(scaled, [1, 2, 3])
[10, 20, 30]
"""

from __future__ import annotations

import logging
import pickle
import time
from collections import deque

from polyrob.errors import ArgumentError, BoundsError
from polyrob.workers import TERMINATE_GRACE, available_cores, init_worker, spawn_context, stop_processes

__all__ = ["WorkerPool", "available_cores"]

#: Seconds between two progress lines off a terminal (a report interval, not an algorithm switch).
LOG_EVERY = 15.0


class _Progress:
    """A tqdm bar on a terminal; off one (tqdm prints nothing there), a ``polyrob`` log line every :data:`LOG_EVERY` s.

    A bound of a six-joint arm takes minutes: a pipe or a log file must show that it advances, with an ETA.
    """

    def __init__(self, total: int, label: str, progress: bool, own: bool = True):
        from tqdm.auto import tqdm

        self.bar = tqdm(total=total, desc=label, disable=not progress, leave=False)
        self.total, self.label, self.done, self.log = total, label or "tasks", 0, own and not progress
        self.own = own
        self.t0 = self.last = time.perf_counter()

    def update(self) -> None:
        from polyrob.progress import report

        self.bar.update()
        self.done += 1
        if self.own:  # the whole job's progress line, when a command shows one
            report(self.done, self.total)
        now = time.perf_counter()
        if self.log and now - self.last >= LOG_EVERY and self.done < self.total:
            self.last = now
            left = (self.total - self.done) * (now - self.t0) / self.done
            logging.getLogger("polyrob").info(
                "%s: %d of %d tasks (%.0f %%) in %.0f s, about %.0f s left",
                self.label,
                self.done,
                self.total,
                100.0 * self.done / self.total,
                now - self.t0,
                left,
            )

    def close(self) -> None:
        self.bar.close()


def _worker_main(conn, payload: bytes) -> None:
    """A worker: load the shared state once, then run tasks until told to stop."""
    init_worker()
    state = pickle.loads(payload)
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            return
        if message is None:
            return
        index, fn, item = message
        try:
            reply = (index, True, fn(state, item))
        except Exception as exc:  # noqa: BLE001 - not swallowed: relayed to the parent, which raises it
            reply = (index, False, exc)
        try:
            conn.send(reply)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            conn.send((index, False, BoundsError(f"a worker's result cannot be sent back ({exc})")))
        except OSError:  # BrokenPipeError included: the parent is gone, nobody to tell
            return


def _died(proc) -> None:
    proc.join(TERMINATE_GRACE)
    raise BoundsError(
        f"a bounds worker process died (exit code {proc.exitcode}); run with workers=1 (-j 1) to see the "
        "error in this process (from a script: workers are spawned and import it, so keep its code under "
        "`if __name__ == '__main__':`)"
    )


def _send(proc, conn, message) -> None:
    try:
        conn.send(message)
    except (BrokenPipeError, ConnectionResetError, EOFError):
        _died(proc)


class WorkerPool:
    """Worker processes sharing one read-only state; a context manager.

    Parameters
    ----------
    state : object
        Passed as the first argument of every task; pickled once per worker.
    workers : int, optional
        Processes (default: the available cores).  With 1 the tasks run in
        the calling process.

    Attributes
    ----------
    fallback : str or None
        Why the tasks ran in the calling process although ``workers > 1``.
    """

    def __init__(self, state, workers: int | None = None):
        self.state = state
        self.workers = available_cores() if workers is None else int(workers)
        if self.workers < 1:
            raise ArgumentError(f"workers must be at least 1, got {workers}")
        self.fallback: str | None = None
        self._procs: list = []

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    # ------------------------------------------------------------------ running
    def map(self, fn, items, *, progress: bool = False, label: str = "", own_progress: bool = True) -> list:
        """``[fn(state, item) for item in items]``, on the workers when there are any.

        ``fn`` must be a module-level function (it is pickled by name).
        ``own_progress=False``: the items are parts of one step of a loop that
        reports its own progress (a batch of the factors' proof): the map
        neither moves the job's line nor logs its count.
        """
        items = list(items)
        bar = _Progress(len(items), label, progress, own_progress)
        try:
            if self.workers > 1 and len(items) > 1 and self._start():
                return self._map_workers(fn, items, bar)
            from polyrob._threads import single_blas_thread

            out = []
            with single_blas_thread():
                for item in items:
                    out.append(fn(self.state, item))
                    bar.update()
            return out
        finally:
            bar.close()

    def _map_workers(self, fn, items, bar) -> list:
        from multiprocessing.connection import wait

        results = [None] * len(items)
        pending = deque(enumerate(items))
        busy = {}
        try:
            for proc, conn in self._procs:
                if pending:
                    i, item = pending.popleft()
                    _send(proc, conn, (i, fn, item))
                    busy[conn] = proc
            sentinels = {proc.sentinel: proc for proc, _ in self._procs}
            while busy:
                for ready in wait(list(busy) + list(sentinels)):
                    if ready in sentinels:
                        _died(sentinels[ready])
                    if ready not in busy:
                        continue
                    try:
                        i, ok, value = ready.recv()
                    except (EOFError, OSError):  # the worker is gone: its exit code says how
                        _died(busy[ready])
                    if not ok:
                        raise value
                    results[i] = value
                    bar.update()
                    if pending:
                        j, item = pending.popleft()
                        _send(busy[ready], ready, (j, fn, item))
                    else:
                        del busy[ready]
        except BaseException:
            # KeyboardInterrupt included: stop the workers now, then re-raise
            self.terminate()
            raise
        return results

    # ------------------------------------------------------------------ lifetime
    def _start(self) -> bool:
        """Start the workers (once); False when the state cannot be sent to them."""
        if self._procs:
            return True
        if self.fallback is not None:
            return False
        try:
            payload = pickle.dumps(self.state)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            self.fallback = f"ran in one process: the robot cannot be sent to worker processes ({exc})"
            return False
        ctx = spawn_context()
        try:
            for _ in range(self.workers):
                parent, child = ctx.Pipe()
                proc = ctx.Process(target=_worker_main, args=(child, payload), daemon=True)
                proc.start()
                child.close()
                self._procs.append((proc, parent))
        except BaseException:
            self.terminate()
            raise
        return True

    def close(self) -> None:
        """Ask idle workers to exit, then make sure they did."""
        for _, conn in self._procs:
            try:
                conn.send(None)
            except (OSError, ValueError):  # already gone
                pass
        for proc, _ in self._procs:
            proc.join(TERMINATE_GRACE)
        self.terminate()

    def terminate(self) -> None:
        """Stop every worker now (SIGTERM, then SIGKILL after a grace period)."""
        procs, self._procs = self._procs, []
        stop_processes([proc for proc, _ in procs], TERMINATE_GRACE)
        for _, conn in procs:
            conn.close()
