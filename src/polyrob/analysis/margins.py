"""What a controller does certify when robust performance is not: its robust margin, and what stands in the way.

A μ bound ``β`` of the robust-performance loop proved at **every** frequency
is itself a certificate (the main loop theorem, Packard & Doyle 1993): for
every parameter set whose normalised ranges are scaled by ``1/β`` about
their centre, the loop is stable and the weighted performance channel has
``‖W·F‖∞ ≤ β``.  MATLAB's ``robgain``/``robstab`` report the same figure
("can tolerate up to 72 % of the modeled uncertainty").  Above 1 the grid's
μ peak bounds nothing between the grid points, so the level is proved
with :func:`polyrob.analysis.mu.between.verify_between` before it is quoted.

Examples
--------
>>> import control
>>> from polyrob.analysis.certificate import certify_loop
>>> from polyrob.analysis.margins import robust_margin
>>> P = control.ss([[-1.0]], [[3.0, 1.0]], [[1.0], [1.0]], [[0.0, 0.0], [0.0, 0.0]])
>>> c = certify_loop(P, -1.0, [[1, 1]], n_u=1, n_y=1)    # N = 3/(s + 2): mu = 1.5
>>> c.status.value                                       # the lower bound 1.5 >= 1 too
'VIOLATED'
>>> m = robust_margin(c)
>>> m.proved, round(m.level, 2), round(m.fraction, 2)
(True, 1.51, 0.66)
>>> m.sentence()
'robust performance at level 1.51 for 66 % of the parameter ranges'
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RobustMargin", "robust_margin", "dominant_weight", "BlockShare", "block_shares", "block_words"]


@dataclass(frozen=True)
class RobustMargin:
    """A μ level proved at every frequency, read as a margin.

    Attributes
    ----------
    level : float
        ``β``: μ ≤ β at every frequency (NaN when not proved).
    proved : bool
    peak_omega : float
        Frequency (rad/s) of the grid's μ peak: where the problem is hardest.
    reason : str
        Why no level was proved (empty when one was).
    """

    level: float
    proved: bool
    peak_omega: float
    reason: str = ""

    @property
    def fraction(self) -> float:
        """``1/β``: the share of the modelled parameter ranges the level holds for (NaN when not proved)."""
        return 1.0 / self.level if self.proved and self.level > 0 else float("nan")

    def sentence(self) -> str:
        """What the margin proves, in the words of MATLAB's ``robgain`` (a figure, not a verdict: the status decides)."""
        if not self.proved:
            return f"no margin proved ({self.reason})"
        return f"robust performance at level {self.level:.3g} for {100 * self.fraction:.0f} % of the parameter ranges"

    def summary(self) -> dict:
        return {
            "level": float(self.level) if self.proved else None,
            "fraction_of_ranges": float(self.fraction) if self.proved else None,
            "peak_omega": float(self.peak_omega),
            "proved": bool(self.proved),
            "reason": self.reason,
        }


def robust_margin(cert) -> RobustMargin:
    """The μ level of a robust-performance certificate proved at every frequency.

    Parameters
    ----------
    cert : Certificate
        From :func:`polyrob.analysis.certificate.certify_loop` (its sweep and closed loop are used).

    Returns
    -------
    RobustMargin
        ``proved`` only when the loop at ``Δ = 0`` is proved stable and the
        level holds between the grid points; a certified certificate's bound is
        its level.
    """
    from polyrob.analysis.certificate import RESPONSE_BITS, RESPONSE_TOL
    from polyrob.analysis.mu.between import verify_between
    from polyrob.analysis.mu.frequency import needs_extended_precision

    mu = cert.mu
    peak_omega = float(mu.peak_upper_frequency) if mu is not None else float("nan")
    if cert.certified:
        return RobustMargin(float(cert.bound), True, peak_omega)
    if mu is None or cert.closed_loop is None:
        return RobustMargin(float("nan"), False, peak_omega, "no mu sweep")
    st = cert.stable_at_delta0
    if st is None or not st.stable:
        return RobustMargin(float("nan"), False, peak_omega, "the loop at Delta = 0 is not proved stable")
    if not np.isfinite(mu.peak_upper):
        return RobustMargin(float("nan"), False, peak_omega, "mu is unbounded on the grid")
    between = getattr(mu, "between", None)
    if between is not None and between.holds:
        return RobustMargin(float(between.level), True, peak_omega)
    M = cert.closed_loop
    if needs_extended_precision(M, mu.omega, RESPONSE_BITS, RESPONSE_TOL):  # the Hamiltonian test runs in double
        return RobustMargin(float("nan"), False, peak_omega, "the loop's realisation needs extended precision")
    res = verify_between(M, mu)
    if not res.holds:
        return RobustMargin(float("nan"), False, peak_omega, f"not proved between the grid points: {res.reason}")
    return RobustMargin(float(res.level), True, peak_omega)


