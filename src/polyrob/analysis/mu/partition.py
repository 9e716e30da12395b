"""μ below a level by branch and bound on the real scalars: the D-G bound on cells of their box.

The D-G upper bound (:mod:`~polyrob.analysis.mu.gradient`) is exact for
three or fewer complex blocks and can be far above μ with many real scalars
repeated (a model exact in a robot's parameters: each link's and the
instrument's scalars, :mod:`polyrob.plant.payload_lft`).  What closes that
gap is the classical one (MATLAB's ``robstab`` does the same on its real
parameters): split the real scalars' box into cells and bound μ on each
cell, where the bound is tighter because each scalar's range is smaller.

A cell of the real scalars ``δ_i ∈ [c_i - r_i, c_i + r_i]`` is the structure
itself after a change of variables: with ``Δ = Δ_c + S Δ'`` (``Δ_c`` the
cell's centre on the real blocks, zero elsewhere, ``S`` the radii there and
one on the complex blocks, so ``S Δ' = Δ' S``)::

    det(I - M Δ) = det(A) det(I - A^-1 M S Δ'),     A = I - M Δ_c

so ``I - M Δ`` is nonsingular on the whole cell when ``A`` is and
``μ(A^-1 M S) < 1`` on the unit structure; and where ``A`` is singular, or
the lower bound of ``A^-1 M S`` reaches 1, a member of the cell makes ``I -
M Δ`` singular.  At a level ``β`` the same holds for ``M / β``: ``μ(M) <
β`` is proved when every leaf of the partition is, and disproved by any
member found.  The cells halve one real scalar's range at a time, the one
whose rows and columns of ``A^-1 M S`` weigh most (the scalar that moves
the loop most over its remaining range).

``A^-1 M S`` is computed in floats: a leaf counts as proved when its bound,
widened by the solve's relative error (``n u cond(A)``, times ten), stays
below 1.

Why by hand: no maintained Python library computes mixed μ, and MATLAB's
``mussv`` has no partition (its ``robstab`` does, for the stability margin).

Examples
--------
Two real scalars, each repeated twice, on a real matrix: μ is 1.8526 (the
largest real eigenvalue of ``M Δ`` over the box's faces), the D-G bound of
the whole box 2.56.  The partition proves 1.05 μ in a few cells and finds a
member at 0.97 μ:

>>> import numpy as np
>>> from polyrob.analysis.mu.blocks import as_block_structure
>>> st = as_block_structure([[-2, 0], [-2, 0]])
>>> M = np.random.default_rng(21).standard_normal((4, 4)) + 0j
>>> above = partition_mu(M, st, level=1.05 * 1.8526)
>>> print(above.verdict, f"{above.root_upper * above.level:.2f}", above.cells < 20)
proved 2.56 True
>>> partition_mu(M, st, level=0.97 * 1.8526).verdict
'member'
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from polyrob.analysis.mu.blocks import BlockStructure, as_block_structure
from polyrob.analysis.mu.gradient import GradientUpper
from polyrob.analysis.mu.lower import lower_bound
from polyrob.errors import ArgumentError

__all__ = ["PartitionResult", "partition_mu", "SOLVE_MARGIN", "SINGULAR_CONDITION"]

#: A leaf's bound is widened by this many times ``n u cond(A)`` (the solve's relative error) before it is compared with 1.
SOLVE_MARGIN = 10.0
#: ``A = I - M Δ_c`` is taken for singular (the cell's centre a member) above this condition number.
SINGULAR_CONDITION = 1e12


@dataclass(frozen=True)
class PartitionResult:
    """What :func:`partition_mu` found at one level.

    Attributes
    ----------
    verdict : {"proved", "member", "unknown"}
        ``"proved"``: ``μ(M) < level`` (every leaf's D-G bound below 1);
        ``"member"``: a member of the structure at the level makes ``I - M
        Δ`` singular, so ``μ(M) >= level``; ``"unknown"``: the cell budget
        ran out first.
    level : float
    cells : int
        Cells bounded (the nodes of the search, the root included).
    proved_fraction : float
        Share of the real scalars' box covered by proved leaves (1 when
        proved; the box's volume in the scaled scalars).
    root_upper : float
        The D-G bound on the whole box, relative to the level (``> 1`` when
        the partition was needed).
    worst_leaf : float
        The largest bound among the proved leaves, relative to the level.
    splits : tuple of int
        How many times each real block (in the structure's order of its real
        blocks) was halved.
    member : ndarray or None
        With ``"member"``: the real scalars' values (within ``±1``) of the
        cell where it was found, at its centre.
    """

    verdict: str
    level: float
    cells: int
    proved_fraction: float
    root_upper: float
    worst_leaf: float
    splits: tuple
    member: np.ndarray | None = None

    @property
    def proved(self) -> bool:
        return self.verdict == "proved"


def partition_mu(Ms, blk, level: float = 1.0, *, max_cells: int = 256, maxiter: int = 100) -> PartitionResult:
    """Prove ``μ(Ms) < level`` on a partition of the real scalars' box, or find a member at the level.

    Parameters
    ----------
    Ms : (n, n) complex array_like
        Padded square matrix (:meth:`BlockStructure.pad`).
    blk : BlockStructure or array_like
        Its structure (MATLAB ``blk``); only the real scalar blocks are split.
    level : float
        The level ``β > 0`` to prove ``μ`` below.
    max_cells : int
        Cells bounded at most (each one D-G descent): beyond, ``"unknown"``.
    maxiter : int
        L-BFGS iterations per temperature of each cell's descent.

    Returns
    -------
    PartitionResult

    Raises
    ------
    ArgumentError
        A level that is not positive, no cell allowed, or a matrix that does not fit the structure.
    """
    st: BlockStructure = as_block_structure(blk)
    Ms = np.asarray(Ms, complex)
    n = st.padded_size
    if Ms.shape != (n, n):
        raise ArgumentError(f"partition_mu: a padded {n} x {n} matrix is needed for {st}, got {Ms.shape}")
    if not (np.isfinite(level) and level > 0):
        raise ArgumentError(f"partition_mu: the level must be positive and finite, got {level}")
    if int(max_cells) < 1:
        raise ArgumentError(f"partition_mu: max_cells must be at least 1 (the whole box), got {max_cells}")
    M = Ms / level
    slices = st.padded_slices
    real = [i for i, b in enumerate(st.blocks) if b.kind == "real"]
    descent = GradientUpper(st, maxiter=maxiter)
    splits = np.zeros(len(real), int)
    # depth first: a cell's children are bounded before its siblings, so a member is met early and the stack stays short
    stack = [(np.zeros(len(real)), np.ones(len(real)), None)]
    cells, proved, root, worst = 0, 0.0, np.nan, 0.0
    while stack:
        if cells >= max_cells:
            return PartitionResult("unknown", level, cells, proved, root, worst, tuple(int(s) for s in splits))
        centre, radius, x0 = stack.pop()
        cells += 1
        shift, scale = np.zeros(n), np.ones(n)
        for k, i in enumerate(real):
            shift[slices[i]], scale[slices[i]] = centre[k], radius[k]
        A = np.eye(n) - M * shift[None, :]  # I - M Δ_c (Δ_c diagonal: its real blocks are scalars times I)
        cond = np.linalg.cond(A)
        if not np.isfinite(cond) or cond > SINGULAR_CONDITION:
            return PartitionResult("member", level, cells, proved, root, worst, tuple(int(s) for s in splits), centre)
        N = np.linalg.solve(A, M * scale[None, :])
        bound, _D, _G, x = descent(N, x0)
        widened = bound * (1.0 + SOLVE_MARGIN * n * np.finfo(float).eps * cond)
        if cells == 1:
            root = float(bound)
        if widened < 1.0:
            proved += float(np.prod(radius))
            worst = max(worst, float(widened))
            continue
        if not real or lower_bound(N, st, starts=1, refine=False)[0] >= 1.0:
            verdict = "member" if real else "unknown"  # no real scalar to split: the D-G bound is all there is
            return PartitionResult(
                verdict, level, cells, proved, root, worst, tuple(int(s) for s in splits), centre if real else None
            )
        weight = [np.linalg.norm(N[slices[i], :], 2) * np.linalg.norm(N[:, slices[i]], 2) for i in real]
        k = int(np.argmax(weight))
        splits[k] += 1
        for side in (1.0, -1.0):
            c, r = centre.copy(), radius.copy()
            r[k] = radius[k] / 2
            c[k] = centre[k] + side * r[k]
            stack.append((c, r, x))
    return PartitionResult("proved", level, cells, 1.0, root, worst, tuple(int(s) for s in splits))
