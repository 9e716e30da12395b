"""The ``lft`` uncertainty model: the inverse inertia as an exact LFT in a few joint variables.

``B_low = M(q)^{-1}`` depends on the positions only.  Where the inertia
matrix is *affine in the cosines and sines of single joint angles*,
``M(q) = M_0 + Σ_f φ_f(q) M_f`` (every planar 2R arm: ``M = M_0 + cos q_2 M_1``),
its inverse is an exact LFT in the real scalars ``φ_f``: the whole ``B``
block moves along its true curve (``repeated=True``, block ``[-rank M_f, 0]``)
or, by default, on the sheet spanned by the rank-one pieces of ``M_f`` with
independent parameters (blocks ``[-1, 0]``, which AB13MD and the fast D-G-K
steps handle); either way ``det B`` stays near its real range instead of
falling towards 0 as in the paper's box.

``A_low`` is modelled as the paper's (``a_part="entries"``, default): one real
parameter per varying entry with the PLDI's intervals, so the model is a
subset of the box.  ``a_part="torque"`` writes instead
``[A_low B_low] = M(q)^{-1} [N(x, u) I]`` with ``N = M(q) A_low`` the
torque-side Jacobian, boxed with the same sampled + searched + verified
extreme search as the PLDI (:func:`polyrob.bounds.pldi.bound_pldi` run on
``N``): fewer parameters, but the product can leave the ``A`` intervals.

The fit of ``M(q)`` is checked on random configurations (relative residual
below :data:`AFFINE_RTOL`); where it fails (spatial arms with three or more
coupled joints, whose inertia has products of trigonometric terms) the model
does not apply and :class:`NotApplicable` is raised (``model="auto"`` then
takes ``axes``).
"""

from __future__ import annotations

import numpy as np

from polyrob.errors import ArgumentError, NotApplicable
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models import assembly

__all__ = [
    "inertia_lft_plant",
    "inertia_lft_contains",
    "affine_inertia",
    "NotApplicable",
    "AFFINE_RTOL",
    "TorqueJacobians",
    "torque_side_pldi",
]

#: Largest relative residual of the affine fit of ``M(q)`` that counts as exact.
AFFINE_RTOL = 1e-9


def _trig_range(fn: str, lo: float, hi: float) -> tuple[float, float]:
    """Exact range of ``cos``/``sin`` over ``[lo, hi]``."""
    f = np.cos if fn == "cos" else np.sin
    pts = [lo, hi]
    off = 0.0 if fn == "cos" else 0.5 * np.pi  # extremes at k pi (cos), pi/2 + k pi (sin)
    k0, k1 = int(np.ceil((lo - off) / np.pi)), int(np.floor((hi - off) / np.pi))
    pts += [off + k * np.pi for k in range(k0, k1 + 1)]
    v = f(np.array(pts))
    return float(max(-1.0, v.min())), float(min(1.0, v.max()))


def affine_inertia(robot, domain, *, samples: int = 64, seed: int = 0):
    """Fit ``M(q) = M_0 + Σ_f φ_f(q) M_f`` with ``φ ∈ {cos q_j, sin q_j}``.

    Returns
    -------
    names : list of str
        ``"cos(q2)"``, ... (1-based joints), the features kept.
    joints, kinds : list
        Joint index and ``"cos"``/``"sin"`` of each feature.
    M0 : ndarray (m, m)
    Mf : list of ndarray (m, m)
    ranges : ndarray (F, 2)
        Exact range of each feature over the domain's position box.

    Raises
    ------
    NotApplicable
        The fit is not exact (relative residual above :data:`AFFINE_RTOL`).
    """
    m = robot.m
    rng = np.random.default_rng(seed)
    lo, hi = domain.q_lower, domain.q_upper
    q = lo + rng.random((samples, m)) * (hi - lo)
    Ms = np.array([robot.mass_matrix(qq) for qq in q])
    feats, joints, kinds = [np.ones(samples)], [], []
    for j in range(m):
        if hi[j] > lo[j]:
            for fn, f in (("cos", np.cos), ("sin", np.sin)):
                feats.append(f(q[:, j]))
                joints.append(j)
                kinds.append(fn)
    X = np.column_stack(feats)
    Y = Ms.reshape(samples, -1)
    coef, *_ = np.linalg.lstsq(X, Y, rcond=None)
    resid = np.abs(X @ coef - Y).max()
    scale = np.abs(Y).max()
    if resid > AFFINE_RTOL * scale:
        raise NotApplicable(
            f"{robot.name}: the inertia matrix is not affine in cos/sin of single joint angles "
            f"(fit residual {resid / scale:.2g} of its size): the lft model needs that (planar 2R arms)"
        )
    M0 = coef[0].reshape(m, m)
    keep = [i for i in range(1, len(feats)) if np.abs(coef[i]).max() > 1e3 * AFFINE_RTOL * scale]
    Mf = [0.5 * (coef[i].reshape(m, m) + coef[i].reshape(m, m).T) for i in keep]
    joints = [joints[i - 1] for i in keep]
    kinds = [kinds[i - 1] for i in keep]
    names = [f"{k}(q{j + 1})" for j, k in zip(joints, kinds)]
    ranges = np.array([_trig_range(k, lo[j], hi[j]) for j, k in zip(joints, kinds)]).reshape(-1, 2)
    return names, joints, kinds, M0, Mf, ranges


