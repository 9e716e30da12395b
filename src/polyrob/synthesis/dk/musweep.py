"""μ upper bound and scalings of a stack of matrices (the D-step's sweep), on one or two cores.

:class:`MuSweep` runs :func:`polyrob.analysis.mu.bounds.mussv` (SLICOT AB13MD) over
the frequencies (descent on the scalings, warm-started, for large repeated
structures); :func:`complex_dscales` is the complex-μ D-step the fits of
:mod:`polyrob.synthesis.scalings.dfit` run on the transformed loop.
"""

from __future__ import annotations

import numpy as np

from polyrob.analysis.mu.blocks import BlockStructure, as_block_structure
from polyrob.synthesis.scalings.data import complexified, scaling_data

__all__ = ["MuSweep", "complex_dscales", "SingleThreadAB13MD", "D_STEP_DESCENT"]

#: Effort of the descent bound in a D-step (the certificate, ``mu_bounds``, uses the defaults).
D_STEP_DESCENT = {"maxiter": 60, "temperatures": (1e-2,)}


class MuSweep:
    """μ upper bound and scalings of a stack of matrices, on one or two cores.

    Each matrix costs one SLICOT AB13MD call (20-45 ms for the 2R robust
    performance problem, ~100 per D-step).  With ``n_jobs = k`` the
    frequencies are dealt to ``k`` worker processes running ``slycot.ab13md``
    (a fresh interpreter through :class:`polyrob.analysis.timelimit.TimeLimitedCall`, never
    a fork, and no re-import of the user's script); this process only
    coordinates.  A worker that fails or times out is replaced by a local
    call.

    Parameters
    ----------
    n_jobs : int, optional
        Worker processes; default ``1`` (serial, in this process).  Workers
        pay off on an otherwise idle multi-core machine only: on a loaded
        2-core machine, measured, two workers gave no speed-up.
    method : str
        :func:`polyrob.analysis.mu.bounds.mussv` method; repeated scalar blocks (LMI) are
        always computed serially.
    """

    def __init__(self, n_jobs: int | None = None, method: str = "auto", timeout: float = 120.0):
        self.n_jobs, self.method, self.timeout = n_jobs, method, timeout
        self._worker = None
        self._dead = False
        #: what did not go as planned (failed worker calls), in words
        self.notes: list[str] = []

    def _jobs(self, H, st) -> int:
        if st.has_repeated or self.method == "lmi":
            return 1
        return max(1, int(self.n_jobs or 1))

    def __call__(self, H: np.ndarray, st: BlockStructure):
        from polyrob.analysis.mu.bounds import mussv, resolve_method
        from polyrob.analysis.mu.upper import upper_ab13md

        st = as_block_structure(st)
        n = st.padded_size
        N = H.shape[0]
        mu = np.zeros(N)
        D = np.zeros((N, n, n), complex)
        G = np.zeros((N, n, n), complex)

        if resolve_method(st, self.method) == "gradient":
            return self._descent(H, st, mu, D, G)

        def local(k):
            if not np.all(np.isfinite(H[k])):
                mu[k], D[k], G[k] = np.inf, np.eye(n), 0.0
                return
            r = mussv(H[k], st, method=self.method, lower=False)
            mu[k], D[k], G[k] = r.upper, r.D, r.G

        jobs = self._jobs(H, st)
        if jobs <= 1 or self._dead or st.has_repeated:
            for k in range(N):
                local(k)
            return mu, D, G
        import threading

        from polyrob.analysis.timelimit import TimeLimitedCall

        # All AB13MD calls run in worker processes; this process only waits
        # (an AB13MD call here would hold the GIL and starve the threads that
        # talk to the workers).
        if self._worker is None:
            # one BLAS thread per worker (set inside the worker, not through this
            # process's environment): k workers with multi-threaded OpenBLAS on
            # k cores spin-wait against each other (no speed-up)
            self._worker = [TimeLimitedCall(SingleThreadAB13MD(), timeout=self.timeout) for _ in range(jobs)]
        nblock, itype = st.ab13md_args
        todo = [k for k in range(N) if np.all(np.isfinite(H[k])) and np.any(H[k])]
        failed = []

        def run_remote(worker, ks):
            for k in ks:
                Ms = np.asfortranarray(st.pad(H[k]))
                ok, val = worker(Ms, nblock, itype)
                if not ok:
                    failed.append(k)
                    continue
                up, Dk, Gk, _ = upper_ab13md(Ms, st, val)
                mu[k], D[k], G[k] = up, Dk, Gk

        threads = [
            threading.Thread(target=run_remote, args=(wk, todo[j :: len(self._worker)]), daemon=True)
            for j, wk in enumerate(self._worker)
        ]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        for k in set(range(N)) - set(todo):
            local(k)
        for k in failed:
            local(k)
        if failed:
            self.notes.append(f"{len(failed)} of {len(todo)} AB13MD calls failed in a worker; computed in this process")
        if todo and len(failed) == len(todo):
            self._dead = True  # the workers do not work here: stay serial
            self.notes.append("the worker processes do not work here: the sweep continues serially")
        return mu, D, G

    @staticmethod
    def _descent(H, st, mu, D, G):
        """Large repeated structures: descent on the scalings, each frequency warm-started from the last."""
        from polyrob._threads import single_blas_thread
        from polyrob.analysis.mu.gradient import GradientUpper

        n, x = st.padded_size, None
        # the D-step only feeds the scaling fit: a coarser descent than the certificate's
        upper = GradientUpper(st, **D_STEP_DESCENT)
        with single_blas_thread():
            for k in range(H.shape[0]):
                if not np.all(np.isfinite(H[k])):
                    mu[k], D[k], G[k] = np.inf, np.eye(n), 0.0
                    continue
                mu[k], D[k], G[k], x = upper(st.pad(H[k]), x)
        return mu, D, G

    def close(self):
        """Stop the worker processes."""
        if self._worker is not None:
            for wk in self._worker:
                wk.close()
            self._worker = None


