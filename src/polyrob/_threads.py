"""One BLAS thread for the many small linear-algebra problems polyrob solves.

Every matrix in a μ bound, an H∞ step or a local search is small; a
multi-threaded OpenBLAS only spin-waits on them, which on a loaded 2-core
machine made L-BFGS-B, SLSQP and eig calls 5-30x slower.
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits

__all__ = ["single_blas_thread"]


def single_blas_thread():
    """A context manager limiting BLAS to one thread."""
    return threadpool_limits(limits=1, user_api="blas")