class TorqueJacobians:
    """A robot stand-in whose Jacobians are ``[0 I; N]`` and ``[0; I]`` with ``N = M(q) A_low``.

    Lets :func:`~polyrob.bounds.pldi.bound_pldi` bound ``N`` with the same
    extreme search as the PLDI (``N`` is, like ``A``, affine in ``u`` and
    quadratic in ``q̇`` for fixed ``q``).
    """

    def __init__(self, robot):
        self._robot = robot
        self.name, self.source, self.m = robot.name + "/N", robot.source, robot.m
        self.joint_names = robot.joint_names

    def __getattr__(self, item):
        if item.startswith("__") or "_robot" not in self.__dict__:  # unpickling (a bounds worker): not yet set
            raise AttributeError(item)
        return getattr(self._robot, item)

    def jacobians_batch(self, q, qdot, u):
        A, B = self._robot.jacobians_batch(q, qdot, u)
        m = self.m
        M = np.linalg.inv(B[:, m:, :])  # B_low = M(q)^-1 (checked before this is used)
        A = A.copy()
        A[:, m:, :] = M @ A[:, m:, :]
        B = np.zeros_like(B)
        B[:, m:, :] = np.eye(m)
        return A, B

    def jacobians(self, q, qdot, u):
        A, B = self.jacobians_batch(np.atleast_2d(q), np.atleast_2d(qdot), np.atleast_2d(u))
        return A[0], B[0]


def torque_side_pldi(pldi, robot, bound_options: dict | None = None):
    """The PLDI of the torque-side Jacobian ``N = M(q) A_low`` (:class:`TorqueJacobians`) over ``pldi``'s domain.

    The PLDI's number of samples, no progress bars and no coverage check
    unless ``bound_options`` says otherwise.
    """
    from polyrob.bounds.pldi import bound_pldi

    opts = {"samples": pldi.info.get("samples"), "progress": False, "coverage": 0, **(bound_options or {})}
    return bound_pldi(TorqueJacobians(robot), pldi.domain, **opts)


def _factor(Mf: np.ndarray):
    """``M_f = U V`` with ``U`` (m, r), ``V`` (r, m), ``r = rank M_f`` (symmetric eigen-split)."""
    lam, Q = np.linalg.eigh(Mf)
    keep = np.abs(lam) > 1e-12 * np.abs(lam).max()
    return Q[:, keep] * lam[keep], Q[:, keep].T


