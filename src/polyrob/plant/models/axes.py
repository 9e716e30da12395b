"""The ``axes`` uncertainty model: an oriented box in the principal directions, plus a residual block.

The varying Jacobian entries ``p`` (``k`` of them) are written::

    p = c + Σ_{j <= r} b_j z_j + e,     z_j ∈ [z_lo_j, z_hi_j],   e = W_l Δ W_r,  ‖Δ‖ <= 1

* ``b_j`` are the ``r`` strongest principal directions of the Jacobian cloud
  that :func:`~polyrob.bounds.pldi.bound_pldi` computed (``pldi.polytope.basis``),
  and ``[z_lo_j, z_hi_j]`` come from the PLDI's support values along ``±w_j``
  (its half-spaces: the same sampled, searched and verified extreme search
  as the intervals; ``w_j · b_i = δ_ij``);
* the residual ``e`` (what the retained directions leave out) is bounded
  entry by entry by linear programs over the PLDI's polytope (every Jacobian
  lies in it, and ``e`` is linear in ``p``), then covered by one full complex
  block ``Δ`` of the lower rows of ``[A B]`` with diagonal scalings chosen so that
  ``‖W_l^{-1} E W_r^{-1}‖_F <= 1`` for every ``E`` with those entry bounds.

Each retained direction moves a rank-``rank(b_j)`` matrix (both lower rows of
``[A B]`` in general), so it is a repeated real scalar ``[-rank, 0]``: the
entries it couples move together, as the real arm's do.  ``n_directions``
is chosen as the smallest ``r`` whose residual gain falls below
``residual_tol`` of the total spread, or given by hand.

The directions' ranges are sampled support values even when the PLDI's
intervals are certified, so the model's ``info["enclosure"]`` is
``"sampled"`` always (``info["enclosure_inputs"]`` keeps the PLDI's).
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from polyrob.errors import ArgumentError, BoundsError
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models.assembly import (
    Channels,
    at_pldi_nominal,
    check_nominal,
    into_accelerations,
    model_plant,
    normalised,
)

__all__ = [
    "axes_plant",
    "axes_contains",
    "entry_layout",
    "residual_block",
    "centred_matrices",
    "AxesChannels",
    "RESIDUAL_TOL",
]

#: Default: keep directions until the residual gain is at most this fraction of the total.
RESIDUAL_TOL = 0.1


def _residual_bounds(pldi, centre, basis_r, W_r):
    """Entrywise range of ``e = (I - b W)(p - c)`` over the polytope (2k LPs).

    The LPs run in the polytope's reduced coordinates ``p = c + basis z``
    (the Jacobians span that affine subspace: ``b32 = b41`` and the like hold
    exactly; the coverage check on fresh samples confirms it).
    """
    poly = pldi.polytope
    k = len(centre)
    Pi = (np.eye(k) - basis_r @ W_r) @ poly.basis
    G = poly.normals @ poly.basis
    g = poly.offsets - poly.normals @ centre
    r_all = poly.basis.shape[1]
    lo, hi = np.zeros(k), np.zeros(k)
    for i in range(k):
        row = Pi[i]
        if np.abs(row).max() < 1e-12 * (1.0 + np.abs(poly.basis[i]).max()):
            continue
        scale = np.abs(row).max()
        for sgn in (1.0, -1.0):
            res = _solve_lp(-sgn * row / scale, G, g, r_all)
            if res.status != 0:
                raise BoundsError(
                    f"the axes model's residual LP failed with every HiGHS method ({res.message}): the PLDI's "
                    "polytope is badly conditioned; give a smaller domain (--qdot-max, --u-max, --q-range) or "
                    "take another model (--uncertainty box)"
                )
            val = row @ res.x
            if sgn > 0:
                hi[i] = val
            else:
                lo[i] = val
    return lo, hi


def _solve_lp(c, G, g, n):
    """``min c x`` over ``G x <= g``, trying HiGHS' dual simplex, then its interior point and primal simplex.

    On badly scaled polytopes (support values of 1e6 next to 1e-3) the default
    choice can stop with status "Not Set"; another method of the same solver
    usually finishes (seen on z1's PLDI).
    """
    res = None
    for method in ("highs", "highs-ipm", "highs-ds"):
        res = optimize.linprog(c, A_ub=G, b_ub=g, bounds=[(None, None)] * n, method=method)
        if res.status == 0:
            return res
    return res


def entry_layout(pldi):
    """Index of the entries in the lower block rows of ``[A B]``: (row - m, column of [x; u])."""
    m = pldi.m
    idx = np.asarray(pldi.entry_index, int).reshape(-1, 3)
    return np.array([(r - m, c if mat == 0 else 2 * m + c) for mat, r, c in idx], int).reshape(-1, 2)


def residual_block(lay, rho, m: int):
    """The residual full complex block of per-entry radii ``rho`` (entries at ``lay``).

    Returns ``(B_f, C_f, gains)``: ``B_f`` (``m x k``) and ``C_f`` (``k x 3m``)
    carry the gains ``W_l``, ``W_r`` with ``‖diag(1/W_l) E diag(1/W_r)‖_F <= 1``
    whenever ``|E| <= rho`` entrywise, so ``E = B_f Δ_f C_f`` with
    ``‖Δ_f‖ <= 1`` covers every such ``E``; ``gains`` holds the rows, columns
    and gains for the plant's ``info``.  ``B_f = C_f = None`` when every radius is 0.
    """
    rho_mat = np.zeros((m, 3 * m))
    rho_mat[lay[:, 0], lay[:, 1]] = rho
    return residual_of_radii(rho_mat)


def residual_of_radii(rho_mat):
    """:func:`residual_block` of a matrix of entry radii (any shape: ``B_f`` has its rows, ``C_f`` its columns)."""
    rows = np.flatnonzero(rho_mat.max(axis=1) > 0)
    cols = np.flatnonzero(rho_mat.max(axis=0) > 0)
    size = max(len(rows), len(cols))
    if not size:
        return None, None, {"residual_rows": rows, "residual_cols": cols, "W_l": None, "W_r": None}
    R = rho_mat[np.ix_(rows, cols)]
    b = np.sqrt(R.max(axis=0))
    a = np.sqrt(len(rows) * ((R / b[None, :]) ** 2).sum(axis=1))
    Bf = np.zeros((rho_mat.shape[0], size))
    Bf[rows, np.arange(len(rows))] = a
    Cf = np.zeros((size, rho_mat.shape[1]))
    Cf[np.arange(len(cols)), cols] = b
    return Bf, Cf, {"residual_rows": rows, "residual_cols": cols, "W_l": a, "W_r": b}


def centred_matrices(pldi, lay, centre):
    """``(A_mid, B_mid)``: the PLDI's nominal pair with its varying entries (at ``lay``) set to ``centre``."""
    m = pldi.m
    A0, B0 = np.asarray(pldi.A0, float), np.asarray(pldi.B0, float)
    AB = np.hstack([A0[m:], B0[m:]])
    AB[lay[:, 0], lay[:, 1]] = centre
    A_mid, B_mid = A0.copy(), B0.copy()
    A_mid[m:], B_mid[m:] = AB[:, : 2 * m], AB[:, 2 * m :]
    return A_mid, B_mid


class AxesChannels:
    """The ``Δ`` channels of an ``axes``-shaped plant, in order: the residual full block, then the directions.

    Each direction moves the lower rows of ``[A B]`` by a matrix of rank
    ``r`` (both rows in general): one real scalar repeated ``r`` times.
    """

    def __init__(self, lay, m: int):
        self.lay, self.m = lay, m
        self._B, self._C, self._blocks, self._names, self._parameter = [], [], [], [], []

    def _add(self, B, C, block, name: str, parameter: int) -> None:
        size = B.shape[1]
        self._B.append(B)
        self._C.append(C)
        self._blocks.append(block)
        self._names += [f"{name}#{i}" for i in range(size)]
        self._parameter += [parameter] * size

    def residual(self, rho) -> dict:
        """Add the full block of per-entry radii ``rho`` (none when every radius is 0); its gains for ``info``."""
        Bf, Cf, gains = residual_block(self.lay, rho, self.m)
        if Bf is not None:
            self._add(Bf, Cf, [Bf.shape[1], Bf.shape[1]], "res", -1)
        return gains

    def direction(self, entries, name: str, parameter: int) -> None:
        """Add a repeated real scalar moving the varying entries by ``entries`` (its half-width included)."""
        E = np.zeros((self.m, 3 * self.m))
        E[self.lay[:, 0], self.lay[:, 1]] = entries
        U, s, Vt = np.linalg.svd(E)
        rank = int(np.sum(s > 1e-12 * max(s[0], 1e-300)))
        self._add(U[:, :rank] * s[:rank], Vt[:rank], [-rank, 0], name, parameter)

    def channels(self) -> Channels:
        """The channels added so far, as :func:`~polyrob.plant.models.assembly.model_plant` takes them."""
        m = self.m
        B_low = np.hstack(self._B) if self._B else np.zeros((m, 0))
        C_vu = np.vstack(self._C) if self._C else np.zeros((0, 3 * m))
        return Channels(
            into_accelerations(m) @ B_low,
            C_vu[:, : 2 * m],
            C_vu[:, 2 * m :],
            self._blocks,
            self._names,
            self._parameter,
        )


def axes_plant(
    pldi, *, n_directions: int | None = None, residual_tol: float = RESIDUAL_TOL, nominal: str = "pldi"
) -> UncertainPlant:
    """The ``axes`` model of a PLDI (see the module docstring).

    Parameters
    ----------
    pldi : PLDI
    n_directions : int, optional
        Retained principal directions (default: automatic, see ``residual_tol``).
    residual_tol : float
        Automatic choice: the smallest ``r`` whose residual gain ``‖ρ‖_F`` (in
        the PLDI's normalised units) is at most this fraction of the total spread.
    nominal : {"pldi", "midpoint"}

    Raises
    ------
    PolyrobError
        ``n_directions`` out of range, unknown nominal.
    """
    check_nominal(nominal)
    poly = pldi.polytope
    m, k = pldi.m, len(pldi.entries)
    lower, upper = np.asarray(pldi.lower, float), np.asarray(pldi.upper, float)
    # the principal directions whose supports the PLDI searched: rows 2k.. of the half-spaces
    n_pc = (poly.n_halfspaces - 2 * k) // 2
    W_all = poly.normals[2 * k : 2 * k + n_pc]  # w_j (normals), w_j . b_i = δ_ij
    basis_all = poly.basis[:, :n_pc]
    h_plus, h_minus = poly.offsets[2 * k : 2 * k + n_pc], poly.offsets[2 * k + n_pc : 2 * k + 2 * n_pc]
    centre0 = poly.centre
    spread = np.linalg.norm((upper - lower) / 2.0 / np.maximum(upper - lower, 1e-300))
    norm_unit = np.maximum(upper - lower, 1e-300)

    def build(r):
        W_r, b_r = W_all[:r], basis_all[:, :r]
        z_hi, z_lo = h_plus[:r] - W_r @ centre0, -h_minus[:r] - W_r @ centre0
        e_lo, e_hi = _residual_bounds(pldi, centre0, b_r, W_r)
        return W_r, b_r, z_lo, z_hi, e_lo, e_hi

    if n_directions is None:
        chosen = None
        for r in range(0, n_pc + 1):
            parts = build(r)
            e_lo, e_hi = parts[4], parts[5]
            if np.linalg.norm(np.maximum(np.abs(e_lo), np.abs(e_hi)) / norm_unit) <= residual_tol * spread:
                chosen = (r, parts)
                break
        if chosen is None:
            chosen = (n_pc, build(n_pc))
        r, (W_r, b_r, z_lo, z_hi, e_lo, e_hi) = chosen
    else:
        r = int(n_directions)
        if not 0 <= r <= n_pc:
            raise ArgumentError(f"n_directions must lie in [0, {n_pc}] (the searched principal directions), got {r}")
        W_r, b_r, z_lo, z_hi, e_lo, e_hi = build(r)

    # centre: the cloud mean moved to the middle of the z box; the residual
    # (I - b W)(p - c0) keeps its own centre 0 (an entrywise mid-point would
    # leave the residual subspace and shift z), so its bound is max(|lo|, |hi|)
    z_mid, z_rad = 0.5 * (z_lo + z_hi), 0.5 * (z_hi - z_lo)
    rho = np.maximum(np.abs(e_lo), np.abs(e_hi))
    centre = centre0 + b_r @ z_mid
    lay = entry_layout(pldi)
    A_mid, B_mid = centred_matrices(pldi, lay, centre)
    stack = AxesChannels(lay, m)
    gains = stack.residual(rho)
    for j in range(r):
        stack.direction(b_r[:, j] * z_rad[j], f"z{j + 1}", j)
    plant = model_plant(
        pldi,
        "axes",
        (A_mid, B_mid),
        stack.channels(),
        ([f"z{j + 1}" for j in range(r)], z_lo + 0.0, z_hi + 0.0),
        # the directions' ranges are the PLDI's sampled support values (and the residual's
        # LPs run over its polytope of sampled half-spaces), certified intervals or not
        info={
            "enclosure": "sampled",
            "enclosure_inputs": {"PLDI": pldi.enclosure, "directions": "sampled"},
            "n_directions": r,
            "searched_directions": n_pc,
            "residual_gain": float(np.linalg.norm(rho / norm_unit)),
            "spread": float(spread),
            "centre": centre,
            "basis": b_r,
            "W": W_r,
            "z_mid": z_mid,
            "z_rad": z_rad,
            **gains,
            "layout": lay,
        },
        nominal_kind=nominal,
    )
    if nominal == "midpoint":
        return plant
    nd = normalised(W_r @ (np.asarray(pldi.nominal, float) - centre), z_rad)
    return at_pldi_nominal(plant, pldi, nd, z_rad)


def axes_contains(unc: UncertainPlant, A, B, *, rtol: float = 1e-9) -> np.ndarray:
    """Whether Jacobians lie in an ``axes`` model's set (a sufficient test).

    The split ``p = c + b z + e`` is the projection used to bound the
    residual (the one every Jacobian of the robot has), so ``True`` proves
    membership; a member built with another split may test ``False``.

    ``z = W (p - c)`` must lie in the directions' ranges and the residual
    ``E = p - c - b z`` (as a matrix of the lower rows of ``[A B]``) must satisfy
    ``‖diag(1/W_l) E diag(1/W_r)‖_2 <= 1``; constant entries must equal the centre's.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    if A.ndim == 2:
        A, B = A[None], B[None]
    info = unc.info
    m = unc.m
    lay = info["layout"]
    AB = np.concatenate([A[:, m:], B[:, m:]], axis=2)  # (N, m, 3m)
    AB_c = np.hstack([unc.A_mid[m:], unc.B_mid[m:]])
    p = AB[:, lay[:, 0], lay[:, 1]]
    d = p - info["centre"]
    z = d @ info["W"].T
    zr = info["z_rad"]
    ok = np.all(np.abs(z) <= zr * (1 + rtol) + rtol, axis=1)
    e = d - z @ info["basis"].T
    E = np.zeros_like(AB)
    E[:, lay[:, 0], lay[:, 1]] = e
    const = AB.copy()
    const[:, lay[:, 0], lay[:, 1]] = 0.0
    AB_c0 = AB_c.copy()
    AB_c0[lay[:, 0], lay[:, 1]] = 0.0
    ok &= np.all(np.abs(const - AB_c0) <= rtol * (1 + np.abs(AB_c0)), axis=(1, 2))
    ok &= np.all(np.abs(A[:, :m] - unc.A_mid[:m]) <= rtol, axis=(1, 2)) & np.all(np.abs(B[:, :m]) <= rtol, axis=(1, 2))
    rows, cols = info["residual_rows"], info["residual_cols"]
    if len(rows):
        S = E[:, rows][:, :, cols] / info["W_l"][None, :, None] / info["W_r"][None, None, :]
        ok &= np.linalg.norm(S, 2, axis=(1, 2)) <= 1.0 + rtol
        outside = np.ones((m, 3 * m), bool)
        outside[np.ix_(rows, cols)] = False
        ok &= np.all(np.abs(E[:, outside]) <= rtol, axis=1)
    else:
        ok &= np.all(np.abs(e) <= rtol * (1 + np.abs(p)), axis=1)
    return ok
