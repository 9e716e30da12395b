"""The uncertain plant: a PLDI written as an LFT in normalised real parameters.

:func:`uncertain_plant` turns a :class:`~polyrob.bounds.pldi.PLDI` into an
:class:`UncertainPlant`, MATLAB's ``uss`` built from one ``ureal`` per varying
Jacobian entry (the paper's section 2, eq. 7-10, and its "ten independent
real parameters" of section 3).

Normalisation (what ``δ`` means)
--------------------------------
Every varying entry ``p_i`` with interval ``[lo_i, hi_i]`` is written
*affinely* in a normalised real parameter ``δ_i ∈ [-1, 1]``::

    p_i(δ_i) = mid_i + rad_i δ_i,    mid_i = (lo_i + hi_i)/2,  rad_i = (hi_i - lo_i)/2

so ``δ_i = -1`` gives ``lo_i``, ``δ_i = +1`` gives ``hi_i`` and the box
``δ ∈ [-1, 1]^k`` is *exactly* the interval box of the PLDI (no
over-bounding).  The LFT's centre (``Δ = 0``) is therefore the **midpoint**
plant, not the nominal ``G_n``.  The nominal of the PLDI (by default the
linearisation at the equilibrium, the paper's ``G_n = (A(0), B(0), C, 0)``)
is kept separately: :meth:`UncertainPlant.nominal_system` returns it, and
:attr:`UncertainPlant.nominal_delta` is the point ``δ_n`` of the box where
the LFT equals it.  ``offset = mid - nominal`` is the brief's ``c_i``.

Why not MATLAB's normalisation: ``ureal('p', nom, 'Range', [lo, hi])`` with an
off-centre nominal uses a bilinear map ``δ ↦ p`` so that ``δ = 0`` gives
``nom``; that map is singular when the nominal sits on an endpoint, which is
the case for the four ``b`` entries of the paper's 2R at ``q = 0``
(``b31 = hi``, ``b32 = b41 = lo``, ``b42 = hi``).  The affine map is exact,
always well posed (``D_vd = 0``) and gives the same set of plants.

LFT structure (the paper's eq. 10 partition, rank one per entry)
-----------------------------------------------------------------
An entry ``A[r, c]`` is one channel ``v = x_c``, ``d = δ v`` entering state
row ``r`` with gain ``rad``; an entry ``B[r, c]`` is ``v = u_c`` (``D_vu``)::

    ẋ = A_mid x + B_d d + B_mid u          d = Δ v,   Δ = diag(δ_1, ..., δ_k)
    v = C_v x          + D_vu u
    y = C x                                 C = [I_m 0]  (y = q)

so ``Fu(M, Δ) = (A_mid + B_d Δ C_v, B_mid + B_d Δ D_vu, C, 0)``.

Entries equal by symmetry (``B = [0; M(q)^{-1}]`` is symmetric in its lower
block, so ``b32 ≡ b41`` for every Jacobian) may share one repeated real
parameter (``merge_symmetric=True``, MATLAB block ``[-2, 0]``): less
conservative, since the two entries can no longer move independently.

Examples
--------
>>> import polyrob
>>> from polyrob.plant.uncertainty import uncertain_plant
>>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
>>> unc = uncertain_plant(pldi)
>>> unc.parameter_names
('a32', 'a33', 'a34', 'a42', 'a43', 'a44', 'b31', 'b32', 'b41', 'b42')
>>> unc.block_structure.tolist()[:2], unc.n_delta
([[-1, 0], [-1, 0]], 10)
>>> uncertain_plant(pldi, merge_symmetric=True).block_structure[-2:].tolist()
[[-2, 0], [-1, 0]]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import control
import numpy as np

from polyrob.errors import BoundsError, PolyrobError

__all__ = [
    "UncertainPlant",
    "uncertain_plant",
    "upper_lft",
    "MAX_CORNERS",
    "SYMMETRY_RTOL",
]

#: Default cap on the number of corners :meth:`UncertainPlant.corners` enumerates.
MAX_CORNERS = 1024
#: Relative tolerance for "identical bounds" when merging symmetric entries.
SYMMETRY_RTOL = 1e-9


# --------------------------------------------------------------------------- LFT helper


def upper_lft(M: control.StateSpace, Delta) -> control.StateSpace:
    """Upper LFT ``Fu(M, Δ)`` with a constant (real or complex) ``Δ``.

    The first ``Δ.shape[0]`` inputs of ``M`` are ``d`` and its first
    ``Δ.shape[1]`` outputs are ``v``; ``d = Δ v`` closes them (MATLAB's
    ``lft(Delta, M)``).  python-control's ``StateSpace.lft`` is the lower LFT
