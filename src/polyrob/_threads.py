"""One BLAS thread for the many small linear-algebra problems polyrob solves.

Every matrix in a μ bound, an H∞ step or a local search is small; a
multi-threaded OpenBLAS only spin-waits on them, which on a loaded 2-core
machine made L-BFGS-B, SLSQP and eig calls 5-30x slower.
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_limits

__all__ = ["single_blas_thread", "single_blas_thread_for_life"]

#: The variables OpenBLAS, OpenMP and MKL read when a copy of the library is loaded.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_blas_thread():
    """A context manager limiting BLAS to one thread."""
    return threadpool_limits(limits=1, user_api="blas")


def single_blas_thread_for_life():
    """One BLAS thread in this process for its whole life: for a worker process polyrob started.

    ``threadpoolctl`` limits only the libraries loaded when it is called, and
    a spawned worker has loaded none yet: numpy, scipy and slycot each bring
    their own OpenBLAS later (four copies, three of them at two threads, in a
    fleet worker on the 2-core development machine), whose idle threads then
    spin beside the other worker's.  The variables of
    :data:`THREAD_VARIABLES` are read as each copy loads, so they are set in
    this process's own environment (never the user's: a worker's
    environment is its own), and the copies already loaded are limited too.
    """
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    return single_blas_thread()
