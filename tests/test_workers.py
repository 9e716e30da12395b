"""polyrob.workers: how a worker process is set up."""

from __future__ import annotations

import os


def _blas_threads_after_imports() -> list:
    """In a worker: the thread count of every BLAS after loading what the pipeline loads."""
    import control  # noqa: F401
    import scipy.linalg  # noqa: F401
    import slycot  # noqa: F401
    from threadpoolctl import threadpool_info

    return [(info["filepath"], info["num_threads"]) for info in threadpool_info() if info["user_api"] == "blas"]


def test_a_worker_runs_every_blas_it_loads_later_on_one_thread(monkeypatch):
    """threadpoolctl alone limits only the libraries loaded at the time, and a spawned worker has none yet:
    numpy, scipy and slycot bring their own OpenBLAS copies later (three of four ran two threads in each fleet
    worker, spinning beside the other worker).  The caller's environment is not changed."""
    from concurrent.futures import ProcessPoolExecutor

    from polyrob.workers import init_worker, spawn_context

    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")  # the caller asks for two: on one core too, this can fail
    before = dict(os.environ)
    with ProcessPoolExecutor(1, mp_context=spawn_context(), initializer=init_worker) as pool:
        blas = pool.submit(_blas_threads_after_imports).result(timeout=120)
    assert blas, "no BLAS library found in the worker"
    assert all(n == 1 for _, n in blas), blas
    assert dict(os.environ) == before
