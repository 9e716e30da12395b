"""Strategy objects of the D-K / D-G-K iteration: the D-step bound and the K-step.

:class:`MuUpperBound` (μ upper bound and scalings at each frequency, SLICOT
AB13MD through :class:`~polyrob.synthesis.dk.musweep.MuSweep`) and
:class:`HinfStep` (:func:`~polyrob.synthesis.hinf.synthesis.hinfsyn` on the scaled
plant) are what :class:`~polyrob.synthesis.dk.iteration.DKIteration` calls; other
bounds or synthesis methods plug in with the same call signatures.
"""

from __future__ import annotations

import control
import numpy as np

from polyrob.analysis.mu.blocks import as_block_structure
from polyrob.synthesis.dk.musweep import MuSweep
from polyrob.synthesis.hinf.synthesis import HinfResult, hinfsyn
from polyrob.synthesis.scalings.data import complexified

__all__ = ["MuUpperBound", "HinfStep"]


class MuUpperBound:
    """D-step strategy: μ upper bound and its scalings at each frequency.

    Parameters
    ----------
    method : {"auto", "ab13md", "lmi"}
        Passed to :func:`polyrob.analysis.mu.bounds.mussv` (AB13MD whenever it applies).
    n_jobs : int, optional
        Worker processes for the sweep (see :class:`~polyrob.synthesis.scalings.dscale.MuSweep`;
        default serial).

    Calling it with a frequency-response stack ``H`` (``(n, rows, cols)``)
    and a structure returns ``(mu, D, G)`` with ``D``, ``G`` on the padded
    problem (``(n, k, k)``).
    """

    def __init__(self, method: str = "auto", n_jobs: int | None = None):
        self.method = method
        self.sweep = MuSweep(n_jobs=n_jobs, method=method)

    def __call__(self, H: np.ndarray, blk) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(mu, D, G)`` at every frequency (padded scalings)."""
        st = as_block_structure(blk)
        self.last_complex = None
        if not st.has_real:
            return self.sweep(H, st)
        return self._mixed(H, st)

    def _mixed(self, H, st):
        """Mixed bound by pruning with the (cheaper) complex bound.

        Mixed μ <= complex μ, so only frequencies whose complex bound exceeds
        the largest mixed bound found so far can hold the mixed peak: they
        are visited in decreasing order of the complex bound, and the others
        keep their complex scalings (``G = 0``), which certify a level below
        the peak.  The peak is exact; AB13MD with ten real blocks costs about
        twice the complex call, and typically a third of the grid is visited.
        The complex bound and scalings are kept in :attr:`last_complex` for
        the D-only route of the fit.
        """
        stc = complexified(st)
        c, Dc, _ = self.sweep(H, stc)
        mu = c.copy()
        D = Dc.copy()
        G = np.zeros_like(Dc)
        order = np.argsort(-c)
        best = 0.0
        todo = []
        for k in order:
            if c[k] <= best:
                break
            todo.append(k)
            if len(todo) >= 4:  # in small batches: best tightens as we go
                m, Dm, Gm = self.sweep(H[todo], st)
                mu[todo], D[todo], G[todo] = m, Dm, Gm
                best = max(best, float(m.max()))
                todo = []
        if todo:
            m, Dm, Gm = self.sweep(H[todo], st)
            mu[todo], D[todo], G[todo] = m, Dm, Gm
        self.last_complex = (c, Dc, stc)
        return mu, D, G

    def close(self):
        """Stop the worker process, if any."""
        self.sweep.close()


class HinfStep:
    """K-step strategy: :func:`~polyrob.synthesis.hinf.synthesis.hinfsyn` on the scaled plant.

    Parameters
    ----------
    tol : float
        Relative tolerance of the γ bisection.  MATLAB's ``hinfsyn`` uses
        1e-2, but late D-K iterations gain a few tenths of a percent each:
        a 1% suboptimal K-step would hide them.
    method : {"auto", "riccati", "lmi"}
    epsilon : float
        Regularisation ε, see :func:`~polyrob.synthesis.hinf.synthesis.hinfsyn`.
    """

    def __init__(self, tol: float = 1e-3, method: str = "auto", epsilon: float = 1e-4):
        self.tol, self.method, self.epsilon = tol, method, epsilon

    def __call__(self, P: control.StateSpace, n_y: int, n_u: int) -> HinfResult:
        return hinfsyn(P, n_y, n_u, tol=self.tol, method=self.method, epsilon=self.epsilon)