def inertia_lft_plant(
    pldi,
    *,
    robot=None,
    nominal: str = "pldi",
    repeated: bool = False,
    a_part: str = "entries",
    bound_options: dict | None = None,
) -> UncertainPlant:
    """The ``lft`` model of a PLDI (see the module docstring).

    Parameters
    ----------
    pldi : PLDI
    robot : Manipulator, optional
        Default: loaded again from the PLDI.
    nominal : {"pldi", "midpoint"}
    repeated : bool
        ``True``: each ``φ_f`` is one repeated real scalar ``[-rank M_f, 0]``,
        the exact inverse inertia (μ then needs the LMI upper bound, slow).
        ``False`` (default): the rank-one pieces of ``M_f = Σ λ q qᵀ`` get
        independent parameters over ``φ_f``'s range (blocks ``[-1, 0]``,
        AB13MD and the fast D-G-K steps apply); the inertia then moves on a
        sheet instead of a curve, still nonsingular and far inside the box.
    a_part : {"entries", "torque"}
        How ``A_low`` is modelled.  ``"entries"`` (default): one real
        parameter per varying entry of ``A`` with the PLDI's intervals (the
        paper's ``A`` part), so the model is the paper's box with its ``B``
        part replaced by the exact curve: a subset of the box, never larger.
        ``"torque"``: ``A_low = M(q)^{-1} N`` with a box on ``N``'s entries
        (fewer parameters, but the product can leave the ``A`` intervals).
    bound_options : dict, optional
        Passed to :func:`~polyrob.bounds.pldi.bound_pldi` when bounding ``N``
        (default: the PLDI's number of samples, no progress bars).

    Raises
    ------
    NotApplicable
        ``M(q)`` is not affine in single-angle cos/sin terms, ``B`` is not
        ``[0; M^{-1}]``, or the robot is an inner closed loop.
    """
    from polyrob.bounds.pldi import entry_name

    assembly.check_nominal(nominal)
    robot = pldi.robot if robot is None else robot
    if getattr(robot, "inner", None) not in (None, "none"):
        # the model is M(q)^-1 of one robot; an inner loop's PLDI spans several true robots (talos: coverage 1/3)
        raise NotApplicable(f"{robot.name}: an inner closed loop ({robot.inner}), not the robot's own M(q)^-1")
    m = robot.m
    n = 2 * m
    names, _, _, M0, Mf, ranges = affine_inertia(robot, pldi.domain)
    assembly.check_inverse_inertia_input(robot, pldi.domain, "lft")
    if a_part not in ("entries", "torque"):
        raise ArgumentError(f"unknown a_part '{a_part}': use 'entries' or 'torque'")
    torque = a_part == "torque"
    npldi = torque_side_pldi(pldi, robot, bound_options) if torque else pldi
    nidx = np.asarray(npldi.entry_index, int).reshape(-1, 3)
    if torque and np.any(nidx[:, 0] != 0):
        raise NotApplicable(f"{robot.name}: M(q) B is not constant; the lft model does not apply")
    n_sel = nidx[:, 0] == 0  # the A entries (the B entries are the inertia's)
    nidx = nidx[n_sel]
    n_lo, n_hi = np.asarray(npldi.lower, float)[n_sel], np.asarray(npldi.upper, float)[n_sel]
    n_mid, n_rad = 0.5 * (n_lo + n_hi), 0.5 * (n_hi - n_lo)
    N_c = np.asarray(npldi.A0, float)[m:, :].copy()
    for (_, r, c), v in zip(nidx, n_mid):
        N_c[r - m, c] = v

    th_mid, th_rad = ranges.mean(axis=1), 0.5 * (ranges[:, 1] - ranges[:, 0])
    M_c = M0 + sum(t * F for t, F in zip(th_mid, Mf))
    Minv = np.linalg.inv(M_c)
    facs = [_factor(F) for F in Mf]
    if not repeated:  # one parameter per rank-one piece, over the feature's range
        names = [
            f"{nm}#{i + 1}" if Uf.shape[1] > 1 else nm for nm, (Uf, _) in zip(names, facs) for i in range(Uf.shape[1])
        ]
        th_mid = np.repeat(th_mid, [Uf.shape[1] for Uf, _ in facs])
        th_rad = np.repeat(th_rad, [Uf.shape[1] for Uf, _ in facs])
        ranges = np.repeat(ranges, [Uf.shape[1] for Uf, _ in facs], axis=0)
        facs = [(Uf[:, [i]], Vf[[i]]) for Uf, Vf in facs for i in range(Uf.shape[1])]
        Mf = [Uf @ Vf for Uf, Vf in facs]
    U = np.hstack([r * Uf for r, (Uf, _) in zip(th_rad, facs)]) if facs else np.zeros((m, 0))
    V = np.vstack([Vf for _, Vf in facs]) if facs else np.zeros((0, m))
    k, nt = len(nidx), U.shape[1]
    nd = k + nt
    E = np.zeros((m, k))  # d_N enters w = N x + u at the entry's row, with its half-width
    C_N = np.zeros((k, n))
    for j, (_, r, c) in enumerate(nidx):
        E[r - m, j] = n_rad[j]
        C_N[j, c] = 1.0
    low = assembly.into_accelerations(m)
    # torque: x_low' = M^-1 (N x + u); entries: x_low' = A_low x + M^-1 u
    T = Minv if torque else np.eye(m)
    B_d = np.hstack([low @ T @ E, -(low @ Minv @ U)])
    C_v = np.vstack([C_N, V @ Minv @ N_c if torque else np.zeros((nt, n))])
    D_vu = np.vstack([np.zeros((k, m)), V @ Minv])
    D_vd = np.zeros((nd, nd))
    if torque:
        D_vd[k:, :k] = V @ Minv @ E
    D_vd[k:, k:] = -V @ Minv @ U
    A_mid = assembly.arm_state_matrix(T @ N_c)
    B_mid = low @ Minv

    n_names = tuple(entry_name("N" if torque else "A", r, c, n) for _, r, c in nidx)
    par_names = n_names + tuple(names)
    ch_param = np.concatenate([np.arange(k), np.repeat(k + np.arange(len(facs)), [Uf.shape[1] for Uf, _ in facs])])
    ch_names = n_names + tuple(f"{names[p - k]}@{i}" for i, p in enumerate(ch_param[k:]))
    blk = [[-1, 0]] * k + [[-Uf.shape[1], 0] for Uf, _ in facs]
    inputs = {"PLDI": pldi.enclosure, **({"N PLDI": npldi.enclosure} if torque else {})}
    plant = assembly.model_plant(
        pldi,
        "lft-torque" if torque else "lft",
        (A_mid, B_mid),
        assembly.Channels(B_d, C_v, D_vu, blk, ch_names, ch_param, D_vd),
        (par_names, np.r_[n_lo, ranges[:, 0]], np.r_[n_hi, ranges[:, 1]]),
        {
            **assembly.enclosure_info(inputs),
            "N_enclosure": npldi.enclosure,
            "M0": M0,
            "Mf": Mf,
            "repeated": repeated,
            "a_part": a_part,
            "N_centre": N_c,
            "N_index": nidx,
            "N_seconds": npldi.info.get("seconds_total") if torque else 0.0,
        },
        nominal_kind=nominal,
    )
    if nominal == "midpoint":
        return plant
    _, delta = _locate(plant, pldi.A0, pldi.B0)
    return assembly.at_pldi_nominal(plant, pldi, np.where(np.isfinite(delta[0]), delta[0], 0.0), np.r_[n_rad, th_rad])


