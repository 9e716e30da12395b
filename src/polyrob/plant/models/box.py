"""The paper's uncertainty model: one independent real parameter per varying entry (``model="box"``).

:func:`box_plant` turns a :class:`~polyrob.bounds.pldi.PLDI` into an
:class:`~polyrob.plant.lftplant.UncertainPlant`, MATLAB's ``uss`` built from one ``ureal`` per varying
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
>>> from polyrob.plant.models.box import box_plant
>>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
>>> unc = box_plant(pldi)
>>> unc.parameter_names
('a32', 'a33', 'a34', 'a42', 'a43', 'a44', 'b31', 'b32', 'b41', 'b42')
>>> unc.block_structure.tolist()[:2], unc.n_delta
([[-1, 0], [-1, 0]], 10)
>>> box_plant(pldi, merge_symmetric=True).block_structure[-2:].tolist()
[[-2, 0], [-1, 0]]
"""

from __future__ import annotations

import numpy as np

from polyrob.errors import BoundsError
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models.assembly import Channels, check_nominal, enclosure_info, model_plant, normalised

__all__ = ["box_plant", "box_contains", "SYMMETRY_RTOL"]

#: Relative tolerance for "identical bounds" when merging symmetric entries.
SYMMETRY_RTOL = 1e-9


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


def box_plant(pldi, *, nominal: str = "pldi", merge_symmetric: bool = False) -> UncertainPlant:
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
    >>> from polyrob.plant.models.box import box_plant
    >>> pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=256, coverage=0, progress=False)
    >>> unc = box_plant(pldi, merge_symmetric=True)
    >>> unc.n_params, unc.n_delta, unc.merged
    (9, 10, (('b32', 'b41'),))
    >>> lo, hi = unc.ranges["b32=b41"]
    >>> round(lo, 4), round(hi, 4)
    (-0.0461, -0.0164)
    """
    check_nominal(nominal)
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

    # a zero-width interval (possible with degenerate bounds) has no δ of its own: 0 (normalised)
    first = np.array([g[0] for g in groups], dtype=int)
    param_names = tuple("=".join(names[k] for k in g) for g in groups)

    return model_plant(
        pldi,
        "box",
        (A_mid, B_mid),
        Channels(B_d, C_v, D_vu, [[-len(g), 0] for g in groups], [names[k] for k in channels], ch_param),
        (param_names, lower[first].copy(), upper[first].copy()),
        # the box is the PLDI's intervals: exactly as proved as they are
        enclosure_info({"PLDI": getattr(pldi, "enclosure", None)}),
        nominal_kind=nominal,
        A_nom=A_nom,
        B_nom=B_nom,
        channel_index=index[channels].copy() if nd else np.zeros((0, 3), dtype=int),
        channel_lower=lower[channels].copy(),
        channel_upper=upper[channels].copy(),
        nominal_delta=normalised(nom[first] - mid[first], rad[first]),
        offset=mid[first] - nom[first],
        merged=tuple((names[k1], names[k2]) for k1, k2 in pairs),
    )


def box_contains(unc: UncertainPlant, A, B, *, rtol: float = 1e-9) -> np.ndarray:
    """Whether Jacobians ``A`` (n, 2m, 2m), ``B`` (n, 2m, m) lie in a box model's set.

    Every channel's entry must lie in its interval and every other entry must
    equal the centre's (to ``rtol`` of the entry's size).
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    if A.ndim == 2:
        A, B = A[None], B[None]
    A_lo, A_hi = unc.A_mid.copy(), unc.A_mid.copy()
    B_lo, B_hi = unc.B_mid.copy(), unc.B_mid.copy()
    for (mat, r, c), lo, hi in zip(unc.channel_index, unc.channel_lower, unc.channel_upper):
        (A_lo if mat == 0 else B_lo)[r, c] = lo
        (A_hi if mat == 0 else B_hi)[r, c] = hi

    def inside(X, lo, hi):
        tol = rtol * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
        return np.all((X >= lo - tol) & (X <= hi + tol), axis=(1, 2))

    return inside(A, A_lo, A_hi) & inside(B, B_lo, B_hi)
