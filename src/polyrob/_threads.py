"""One BLAS thread for the many small linear-algebra problems polyrob solves.

Every matrix in a μ bound, an H∞ step or a local search is small; a
multi-threaded OpenBLAS only spin-waits on them, which on a loaded 2-core
machine made L-BFGS-B, SLSQP and eig calls 5-30x slower.
"""

from __future__ import annotations

import ctypes
import os
import threading

from threadpoolctl import ThreadpoolController

__all__ = ["single_blas_thread", "single_blas_thread_for_life"]

#: The variables OpenBLAS, OpenMP and MKL read when a copy of the library is loaded.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


_CONTROLLER: list = [None, -1]  # the process's ThreadpoolController and the count of shared objects it saw
_LOCK = threading.Lock()


#: ``int callback(struct dl_phdr_info *, size_t, void *)`` of ``dl_iterate_phdr``.
_PHDR_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)


def _loaded_objects() -> int:
    """How many shared objects this process has loaded (``dl_iterate_phdr``; -1 where it is unavailable)."""
    count = [0]

    def one(info, size, data):
        count[0] += 1
        return 0

    try:
        ctypes.CDLL(None).dl_iterate_phdr(_PHDR_CALLBACK(one), None)
    except (AttributeError, OSError):
        return -1
    return count[0]


def _controller() -> ThreadpoolController:
    """One ``ThreadpoolController`` per process, found again when a library was loaded since.

    ``threadpool_limits`` builds a controller at every call, which scans the
    process's shared objects and opens each BLAS one (about 1 ms); μ bounds
    take the limit once per matrix, tens of thousands of times in a sweep.
    Counting the loaded objects costs about 40 µs and says when a copy of
    BLAS may have come in (slycot's, loaded late), so none is left unlimited.
    """
    loaded = _loaded_objects()
    with _LOCK:
        if _CONTROLLER[0] is None or loaded < 0 or loaded != _CONTROLLER[1]:
            _CONTROLLER[:] = [ThreadpoolController(), loaded]
        return _CONTROLLER[0]


def single_blas_thread():
    """A context manager limiting BLAS to one thread.

    Examples
    --------
    >>> import numpy as np
    >>> with single_blas_thread():
    ...     float(np.linalg.norm(np.eye(3)))
    1.7320508075688772
    """
    return _controller().limit(limits=1, user_api="blas")


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
