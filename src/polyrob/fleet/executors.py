"""Where the jobs of a batch run: local worker processes, or a Dask distributed cluster.

Both executors take ``fn`` and its argument tuples and yield ``(index, ok,
value)`` as the calls finish, in completion order: ``ok`` False when the call
itself did not return (its worker process died, the pool broke, the cluster
lost it), and ``value`` is then the exception.  ``fn`` is a module-level
function (it is pickled by name), here :func:`polyrob.fleet.jobs.run_job`.

* :class:`LocalExecutor`: one :class:`concurrent.futures.ProcessPoolExecutor`
  with the ``spawn`` start method (fresh interpreters: nothing inherited, no
  forked locks).  Each worker is set up by :func:`polyrob.workers.init_worker`:
  it ignores SIGINT (the parent handles Ctrl-C, a terminal sends it to the
  whole process group), limits BLAS to one thread (threadpoolctl, and
  the OpenBLAS/OpenMP variables in the worker's own environment for the
  copies it loads later; the caller's is untouched) and exits quietly when
  the parent is gone.  On KeyboardInterrupt or any error the queued calls are cancelled and
  the workers terminated before the exception goes on.  With one worker the
  calls run in the calling process.
* :class:`DaskExecutor`: :class:`distributed.Client` on a scheduler address
  (or a given client / cluster object); the calls are cancelled on the
  cluster on KeyboardInterrupt.
"""

from __future__ import annotations

from polyrob.errors import ArgumentError
from polyrob.workers import init_worker, spawn_context, stop_processes

__all__ = ["LocalExecutor", "DaskExecutor", "make_executor"]


class LocalExecutor:
    """Calls in spawned worker processes on this machine.

    Parameters
    ----------
    workers : int
        Processes (>= 1); 1 runs the calls in this process.
    """

    kind = "local"

    def __init__(self, workers: int = 1):
        if int(workers) < 1:
            raise ArgumentError(f"workers must be at least 1, got {workers}")
        self.workers = int(workers)

    def describe(self) -> str:
        return f"{self.workers} local worker process(es)" if self.workers > 1 else "this process"

    def run(self, fn, calls):
        """Yield ``(index, ok, fn(*calls[index]) or its exception)`` as each call finishes."""
        calls = list(calls)
        if self.workers == 1 or len(calls) <= 1:
            for i, args in enumerate(calls):  # in this process: an exception is the caller's to see
                yield i, True, fn(*args)
            return
        yield from self._run_pool(fn, calls)

    def _run_pool(self, fn, calls):
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

        pool = ProcessPoolExecutor(
            max_workers=min(self.workers, len(calls)), mp_context=spawn_context(), initializer=init_worker
        )
        clean = False
        try:
            futures = {pool.submit(fn, *args): i for i, args in enumerate(calls)}
            pending = set(futures)
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    exc = fut.exception()
                    yield (futures[fut], False, exc) if exc is not None else (futures[fut], True, fut.result())
            clean = True
        finally:
            if clean:
                pool.shutdown(wait=True)
            else:  # Ctrl-C, a broken pool, or the consumer stopped: do not wait for running robots
                _terminate(pool)


def _terminate(pool) -> None:
    """Cancel what is queued and end the workers now (a running robot may take minutes)."""
    # The executor keeps its processes in ``_processes`` (pid -> Process); there is
    # no public way to stop a running call, and waiting would make Ctrl-C take minutes.
    procs = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    # The executor's own thread notices the dead workers and joins them too; a
    # process's Popen.poll is not thread-safe, so a join here can return while
    # that thread holds the exit status.  Let the thread finish first.
    stop_processes(procs, 2.0, settle=None if manager is None else lambda: manager.join(2.0))


class DaskExecutor:
    """Calls on a Dask distributed cluster.

    Parameters
    ----------
    scheduler : str or distributed.Client or cluster
        A scheduler address (``tcp://host:8786``), a client (used as is, not
        closed), or a cluster object such as ``distributed.LocalCluster``.
    """

    kind = "dask"

    def __init__(self, scheduler):
        self.scheduler = scheduler

    def describe(self) -> str:
        address = getattr(self.scheduler, "scheduler_address", None) or getattr(self.scheduler, "scheduler", None)
        return f"Dask scheduler {address or self.scheduler}"

    def _client(self):
        try:
            from distributed import Client
        except ImportError as exc:  # optional dependency
            raise ArgumentError(
                "a Dask scheduler needs the 'distributed' package: pip install 'dask[distributed]'"
            ) from exc
        if isinstance(self.scheduler, Client):
            return self.scheduler, False
        try:
            return Client(self.scheduler, timeout="20s"), True
        except OSError as exc:  # unreachable address, refused connection, timeout
            raise ArgumentError(f"cannot reach the Dask scheduler {self.scheduler}: {exc}") from exc

    def run(self, fn, calls):
        """Yield ``(index, ok, fn(*calls[index]) or its exception)`` as each call finishes on the cluster."""
        from distributed import as_completed

        client, owned = self._client()
        futures = []
        clean = False
        try:
            futures = [
                client.submit(fn, *args, pure=False, key=f"polyrob-fleet-{i}-{id(self)}")
                for i, args in enumerate(calls)
            ]
            index = {fut.key: i for i, fut in enumerate(futures)}
            for fut in as_completed(futures):
                if fut.status == "finished":
                    yield index[fut.key], True, fut.result()
                else:  # erred (e.g. KilledWorker) or cancelled by someone else
                    yield (
                        index[fut.key],
                        False,
                        fut.exception()
                        if fut.status == "error"
                        else RuntimeError(f"the cluster reports the call {fut.status}"),
                    )
            clean = True
        finally:
            if not clean and futures:
                client.cancel(futures, force=True)
            if owned:
                client.close()


def make_executor(workers: int = 1, scheduler=None):
    """:class:`DaskExecutor` when ``scheduler`` is given, else :class:`LocalExecutor`."""
    return LocalExecutor(workers) if scheduler is None else DaskExecutor(scheduler)
