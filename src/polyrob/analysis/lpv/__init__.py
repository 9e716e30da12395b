"""Rate-bounded induced-L2 analysis of gridded LPV systems: :func:`lpvnorm` (LPVTools' ``lpvnorm``).

:func:`lpvnorm` returns an :class:`LpvNormResult` whose ``gamma`` is proved:
the LMI solution re-checked in float64 with a rounding margin
(:mod:`polyrob.analysis.lpv.check`), on the grid, or on the whole parameter
box for an affine system (:mod:`polyrob.analysis.lpv.between`).  See
docs/lpvnorm.md.

Examples
--------
>>> import numpy as np
>>> from polyrob.analysis.lpv import lpvnorm
>>> sysf = lambda r: (np.array([[-2.0 + r[0]]]), np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 1)))
>>> r = lpvnorm(sysf, [np.array([0.0, 1.0])], affine=True)      # 1/(s + 2 - rho), rho in [0, 1]
>>> r.proved, round(r.gamma, 4), r.coverage.startswith("the whole parameter box")
(True, 1.0, True)
"""

from polyrob.analysis.lpv.check import check_solution, proved_gamma
from polyrob.analysis.lpv.norm import lpvnorm
from polyrob.analysis.lpv.result import LpvNormResult

__all__ = ["lpvnorm", "LpvNormResult", "check_solution", "proved_gamma"]