class SingleThreadAB13MD:
    """``slycot.ab13md`` limited to one BLAS thread, for a worker process.

    The limit is taken on the first call in the worker (``threadpoolctl``)
    and kept by the instance, which lives in that process only.
    """

    def __init__(self):
        self._limit = None

    def __getstate__(self):
        return {}

    def __setstate__(self, state):
        self._limit = None

    def __call__(self, *args):
        import slycot

        if self._limit is None:
            from threadpoolctl import threadpool_limits

            self._limit = threadpool_limits(limits=1)
        return slycot.ab13md(*args)


def complex_dscales(
    X: np.ndarray, st: BlockStructure, mask=None, fallback=None, sweep: MuSweep | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Complex-μ upper bound of each ``X[k]`` (real blocks as complex) and its normalised ``d``.

    With ``mask``, only the masked frequencies are swept; elsewhere ``d`` is
    ``fallback`` (per-block data, e.g. the D-step's) and the level is
    ``σ̄(D X D^{-1})`` for it.  Frequencies far below the peak carry little
    weight in the fit, and the fit check repairs them if needed.
    """
    stc = complexified(st)
    sweep = sweep if sweep is not None else MuSweep(n_jobs=1)
    N = X.shape[0]
    idx = np.arange(N) if mask is None else np.where(mask)[0]
    c = np.zeros(N)
    d = np.ones((N, len(st.blocks)))
    if idx.size:
        ci, Di, _ = sweep(X[idx], stc)
        sd = scaling_data(np.arange(idx.size, dtype=float) + 1.0, ci, Di, np.zeros_like(Di), stc)
        c[idx], d[idx] = ci, sd.d
    rest = np.setdiff1d(np.arange(N), idx)
    if rest.size:
        d[rest] = fallback[rest] if fallback is not None else 1.0
        rsl, csl = st.col_slices, st.row_slices
        for k in rest:
            dl = np.ones(X.shape[1])
            dr = np.ones(X.shape[2])
            for i in range(len(st.blocks)):
                dl[rsl[i]] = d[k, i]
                dr[csl[i]] = d[k, i]
            c[k] = np.linalg.norm(dl[:, None] * X[k] / dr[None, :], 2)
    return c, d
