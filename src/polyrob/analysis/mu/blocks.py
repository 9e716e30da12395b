"""Uncertainty block structures for the structured singular value.

A :class:`BlockStructure` describes the set

.. math:: \\mathbf{\\Delta} = \\{\\operatorname{diag}(\\Delta_1, \\ldots, \\Delta_N)\\}

in the encoding of MATLAB's ``mussv``: one row ``[r, c]`` per block.

========== =====================================================
row        block :math:`\\Delta_i`
========== =====================================================
``[-1, 0]``  real scalar :math:`\\delta \\in \\mathbb{R}`
``[-r, 0]``  repeated real scalar :math:`\\delta I_r`
``[1, 0]``   complex scalar :math:`\\delta \\in \\mathbb{C}`
``[r, 0]``   repeated complex scalar :math:`\\delta I_r`
``[r, c]``   full complex :math:`r \\times c` block (``c > 0``)
========== =====================================================

With :math:`\\Delta` of size :math:`\\sum r_i \\times \\sum c_i`, the matrix
:math:`M` analysed against it is :math:`\\sum c_i \\times \\sum r_i`, so that
:math:`I - M\\Delta` is square.

Internally every algorithm works on a *padded square* problem: a non-square
full block :math:`r \\times c` is embedded in a :math:`k \\times k` block,
:math:`k = \\max(r, c)`, and :math:`M` gets matching zero rows/columns.  The
padding leaves :math:`\\mu` unchanged because
:math:`\\det(I - E_c M E_r^T \\Delta') = \\det(I - M E_r^T \\Delta' E_c)` and the
compression :math:`E_r^T \\Delta' E_c` never increases the norm.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, Union

import numpy as np

from polyrob.errors import ArgumentError

__all__ = ["Block", "BlockStructure", "as_block_structure"]

BlockKind = Literal["real", "complex", "full"]


@dataclass(frozen=True)
class Block:
    """One block of a :class:`BlockStructure`.

    Attributes
    ----------
    kind : {"real", "complex", "full"}
        ``"real"``/``"complex"`` are (possibly repeated) scalars
        :math:`\\delta I_r`; ``"full"`` is a full complex ``rows x cols`` block.
    rows, cols : int
        Size of :math:`\\Delta_i` (``rows == cols`` for scalar blocks).
    """

    kind: BlockKind
    rows: int
    cols: int

    @property
    def repeated(self) -> bool:
        """True for a scalar block repeated more than once (not AB13MD-able)."""
        return self.kind != "full" and self.rows > 1

    @property
    def size(self) -> int:
        """Side of the block in the padded square problem."""
        return max(self.rows, self.cols)

    @property
    def matlab(self) -> tuple[int, int]:
        """The MATLAB ``blk`` row of this block."""
        if self.kind == "real":
            return (-self.rows, 0)
        if self.kind == "complex":
            return (self.rows, 0)
        return (self.rows, self.cols)


BlkLike = Union["BlockStructure", Sequence[Sequence[int]], np.ndarray]


@dataclass(frozen=True)
class BlockStructure:
    """Block-diagonal uncertainty structure (MATLAB ``blk`` encoding).

    Build it with :meth:`from_matlab` (or pass a ``blk`` array anywhere a
    structure is expected; see :func:`as_block_structure`).

    Examples
    --------
    >>> from polyrob.analysis.mu.blocks import BlockStructure
    >>> blk = BlockStructure.from_matlab([[-1, 0], [2, 0], [1, 3]])
    >>> [b.kind for b in blk.blocks]
    ['real', 'complex', 'full']
    >>> blk.delta_shape, blk.m_shape
    ((4, 6), (6, 4))
    >>> blk.matlab.tolist()
    [[-1, 0], [2, 0], [1, 3]]
    """

    blocks: tuple[Block, ...]

    # ----------------------------------------------------------- construction
    @classmethod
    def from_matlab(cls, blk: Sequence[Sequence[int]] | np.ndarray) -> BlockStructure:
        """Parse MATLAB's ``blk`` (list of rows or an ``N x 2`` array)."""
        try:
            arr = np.asarray(blk, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ArgumentError(f"block structure must be an N x 2 integer array, got {blk!r}") from exc
        if arr.ndim == 1 and arr.size == 2:
            arr = arr.reshape(1, 2)
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
            raise ArgumentError(
                f"block structure must be a non-empty N x 2 array of [rows, cols], got shape {arr.shape}"
            )
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            raise ArgumentError(f"block structure entries must be integers, got {arr.tolist()}")
        blocks = []
        for i, (r, c) in enumerate(arr.astype(int).tolist()):
            if r == 0:
                raise ArgumentError(f"block {i}: [{r}, {c}] has zero size")
            if r < 0:
                if c != 0:
                    raise ArgumentError(f"block {i}: [{r}, {c}] is invalid; real blocks are scalars [-r, 0]")
                blocks.append(Block("real", -r, -r))
            elif c == 0:
                blocks.append(Block("complex", r, r))
            elif c < 0:
                raise ArgumentError(f"block {i}: [{r}, {c}] has a negative column count")
            elif r == 1 and c == 1:
                # MATLAB treats [1 1] and [1 0] identically: a complex scalar.
                blocks.append(Block("complex", 1, 1))
            else:
                blocks.append(Block("full", r, c))
        return cls(tuple(blocks))

    # ------------------------------------------------------------ properties
    @property
    def matlab(self) -> np.ndarray:
        """The MATLAB ``blk`` encoding as an ``N x 2`` integer array."""
        return np.array([b.matlab for b in self.blocks], dtype=int)

    @property
    def delta_shape(self) -> tuple[int, int]:
        """Shape of :math:`\\Delta` (``sum(rows), sum(cols)``)."""
        return (sum(b.rows for b in self.blocks), sum(b.cols for b in self.blocks))

    @property
    def m_shape(self) -> tuple[int, int]:
        """Shape of the matrix :math:`M` that closes the loop with :math:`\\Delta`."""
        r, c = self.delta_shape
        return (c, r)

    @property
    def padded_size(self) -> int:
        """Side of the padded square problem."""
        return sum(b.size for b in self.blocks)

    @property
    def has_real(self) -> bool:
        return any(b.kind == "real" for b in self.blocks)

    @property
    def has_repeated(self) -> bool:
        return any(b.repeated for b in self.blocks)

    @property
    def is_complex(self) -> bool:
        """True when no block is real (the classic complex :math:`\\mu`)."""
        return not self.has_real

    def relaxed(self) -> BlockStructure:
        """The structure with every repeated scalar block made AB13MD-able, a superset of this one.

        A repeated real ``δ I_r`` becomes ``r`` independent real scalars, a
        repeated complex ``δ I_r`` a full complex ``r x r`` block; both
        contain the original block, and the padded problem keeps its size
        and order.  So μ of the relaxed structure is an upper bound of μ of
        this one, and its ``D``, ``G`` scalings are admissible for it (a
        diagonal ``D`` commutes with ``δ I_r``).

        Examples
        --------
        >>> as_block_structure([[-3, 0], [2, 0], [1, 2]]).relaxed().matlab.tolist()
        [[-1, 0], [-1, 0], [-1, 0], [2, 2], [1, 2]]
        """
        blocks = []
        for b in self.blocks:
            if b.kind == "real" and b.rows > 1:
                blocks.extend([Block("real", 1, 1)] * b.rows)
            elif b.kind == "complex" and b.rows > 1:
                blocks.append(Block("full", b.rows, b.rows))
            else:
                blocks.append(b)
        return BlockStructure(tuple(blocks))

    @property
    def ab13md_args(self) -> tuple[np.ndarray, np.ndarray]:
        """``(nblock, itype)`` for SLICOT AB13MD on the padded problem.

        Raises
        ------
        PolyrobError
            If a scalar block is repeated: AB13MD only knows real scalars and
            full complex blocks.
        """
        if self.has_repeated:
            raise ArgumentError("AB13MD does not support repeated scalar blocks; use method='lmi'")
        nblock = np.array([b.size for b in self.blocks], dtype=np.int64)
        itype = np.array([1 if b.kind == "real" else 2 for b in self.blocks], dtype=np.int64)
        return nblock, itype

    def __str__(self) -> str:
        names = {"real": "R", "complex": "C"}
        parts = []
        for b in self.blocks:
            if b.kind == "full":
                parts.append(f"C{b.rows}x{b.cols}")
            else:
                parts.append(names[b.kind] + (f"*I{b.rows}" if b.rows > 1 else ""))
        return "diag(" + ", ".join(parts) + ")"

    # --------------------------------------------------------- index helpers
    def _offsets(self, attr: str) -> list[slice]:
        out, k = [], 0
        for b in self.blocks:
            n = getattr(b, attr)
            out.append(slice(k, k + n))
            k += n
        return out

    @property
    def row_slices(self) -> list[slice]:
        """Slices of each block's rows in :math:`\\Delta` (= columns of M)."""
        return self._offsets("rows")

    @property
    def col_slices(self) -> list[slice]:
        """Slices of each block's columns in :math:`\\Delta` (= rows of M)."""
        return self._offsets("cols")

    @property
    def padded_slices(self) -> list[slice]:
        """Slices of each block in the padded square problem."""
        return self._offsets("size")

    def embeddings(self) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays placing the c-space (rows of ``M``) and r-space (its columns) into the padded space."""
        ec, er = [], []
        for b, sl in zip(self.blocks, self.padded_slices):
            ec.extend(range(sl.start, sl.start + b.cols))
            er.extend(range(sl.start, sl.start + b.rows))
        return np.array(ec, dtype=int), np.array(er, dtype=int)

    # ------------------------------------------------------------ conversions
    def check_m(self, M: np.ndarray) -> np.ndarray:
        """Return ``M`` as a complex 2-D array, checking its shape."""
        M = np.atleast_2d(np.asarray(M, dtype=complex))
        if M.shape != self.m_shape:
            raise ArgumentError(
                f"M has shape {M.shape} but block structure {self} needs {self.m_shape} "
                "(rows = sum of block columns, cols = sum of block rows)"
            )
        if not np.all(np.isfinite(M)):
            raise ArgumentError("M contains NaN or Inf")
        return M

    def pad(self, M: np.ndarray) -> np.ndarray:
        """Embed ``M`` (or a stack ``(..., nc, nr)``) in the padded square problem."""
        M = np.asarray(M, dtype=complex)
        n = self.padded_size
        ec, er = self.embeddings()
        out = np.zeros(M.shape[:-2] + (n, n), dtype=complex)
        out[..., ec[:, None], er[None, :]] = M
        return out

    def unpad_delta(self, delta_sq: np.ndarray) -> np.ndarray:
        """Compress a padded square :math:`\\Delta'` to the original shape."""
        ec, er = self.embeddings()
        return np.asarray(delta_sq)[..., er[:, None], ec[None, :]]

    def pad_delta(self, delta: np.ndarray) -> np.ndarray:
        """Embed a :math:`\\Delta` in the padded square problem (zero padding)."""
        ec, er = self.embeddings()
        n = self.padded_size
        out = np.zeros(np.shape(delta)[:-2] + (n, n), dtype=complex)
        out[..., er[:, None], ec[None, :]] = delta
        return out

    def restrict_scaling(self, D_sq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Split a padded scaling into ``(D_left, D_right)`` on M's rows / columns."""
        ec, er = self.embeddings()
        return D_sq[..., ec[:, None], ec[None, :]], D_sq[..., er[:, None], er[None, :]]

    # --------------------------------------------------------- perturbations
    def project(self, delta: np.ndarray) -> np.ndarray:
        """Nearest (Frobenius) element of the structure to ``delta``.

        Useful to clean rounding noise: scalars become the mean of the
        diagonal (real part for real blocks), off-block entries vanish.
        """
        delta = np.asarray(delta, dtype=complex)
        out = np.zeros(self.delta_shape, dtype=complex)
        for b, rs, cs in zip(self.blocks, self.row_slices, self.col_slices):
            blkv = delta[rs, cs]
            if b.kind == "full":
                out[rs, cs] = blkv
            else:
                d = np.trace(blkv) / b.rows
                out[rs, cs] = (d.real if b.kind == "real" else d) * np.eye(b.rows)
        return out

    def contains(self, delta: np.ndarray, tol: float = 1e-9) -> bool:
        """True if ``delta`` has this block-diagonal structure (to ``tol``)."""
        delta = np.asarray(delta)
        if delta.shape != self.delta_shape:
            return False
        scale = max(1.0, float(np.max(np.abs(delta), initial=0.0)))
        return bool(np.max(np.abs(delta - self.project(delta)), initial=0.0) <= tol * scale)

    def random_delta(self, rng: np.random.Generator | None = None, uniform: bool = False) -> np.ndarray:
        """Random element with every block of norm one (for tests and starts).

        With ``uniform=True`` real scalars are drawn uniformly in [-1, 1]
        instead of at the vertices.
        """
        rng = np.random.default_rng() if rng is None else rng
        parts = []
        for b in self.blocks:
            if b.kind == "real":
                d = rng.uniform(-1.0, 1.0) if uniform else rng.choice([-1.0, 1.0])
                parts.append(d * np.eye(b.rows))
            elif b.kind == "complex":
                parts.append(np.exp(2j * np.pi * rng.random()) * np.eye(b.rows))
            else:
                X = rng.standard_normal((b.rows, b.cols)) + 1j * rng.standard_normal((b.rows, b.cols))
                parts.append(X / np.linalg.norm(X, 2))
        return self.assemble(parts)

    def assemble(self, parts: Sequence[np.ndarray | complex]) -> np.ndarray:
        """Block-diagonal :math:`\\Delta` from one matrix (or scalar) per block."""
        if len(parts) != len(self.blocks):
            raise ArgumentError(f"need {len(self.blocks)} blocks, got {len(parts)}")
        out = np.zeros(self.delta_shape, dtype=complex)
        for b, p, rs, cs in zip(self.blocks, parts, self.row_slices, self.col_slices):
            p = np.asarray(p, dtype=complex)
            out[rs, cs] = p * np.eye(b.rows) if p.ndim == 0 else p
        return out


def as_block_structure(blk: BlkLike) -> BlockStructure:
    """Accept a :class:`BlockStructure` or a MATLAB ``blk`` array.

    Examples
    --------
    >>> from polyrob.analysis.mu.blocks import as_block_structure
    >>> print(as_block_structure([[-1, 0], [-1, 0], [2, 2], [1, 1], [1, 1]]))
    diag(R, R, C2x2, C, C)
    """
    if isinstance(blk, BlockStructure):
        return blk
    return BlockStructure.from_matlab(blk)


def perron_upper(Ms: np.ndarray, st: BlockStructure) -> tuple[float, np.ndarray]:
    """Cheap D-scaled upper bound (Perron scaling of the block-norm matrix).

    ``D = diag(d_i I)`` commutes with every structure, so
    ``sigma_max(D M D^-1)`` is a valid upper bound; the Perron vectors of the
    matrix of block norms give a good ``d`` (Safonov's heuristic).
    """
    sls = st.padded_slices
    B = np.array([[np.linalg.norm(Ms[a, b], 2) for b in sls] for a in sls]) + 1e-12
    lv, V = np.linalg.eig(B)
    lw, W = np.linalg.eig(B.T)
    x, y = np.abs(V[:, np.argmax(np.abs(lv))]), np.abs(W[:, np.argmax(np.abs(lw))])
    d = np.sqrt(np.maximum(y, 1e-300) / np.maximum(x, 1e-300))
    d = np.concatenate([np.full(sl.stop - sl.start, di) for sl, di in zip(sls, d / d.max())])
    if not np.all(np.isfinite(d)) or d.min() <= 0:
        d = np.ones(Ms.shape[0])
    return float(np.linalg.norm(d[:, None] * Ms / d[None, :], 2)), np.diag(d)