def dominant_weight(P, N, omega: float) -> str | None:
    """The weighted signal (a label of ``P.z_labels``) with the largest nominal gain at ``omega``.

    ``N = lft(P, K)`` is the loop at ``Δ = 0`` (a certificate's ``closed_loop``),
    stable; its ``w -> z`` response says which performance demand (``W_S`` on
    the error, ``W_T`` on the output, ...) is the hard one there.  ``None``
    for a bare state space.
    """
    from polyrob.analysis.mu.frequency import freqresp

    if not getattr(P, "z_labels", None) or not np.isfinite(omega):
        return None
    zs, ws = P.output_slices["z"], P.input_slices["w"]
    H = np.asarray(freqresp(N[zs, ws], np.array([max(float(omega), 0.0)])))[0]  # (z, w) at omega
    gains = {lab: float(np.linalg.norm(H[rows], 2)) for lab, rows in P.z_slices.items()}
    return max(gains, key=gains.get)


@dataclass(frozen=True)
class BlockShare:
    """μ at one frequency with one uncertainty block left out (``Δ_i = 0``).

    MATLAB's ``robstab``/``robgain`` report the same question as a
    sensitivity per uncertain element; leaving the block out says how much
    of μ it carries at the peak, also for a full block, which has no range
    to shrink by a percentage.

    Attributes
    ----------
    block : str
        The block in the model's words (:func:`block_words`).
    mu_without : float
        μ's upper bound at the frequency without it (a bound of that smaller problem).
    """

    block: str
    mu_without: float

    def phrase(self) -> str:
        return f"{self.block} {self.mu_without:.3g}"


def block_words(unc, blk) -> tuple[str, ...]:
    """Words for each block of ``blk`` (``Δ`` order; the last, the performance block, when it is there).

    Real blocks by their parameter's name; full blocks by what they carry
    when the model says it (the residual of the Jacobian's state columns or
    of its acceleration columns, the inertia), else by their size.
    """
    from polyrob.analysis.mu.blocks import as_block_structure

    st = as_block_structure(blk)
    names = tuple(getattr(unc, "channel_names", ()) or ())
    params = np.asarray(getattr(unc, "channel_parameter", ()), int)
    pnames = tuple(getattr(unc, "parameter_names", ()) or ())
    residuals = list((getattr(unc, "info", None) or {}).get("residual_blocks") or ())
    n_x = int(getattr(unc, "n_x", 0) or 0)
    words, start, full = [], 0, 0
    for b in st.blocks:
        width = b.cols  # rows of M: the block's input channels v
        if start >= len(names):
            words.append("performance")
        elif b.kind == "real" and start < len(params) and params[start] >= 0:
            words.append(pnames[params[start]] if params[start] < len(pnames) else names[start])
        else:
            cols = np.asarray(residuals[full]["cols"]) if full < len(residuals) else None
            what = f"full block {b.rows}x{b.cols}"
            if cols is not None and n_x and np.all(cols < n_x):
                what = f"the state columns' residual ({b.rows}x{b.cols})"
            elif cols is not None and n_x and np.all(cols >= n_x):
                what = f"the acceleration columns' residual, the inertia ({b.rows}x{b.cols})"
            words.append(what)
            full += 1
        start += width
    return tuple(words)


def block_shares(M, blk, words=None, *, skip_last: bool = True) -> tuple[BlockShare, ...]:
    """μ of ``M`` with each block of ``blk`` left out in turn, the block whose removal lowers μ most first.

    Parameters
    ----------
    M : (nc, nr) array_like
        The loop at one frequency (rows: the blocks' inputs).
    blk : BlockStructure or array_like
    words : sequence of str, optional
        One per block (default: ``block 0``, ``block 1``, ...).
    skip_last : bool
        Leave the last block (robust performance's performance block) in.

    Examples
    --------
    Two real scalars, the first coupling to itself only: without it μ is
    the second's 0.5, without the second it is the first's 2.

    >>> import numpy as np
    >>> from polyrob.analysis.margins import block_shares
    >>> M = np.array([[2.0, 0.0], [0.0, 0.5]])
    >>> [s.phrase() for s in block_shares(M, [[-1, 0], [-1, 0]], ["a", "b"], skip_last=False)]
    ['a 0.5', 'b 2']
    """
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv

    st = as_block_structure(blk)
    M = np.asarray(M, complex)
    blocks = list(st.blocks)
    words = list(words) if words is not None else [f"block {i}" for i in range(len(blocks))]
    row0 = np.cumsum([0] + [b.cols for b in blocks])  # M's rows: the blocks' inputs
    col0 = np.cumsum([0] + [b.rows for b in blocks])  # M's columns: the blocks' outputs
    shares = []
    for i in range(len(blocks) - (1 if skip_last else 0)):
        if len(blocks) == 1:
            break
        rows = np.r_[0 : row0[i], row0[i + 1] : row0[-1]]
        cols = np.r_[0 : col0[i], col0[i + 1] : col0[-1]]
        rest = [b.matlab for k, b in enumerate(blocks) if k != i]
        mu = mussv(M[np.ix_(rows, cols)], rest, lower=False).upper
        shares.append(BlockShare(words[i], float(mu)))
    return tuple(sorted(shares, key=lambda s: s.mu_without))