def _locate(unc: UncertainPlant, A, B):
    """``δ`` (n, n_params) of Jacobians (n, ...) in the model's coordinates, and whether each fits exactly.

    ``φ`` comes from ``M = B_low^{-1}`` by least squares on the ``M_f``; ``N = M A_low``.
    """
    m = unc.m
    Mf = unc.info["Mf"]
    nidx = unc.info["N_index"]
    lo, hi = unc.parameter_lower, unc.parameter_upper
    mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
    A, B = np.asarray(A, float), np.asarray(B, float)
    if A.ndim == 2:
        A, B = A[None], B[None]
    n = len(A)
    fit = np.ones(n, bool)
    Bl = B[:, m:, :]
    good = np.abs(np.linalg.det(Bl)) > 0
    fit &= good
    M = np.linalg.inv(np.where(good[:, None, None], Bl, np.eye(m)))
    X = np.column_stack([F.ravel() for F in Mf]) if Mf else np.zeros((m * m, 0))
    Y = (M - unc.info["M0"]).reshape(n, -1)
    phi = Y @ np.linalg.pinv(X).T if X.shape[1] else np.zeros((n, 0))
    fit &= np.abs(phi @ X.T - Y).max(axis=1) <= 1e-7 * np.abs(M).reshape(n, -1).max(axis=1)
    N = M @ A[:, m:, :] if unc.info["a_part"] == "torque" else A[:, m:, :]
    rows, cols = nidx[:, 1] - m, nidx[:, 2]
    nvals = N[:, rows, cols]
    Nc = np.repeat(unc.info["N_centre"][None], n, axis=0)
    Nc[:, rows, cols] = nvals
    fit &= np.abs(Nc - N).max(axis=(1, 2)) <= 1e-7 * (1.0 + np.abs(N).max(axis=(1, 2)))
    top = np.hstack([np.zeros((m, m)), np.eye(m)])
    fit &= np.all(np.abs(A[:, :m] - top) <= 1e-12, axis=(1, 2)) & np.all(B[:, :m] == 0, axis=(1, 2))
    vals = np.hstack([nvals, phi])
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(rad > 0, (vals - mid) / np.where(rad > 0, rad, 1.0), np.where(vals == mid, 0.0, np.inf))
    return fit, delta


def inertia_lft_contains(unc: UncertainPlant, A, B, *, rtol: float = 1e-9) -> np.ndarray:
    """Whether Jacobians ``A`` (n, 2m, 2m), ``B`` (n, 2m, m) lie in an ``lft`` model's set.

    ``φ`` is recovered from ``M = B_low^{-1}`` (it must fit exactly), ``N = M A_low``;
    both must lie in their ranges (up to ``rtol`` of the range's size).
    """
    fit, delta = _locate(unc, A, B)
    lo, hi = unc.parameter_lower, unc.parameter_upper
    tol = rtol * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
    mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
    with np.errstate(invalid="ignore"):
        vals = mid + rad * delta
    return fit & np.all((vals >= lo - tol) & (vals <= hi + tol), axis=1)