with a system; the upper one with a constant is three matrix products:
    with ``Q = (I - Δ D11)^{-1} Δ`` the result is
    ``(A + B1 Q C1, B2 + B1 Q D12, C2 + D21 Q C1, D22 + D21 Q D12)``.

    Parameters
    ----------
    M : control.StateSpace
    Delta : array_like (n_d, n_v)

    Returns
    -------
    control.StateSpace
        The remaining channels; signal names of ``M`` are kept.

    Raises
    ------
    PolyrobError
        ``Δ`` too large for ``M``, or the loop is ill posed (``I - Δ D11`` singular).

    Examples
    --------
    >>> import control, numpy as np
    >>> from polyrob.plant.uncertainty import upper_lft
    >>> M = control.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], np.zeros((2, 2)))
    >>> upper_lft(M, [[2.0]]).A    # x' = -x + d, d = 2 x
    array([[1.]])
    """
    Delta = np.atleast_2d(np.asarray(Delta))
    nd, nv = Delta.shape
    if nd > M.ninputs or nv > M.noutputs:
        raise PolyrobError(f"Δ is {nd}x{nv} but M has only {M.ninputs} inputs and {M.noutputs} outputs")
    A, B, C, D = (np.asarray(X) for X in (M.A, M.B, M.C, M.D))
    B1, B2 = B[:, :nd], B[:, nd:]
    C1, C2 = C[:nv], C[nv:]
    D11, D12, D21, D22 = D[:nv, :nd], D[:nv, nd:], D[nv:, :nd], D[nv:, nd:]
    I_ = np.eye(nd)
    lhs = I_ - Delta @ D11
    if nd and np.linalg.cond(lhs) > 1e12:
        raise PolyrobError("the upper LFT is ill posed: I - Δ D_vd is singular")
    Q = np.linalg.solve(lhs, Delta) if nd else np.zeros((0, nv))
    return control.ss(
        A + B1 @ Q @ C1, B2 + B1 @ Q @ D12, C2 + D21 @ Q @ C1, D22 + D21 @ Q @ D12,
        inputs=M.input_labels[nd:], outputs=M.output_labels[nv:], states=M.state_labels, dt=M.dt,
    )


# --------------------------------------------------------------------------- result


@dataclass(frozen=True, eq=False)
class UncertainPlant:
    """A PLDI as an LFT in normalised real parameters (MATLAB's ``uss``).

    Build it with :func:`uncertain_plant`.  Parameters are the independent
    ``ureal``'s (one per varying entry, or one per symmetric pair when
    merged); *channels* are the rows of ``Δ`` (one per varying entry), so
    ``n_delta >= n_params``.

    Attributes
    ----------
    robot_name : str
    nominal_kind : {"pldi", "midpoint"}
        Where :meth:`nominal_system` comes from.
    A_nom, B_nom, C : ndarray
        The nominal ``G_n = (A_nom, B_nom, C, 0)``; ``C = [I_m 0]`` (``y = q``).
    A_mid, B_mid : ndarray
        The LFT centre (``Δ = 0``): the nominal with every varying entry at
        its interval midpoint.
    B_d, C_v, D_vu : ndarray
        The uncertainty channels: ``ẋ += B_d d``, ``v = C_v x + D_vu u``.
    parameter_names : tuple of str
        ``"a32"``; a merged pair is ``"b32=b41"``.
    parameter_lower, parameter_upper : ndarray (n_params,)
        Range of each parameter (for a merged pair, the hull of the two
        entries' intervals, which agree to :data:`SYMMETRY_RTOL`).
    channel_names : tuple of str
        Entry of each ``Δ`` channel (``"a32"``, ...), in ``Δ`` order.
    channel_parameter : ndarray (n_delta,) of int
        Parameter driving each channel.
    channel_index : ndarray (n_delta, 3)
        Matrix (0 = A, 1 = B), row, column of each channel's entry.
    channel_lower, channel_upper : ndarray (n_delta,)
        Interval of each channel's entry.
    nominal_delta : ndarray (n_params,)
        ``δ`` at which the LFT equals :meth:`nominal_system` (all zeros for
        ``nominal="midpoint"``); outside ``[-1, 1]`` if the nominal lies
        outside the intervals.
    offset : ndarray (n_params,)
        ``midpoint - nominal`` (the brief's ``c_i``).
    block_structure : ndarray (n_blocks, 2) of int
        MATLAB ``blk`` rows: ``[-1, 0]`` per independent parameter,
        ``[-r, 0]`` for a parameter repeated on ``r`` channels.
    merged : tuple of tuple of str
        The entry pairs merged by symmetry.
    """

    robot_name: str
    nominal_kind: str
    A_nom: np.ndarray
    B_nom: np.ndarray
    C: np.ndarray
    A_mid: np.ndarray
    B_mid: np.ndarray
    B_d: np.ndarray
    C_v: np.ndarray
    D_vu: np.ndarray
    parameter_names: tuple[str, ...]
    parameter_lower: np.ndarray
    parameter_upper: np.ndarray
    channel_names: tuple[str, ...]
    channel_parameter: np.ndarray
    channel_index: np.ndarray
    channel_lower: np.ndarray
    channel_upper: np.ndarray
    nominal_delta: np.ndarray
    offset: np.ndarray
    block_structure: np.ndarray
    merged: tuple[tuple[str, ...], ...] = ()
    info: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ sizes
    @property
    def m(self) -> int:
        """Number of joints (inputs ``u`` and outputs ``y = q``)."""
        return self.B_nom.shape[1]

    @property
    def n_x(self) -> int:
        return self.A_nom.shape[0]

    @property
    def n_delta(self) -> int:
        """Number of uncertainty channels (rows of ``Δ``)."""
        return len(self.channel_names)

    @property
    def n_params(self) -> int:
        """Number of independent real parameters."""
        return len(self.parameter_names)

    @property
    def ranges(self) -> dict[str, tuple[float, float]]:
        """``{parameter: (lower, upper)}``, MATLAB's ``ureal`` ``Range``."""
        return {
            n: (float(lo), float(hi))
            for n, lo, hi in zip(self.parameter_names, self.parameter_lower, self.parameter_upper)
        }

    @property
    def nominal_inside(self) -> bool:
        """Whether the nominal lies in the interval box (``|δ_n| <= 1``)."""
        return bool(np.all(np.abs(self.nominal_delta) <= 1.0 + 1e-12))

    def _labels(self):
        m = self.m
        u = [f"u[{i}]" for i in range(m)]
        y = [f"y[{i}]" for i in range(m)]
        x = [f"q[{i}]" for i in range(m)] + [f"qdot[{i}]" for i in range(m)]
        d = [f"d_{n}" for n in self.channel_names]
        v = [f"v_{n}" for n in self.channel_names]
        return u, y, x, d, v

    # ------------------------------------------------------------------ systems
    def _ss(self, A, B, name):
        u, y, x, _, _ = self._labels()
        return control.ss(A, B, self.C, np.zeros((self.m, self.m)), inputs=u, outputs=y, states=x, name=name, dt=0)

    def nominal_system(self) -> control.StateSpace:
        """The nominal plant ``G_n = (A_nom, B_nom, [I 0], 0)`` (eq. 7).

        Examples
        --------
        >>> import polyrob
        >>> from polyrob.plant.uncertainty import uncertain_plant
        >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
        >>> G = uncertain_plant(pldi).nominal_system()
        >>> G.ninputs, G.noutputs, G.nstates, G.input_labels
        (2, 2, 4, ['u[0]', 'u[1]'])
        """
        return self._ss(self.A_nom, self.B_nom, "G_n")

    def midpoint_system(self) -> control.StateSpace:
        """The LFT centre ``(A_mid, B_mid, C, 0)`` (``Δ = 0``)."""
        return self._ss(self.A_mid, self.B_mid, "G_mid")

    def lft_system(self) -> control.StateSpace:
        """``M`` with ``G(δ) = Fu(M, Δ)``: inputs ``[d, u]``, outputs ``[v, y]``.

        Signals are named ``d_<entry>``, ``u[i]``, ``v_<entry>``, ``y[i]``.
        """
        u, y, x, d, v = self._labels()
        nd, m = self.n_delta, self.m
        B = np.hstack([self.B_d, self.B_mid])
        C = np.vstack([self.C_v, self.C])
        D = np.zeros((nd + m, nd + m))
        D[:nd, nd:] = self.D_vu
        return control.ss(self.A_mid, B, C, D, inputs=d + u, outputs=v + y, states=x, name="M", dt=0)

    # ------------------------------------------------------------------ δ handling
    def _check_delta(self, delta, strict: bool) -> np.ndarray:
        delta = np.asarray(delta, dtype=float)
        if delta.shape != (self.n_params,):
            raise PolyrobError(
                f"δ must have one value per parameter ({self.n_params}: {', '.join(self.parameter_names)}), "
                f"got shape {delta.shape}"
            )
        if not np.all(np.isfinite(delta)):
            raise PolyrobError("δ must be finite")
        if strict and np.any(np.abs(delta) > 1.0 + 1e-12):
            raise PolyrobError(
                f"δ must lie in [-1, 1] (max |δ| = {np.abs(delta).max():.6g}); pass strict=False to extrapolate"
            )
        return delta

    def delta_matrix(self, delta) -> np.ndarray:
        """``Δ = diag(δ)`` over the channels (a merged parameter repeats), ``n_delta x n_delta``."""
        delta = self._check_delta(delta, strict=False)
        return np.diag(delta[self.channel_parameter])

    def matrices_at(self, delta, *, strict: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """``(A(δ), B(δ))``.

        Each entry is ``((1 - δ)/2) lo + ((1 + δ)/2) hi``, which equals the
        LFT's ``mid + rad δ`` up to rounding but hits ``lo``/``hi`` *exactly*
        at ``δ = ∓1`` and (clipped) never leaves ``[lo, hi]`` for ``|δ| <= 1``.
        """
        delta = self._check_delta(delta, strict)
        A, B = self.A_mid.copy(), self.B_mid.copy()
        dch = delta[self.channel_parameter]
        lo, hi = self.channel_lower, self.channel_upper
        vals = 0.5 * (1.0 - dch) * lo + 0.5 * (1.0 + dch) * hi
        inside = np.abs(dch) <= 1.0
        vals = np.where(inside, np.clip(vals, lo, hi), vals)
        for (mat, r, c), val in zip(self.channel_index, vals):
            (A if mat == 0 else B)[r, c] = val
        return A, B

    def plant_at(self, delta, *, strict: bool = True) -> control.StateSpace:
        """The plant ``G(δ) = (A(δ), B(δ), C, 0)``, MATLAB's ``usubs``.

        Parameters
        ----------
        delta : array_like (n_params,)
            Normalised parameters in ``[-1, 1]``.
        strict : bool
            Refuse ``|δ| > 1`` (extrapolation outside the PLDI).

        Examples
        --------
        >>> import numpy as np, polyrob
        >>> from polyrob.plant.uncertainty import uncertain_plant
        >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
        >>> unc = uncertain_plant(pldi)
        >>> G = unc.plant_at(-np.ones(unc.n_params))
        >>> bool(G.B[2, 0] == pldi.interval("b31")[0])
        True
        """
        return self._ss(*self.matrices_at(delta, strict=strict), "G")

    def delta_samples(
        self, n: int | None = None, *, kind: str = "uniform", seed=None, max_corners: int = MAX_CORNERS
    ) -> np.ndarray:
        """Points ``δ`` of the box, shape ``(n, n_params)``.

        Parameters
        ----------
        n : int, optional
            Number of points; for ``kind="corners"`` ``None`` means all
            ``2^n_params`` corners.
        kind : {"uniform", "corners"}
            Uniform in ``[-1, 1]^k``, or corners ``{-1, 1}^k`` (all of them in
            binary order, first parameter fastest, when ``n`` is None; ``n``
            random corners otherwise).
        seed : int or numpy Generator, optional
        max_corners : int
            Refuse to enumerate more corners than this.

        Raises
        ------
        PolyrobError
            Unknown ``kind``, ``n`` missing for uniform sampling, or more than
            ``max_corners`` corners requested for enumeration.
        """
        k = self.n_params
        rng = np.random.default_rng(seed)
        if kind == "uniform":
            if n is None or int(n) < 0:
                raise PolyrobError("uniform δ sampling needs a number of samples n >= 0")
            return rng.uniform(-1.0, 1.0, size=(int(n), k))
        if kind == "corners":
            if n is not None:
                return rng.choice([-1.0, 1.0], size=(int(n), k))
            if 2**k > max_corners:
                raise PolyrobError(
                    f"{k} parameters have 2^{k} = {2**k} corners, more than max_corners={max_corners}; "
                    "raise max_corners or draw random corners with delta_samples(n, kind='corners')"
                )
            bits = (np.arange(2**k)[:, None] >> np.arange(k)[None, :]) & 1
            return 2.0 * bits - 1.0
        raise PolyrobError(f"unknown δ sampling kind '{kind}': use 'uniform' or 'corners'")

    def usample(self, n: int, seed=None, *, return_delta: bool = False):
        """``n`` plants at uniform random ``δ ∈ [-1, 1]^k``, MATLAB's ``usample``.

        Returns
        -------
        list of control.StateSpace, or (list, ndarray (n, n_params)) with ``return_delta``.
        """
        deltas = self.delta_samples(n, kind="uniform", seed=seed)
        systems = [self.plant_at(d) for d in deltas]
        return (systems, deltas) if return_delta else systems

    def corners(self, max_corners: int = MAX_CORNERS, *, return_delta: bool = False):
        """The plants at all ``2^k`` corners ``δ ∈ {-1, 1}^k`` of the box.

        Every corner's entries are exactly interval endpoints.  Raises
        :class:`~polyrob.errors.PolyrobError` when ``2^k > max_corners``
        (use ``delta_samples(n, kind="corners")`` for random corners).
        """
        deltas = self.delta_samples(kind="corners", max_corners=max_corners)
        systems = [self.plant_at(d) for d in deltas]
        return (systems, deltas) if return_delta else systems


# --------------------------------------------------------------------------- construction


def _symmetric_pairs(index, lower, upper, nominal, m) -> list[tuple[int, int]]:
    """Pairs ``(k1, k2)`` of B entries ``B[m+i, j]``, ``B[m+j, i]`` (i < j) with the same bounds.

    ``B = [0; M(q)^{-1}]`` and the inverse inertia is symmetric, so these two
    entries are the same function of the state; they are merged only if their
    bounds and nominals also agree (a safeguard for robots where ``B`` is not
    ``M^{-1}``, e.g. with a motor model in front).
    """
    where = {tuple(int(v) for v in row): k for k, row in enumerate(index)}

    def same(a, b):
        return abs(a - b) <= SYMMETRY_RTOL * max(1.0, abs(a), abs(b))

    pairs = []
    for i in range(m):
        for j in range(i + 1, m):
            k1, k2 = where.get((1, m + i, j)), where.get((1, m + j, i))
            if k1 is None or k2 is None:
                continue
            if same(lower[k1], lower[k2]) and same(upper[k1], upper[k2]) and same(nominal[k1], nominal[k2]):
                pairs.append((k1, k2))
    return pairs


def uncertain_plant(pldi, *, nominal: str = "pldi", merge_symmetric: bool = False) -> UncertainPlant:
    """The uncertain plant of a PLDI: MATLAB's ``uss`` of one ``ureal`` per entry.

    Parameters
    ----------
    pldi : PLDI
        From :func:`polyrob.bound_pldi`.
    nominal : {"pldi", "midpoint"}
        ``G_n`` is the PLDI's nominal ``(A0, B0)`` (the linearisation at the
        equilibrium by default, as in the paper) or the interval midpoints
        (then ``G_n`` is also the LFT centre and ``nominal_delta = 0``).
    merge_symmetric : bool
        Let entries equal by symmetry of ``M(q)^{-1}`` (``b32 = b41``) share
        one repeated real parameter (block ``[-2, 0]``).  Default ``False``:
        every entry independent, the paper's choice.

    Returns
    -------
    UncertainPlant

    Raises
    ------
    BoundsError
        Inverted or non-finite intervals, or a nominal matrix of the wrong size.
    PolyrobError
        Unknown ``nominal``.

    Notes
    -----
    See the module docstring for the normalisation: the LFT is centred at
    the interval midpoints so that ``δ ∈ [-1, 1]^k`` is exactly the interval
    box even when the nominal is off-centre (or on an endpoint).

    Examples
    --------
    >>> import polyrob
    >>> from polyrob.plant.uncertainty import uncertain_plant
    >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    >>> unc = uncertain_plant(pldi, merge_symmetric=True)
    >>> unc.n_params, unc.n_delta, unc.merged
    (9, 10, (('b32', 'b41'),))
    >>> lo, hi = unc.ranges["b32=b41"]
    >>> round(lo, 4), round(hi, 4)
    (-0.0461, -0.0164)
    """
    if nominal not in ("pldi", "midpoint"):
        raise PolyrobError(f"unknown nominal '{nominal}': use 'pldi' or 'midpoint'")
    A0, B0 = np.array(pldi.A0, dtype=float), np.array(pldi.B0, dtype=float)
    m = B0.shape[1]
    n = 2 * m
    if A0.shape != (n, n) or B0.shape != (n, m):
        raise BoundsError(f"the PLDI's nominal pair has shapes {A0.shape}, {B0.shape}; expected ({n}, {n}), ({n}, {m})")
    index = np.asarray(pldi.entry_index, dtype=int).reshape(-1, 3)
    names = tuple(pldi.entries)
    lower, upper, nom = (np.asarray(v, dtype=float) for v in (pldi.lower, pldi.upper, pldi.nominal))
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        raise BoundsError("the PLDI has non-finite bounds")
    if np.any(lower > upper):
        bad = [nm for nm, lo, hi in zip(names, lower, upper) if lo > hi]
        raise BoundsError(f"inverted intervals (lower > upper) for {', '.join(bad)}")
    # parameters: one per entry, or one per symmetric pair (placed at the pair's
    # first entry so the channel order stays the PLDI's entry order as far as possible)
    nom_check = 0.5 * (lower + upper) if nominal == "midpoint" else nom
    pairs = _symmetric_pairs(index, lower, upper, nom_check, m) if merge_symmetric else []
    partner = {k1: k2 for k1, k2 in pairs}
    absorbed = {k2 for _, k2 in pairs}
    groups: list[list[int]] = []
    for k in range(len(names)):
        if k in absorbed:
            continue
        groups.append([k, partner[k]] if k in partner else [k])
    channels = [k for g in groups for k in g]
    ch_param = np.array([p for p, g in enumerate(groups) for _ in g], dtype=int)
    # a merged pair is one function of the state whose two sampled intervals agree
    # to SYMMETRY_RTOL; both channels get the hull of the two, so B(δ) stays exactly
    # symmetric and each entry's own interval is still covered
    lower, upper = lower.copy(), upper.copy()
    for g in groups:
        lower[g], upper[g] = lower[g].min(), upper[g].max()
    mid = 0.5 * (lower + upper)
    rad = 0.5 * (upper - lower)

    # the LFT centre: the nominal with each varying entry at its midpoint
    # (constant entries keep the nominal's values)
    A_mid, B_mid = A0.copy(), B0.copy()
    for (mat, r, c), v in zip(index, mid):
        (A_mid if mat == 0 else B_mid)[r, c] = v
    if nominal == "midpoint":
        A_nom, B_nom, nom = A_mid.copy(), B_mid.copy(), mid.copy()
    else:
        A_nom, B_nom = A0, B0

    nd = len(channels)
    B_d = np.zeros((n, nd))
    C_v = np.zeros((nd, n))
    D_vu = np.zeros((nd, m))
    for j, k in enumerate(channels):
        mat, r, c = index[k]
        B_d[r, j] = rad[k]  # d_j enters state row r with the half-width as gain
        if mat == 0:
            C_v[j, c] = 1.0  # v_j = x_c
        else:
            D_vu[j, c] = 1.0  # v_j = u_c

    first = np.array([g[0] for g in groups], dtype=int)
    # a zero-width interval (possible with degenerate bounds) has no δ of its own: 0
    safe = np.where(rad[first] > 0, rad[first], 1.0)
    nominal_delta = np.where(rad[first] > 0, (nom[first] - mid[first]) / safe, 0.0)
    blk = np.array([[-len(g), 0] for g in groups], dtype=int).reshape(-1, 2)
    param_names = tuple("=".join(names[k] for k in g) for g in groups)

    return UncertainPlant(
        robot_name=getattr(pldi, "robot_name", ""),
        nominal_kind=nominal,
        A_nom=A_nom,
        B_nom=B_nom,
        C=np.hstack([np.eye(m), np.zeros((m, m))]),
        A_mid=A_mid,
        B_mid=B_mid,
        B_d=B_d,
        C_v=C_v,
        D_vu=D_vu,
        parameter_names=param_names,
        parameter_lower=lower[first].copy(),
        parameter_upper=upper[first].copy(),
        channel_names=tuple(names[k] for k in channels),
        channel_parameter=ch_param,
        channel_index=index[channels].copy() if nd else np.zeros((0, 3), dtype=int),
        channel_lower=lower[channels].copy(),
        channel_upper=upper[channels].copy(),
        nominal_delta=nominal_delta,
        offset=mid[first] - nom[first],
        block_structure=blk,
        merged=tuple((names[k1], names[k2]) for k1, k2 in pairs),
        info={"enclosure": getattr(pldi, "enclosure", None)},
    )
