"""``inner-gain`` with rotor inertia or a payload: computed torque as an exact LFT in its physical scalars.

A computed-torque inner layer ``u = M_hat(q) v + h_hat(q, qdot)`` computes
with a model that has the true rotor (armature) inertia ``R``, link masses
and inertias ``L`` off by one factor, and the middle of a payload range.
The true robot differs from the model by scalars ``theta_k`` on which its
inertia and its torques depend affinely: the link factor (``theta = 1 -
s``: ``M = M_hat - theta L``) and the payload mass (``theta = mass -
mass_mid`` at a fixed centre of mass: ``M = M_hat + theta P``).  Writing
``M = M_hat (I - sum theta_k G_k)`` and the torque mismatch the same way,
the outer input ``v`` and the true robot's acceleration ``a`` satisfy
exactly::

    a = v + sum_k theta_k (G_k(q) a + phi_k(q, qdot))

(``G = M_hat^-1 L`` for the links, ``-M_hat^-1 P`` for the payload), so the
inner loop's Jacobians are ``[A_low B_low] = (I - sum theta_k G_k)^-1 [sum
theta_k J_k, I]`` with ``J_k = d(G_k a + phi_k)/dx``, and the loop is the LFT::

    a = v + sum_k w_k,   w_k = theta_k z_k,   z_k = K_k [x; a],   K_k = [J_k  G_k]

one real scalar per ``theta_k`` repeated on ``m`` channels; ``G_k`` is fed
back through them (``D_vd``).  Without armature and payload ``G = I`` and
this is the one-gain model of :mod:`~polyrob.plant.models.inner_gain`; with
them ``B_low`` is no multiple of ``I`` (talos' arm: ``G`` has eigenvalues
from about 0 on the wrist to 0.9 on the shoulder).  The factors move over
the domain, ``K_k = K_k,c + E_k``: the loop is ``a = v + sum_k theta_k
K_k,c [x; a] + E [x; a]`` with ``E = sum_k theta_k E_k`` within ``sum_k
r_k |E_k|`` entrywise (``r_k`` the half range of ``theta_k``), carried by
full complex blocks as ``axes`` carries its residual: one for the state
columns ``J`` and one for the acceleration columns ``G``
(:func:`residual_blocks`).  Every true robot
is then a member exactly (its ``theta``, and ``E`` its ``[B_low^-1 A_low, I
- B_low^-1]`` less ``sum theta_k K_k,c``), and membership is convex in
``theta``.  ``K_k`` does not depend on the ``theta``: a task domain fixes
``a``, so each factor's ranges come from one true robot that differs from
the model in ``theta_k`` alone, ``K_k = [B_low^-1 A_low, I - B_low^-1] /
theta_k``, bounded by the PLDI's own search on that map
(:class:`FactorLoop`), or proved, when the PLDI carries the proof of
``bound_pldi(..., certify=True)`` (:func:`proved_factor_ranges`): the
model then rests on nothing sampled.  A torque box (``a`` would depend on the ``theta``)
and a payload whose centre of mass ranges (it enters as ``mass x
offset``) are refused.

Why by hand: MATLAB's ``uss`` would hold this LFT, but the factors and their
ranges over a robot's task are polyrob's own.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from polyrob.errors import ArgumentError, NotApplicable
from polyrob.model.inner import InnerLoopRobot
from polyrob.plant.lftplant import UncertainPlant
from polyrob.plant.models.assembly import (
    Channels,
    arm_state_matrix,
    enclosure_info,
    into_accelerations,
    model_plant,
)
from polyrob.plant.models.axes import entry_layout, residual_of_radii

#: ``residual="real"``: entries of the residual below this (relative to its largest, at least 1) get no scalar.
NEGLIGIBLE_ENTRY = 1e-12

__all__ = [
    "FactorLoop",
    "factor_parameters",
    "inner_factors_plant",
    "factor_lft_plant",
    "bound_one_robot",
    "proved_factor_ranges",
    "residual_blocks",
]


@dataclass(frozen=True, eq=False)
class FactorLoop(InnerLoopRobot):
    """A true robot's inner loop whose Jacobians are reported as its factor ``K = [J G]``.

    The true robot differs from the model in one scalar, ``theta``:
    ``jacobians_batch`` returns ``A`` with lower rows ``J = B_low^-1 A_low /
    theta`` and ``B`` with lower rows ``G = (I - B_low^-1) / theta``, so that
    :func:`polyrob.bound_pldi` bounds ``K`` with the search it uses for any
    Jacobian.
    """

    theta: float = 0.1
    #: ``B`` is a factor, not an inverse inertia: the bounds do not check it for positive definiteness.
    jacobians_are_factors = True

    def jacobians_batch(self, q, qdot, v):
        A, B = super().jacobians_batch(q, qdot, v)
        m = self.m
        inverse = np.linalg.inv(B[:, m:])
        A[:, m:] = inverse @ A[:, m:] / self.theta
        B[:, m:] = (np.eye(m) - inverse) / self.theta
        return A, B


def factor_parameters(robot) -> list[tuple[str, float, FactorLoop]]:
    """``(name, half range, factor loop)`` of each scalar in which ``robot``'s true robots differ from its model.

    Raises
    ------
    NotApplicable
        A payload whose centre of mass ranges.
    """
    payload = robot.payload
    mass, com = payload.midpoint if payload is not None else (0.0, np.zeros(3))
    if payload is not None and np.any(np.array(payload.com_upper) > np.array(payload.com_lower)):
        raise NotApplicable("inner-gain: a payload whose centre of mass ranges enters as mass x offset (not affine)")

    def loop(true, theta):
        values = {f.name: getattr(true, f.name) for f in fields(InnerLoopRobot) if f.init}
        return FactorLoop(**values, theta=float(theta))

    out = []
    if robot.model_error:
        p = float(robot.model_error)
        out.append(("links", p, loop(robot.with_true(mass, com, 1.0 - p), p)))
    if payload is not None and payload.mass_upper > payload.mass_lower:
        r = 0.5 * (payload.mass_upper - payload.mass_lower)
        out.append(("payload", r, loop(robot.with_true(mass + r, com, 1.0), r)))
    return out


def bound_one_robot(robot, pldi):
    """The PLDI of one true robot (or factor) over ``pldi``'s domain, with the effort of a model's own ranges.

    The PLDI's sample count, one local search per direction, one verification
    round, the intervals (no polytope vertices or volume); the model's
    coverage is checked afterwards on fresh points.  On
    as many workers as the PLDI had (one inside a fleet's job).
    """
    from dataclasses import replace

    from polyrob.bounds.pldi import bound_pldi

    domain = pldi.domain
    if getattr(domain, "robot", None) is not None:
        domain = replace(domain, robot=robot)
    samples = int((pldi.info or {}).get("samples", 256))
    workers = (pldi.info or {}).get("workers")
    return bound_pldi(
        robot,
        domain,
        samples=samples,
        screen=0,
        starts_per_direction=1,
        verify_rounds=1,
        coverage=0,
        describe_polytope=False,
        workers=int(workers) if workers else 1,
        progress=False,
    )


def _factor_range(pldi, factor: FactorLoop):
    """``(K_c, radii)``: the centre of the factor (``m x 3m``) and its entries' half-widths (``m x 3m``)."""
    one = bound_one_robot(factor, pldi)
    m = pldi.m
    K = np.hstack([np.asarray(one.A0, float)[m:], np.asarray(one.B0, float)[m:]])
    lay = entry_layout(one)
    lo, hi = np.asarray(one.lower, float), np.asarray(one.upper, float)
    K[lay[:, 0], lay[:, 1]] = 0.5 * (lo + hi)
    radii = np.zeros_like(K)
    radii[lay[:, 0], lay[:, 1]] = 0.5 * (hi - lo)
    return K, radii


def inner_factors_plant(pldi, robot) -> UncertainPlant:
    """The exact LFT of the module text for a computed-torque loop (armature, payload mass, link factor).

    Raises
    ------
    NotApplicable
        Not a task domain, a payload whose centre of mass ranges, or a true
        robot whose ``I - sum theta_k G_k`` may be singular.
    """
    from polyrob.domains.task import TaskDomain

    if not isinstance(pldi.domain, TaskDomain):
        raise NotApplicable("inner-gain: with rotor inertia or a payload it needs a task domain, not a torque box")
    n = 2 * pldi.m
    params = factor_parameters(robot)
    proved = proved_factor_ranges(pldi, [name for name, _, _ in params])
    if proved is None:
        centres, radii = zip(*(_factor_range(pldi, loop) for _, _, loop in params))
    else:
        centres, radii = proved
    ranges = np.array([r for _, r, _ in params])
    if sum(r * np.max(np.abs(np.linalg.eigvals(K[:, n:]))) for r, K in zip(ranges, centres)) >= 1.0:
        raise NotApplicable("inner-gain: I - sum theta_k G_k may be singular inside the ranges")
    # the residual sum_k theta_k E_k, within sum_k r_k |E_k| entrywise, as full blocks outside the theta loops
    spread = np.tensordot(ranges, np.array(radii), axes=1)
    names = tuple(name for name, _, _ in params)
    # the LFT rests on the factors' ranges alone: proved, the A, B intervals of the PLDI do not enter it
    inputs = {"PLDI": pldi.enclosure, "factors": "sampled"} if proved is None else {"factors": "certified"}
    return factor_lft_plant(pldi, "inner-gain", names, ranges, centres, spread, inputs)


def proved_factor_ranges(pldi, names):
    """``(centres, radii)`` of the factors ``names`` from the PLDI's proof (``bound_pldi(..., certify=True)``), or ``None``.

    The proof (:func:`polyrob.bounds.certified.factors.prove_factor_ranges`)
    encloses each factor ``K_k = [J_k G_k]`` over the task box with outward
    rounding, for the same directions as :func:`factor_parameters`; its
    intervals' midpoints and half-widths are the model's ``K_k,c`` and
    radii, so every true robot of the ranges is a member over the whole
    task, not only at sampled points.
    """
    proof = ((pldi.info or {}).get("certify") or {}).get("factors")
    if not proof or set(proof) != set(names):
        return None
    lower = [np.asarray(proof[name]["lower"], float) for name in names]
    upper = [np.asarray(proof[name]["upper"], float) for name in names]
    centres = tuple(0.5 * (lo + hi) for lo, hi in zip(lower, upper))
    # the half-width rounded up: the centre's rounding must not leave an end outside
    radii = tuple(np.maximum(hi - c, c - lo) * (1 + 1e-12) for lo, hi, c in zip(lower, upper, centres))
    return centres, radii


def factor_lft_plant(
    pldi,
    model: str,
    names,
    ranges,
    centres,
    spread,
    inputs: dict,
    info: dict | None = None,
    weighting=None,
    g_norm: float | None = None,
    g_offset=0.0,
    residual: str = "block",
    state_residual_norm: float | None = None,
    g_shape=None,
    motion_spread=None,
    low_rank: bool = False,
    motion_norms=None,
    payload=None,
):
    """The LFT ``a = v + sum_k theta_k K_k,c [x; a] + E [x; a]`` (module text) as an :class:`UncertainPlant`.

    ``theta_k`` within ``±ranges[k]`` (one real scalar repeated ``m`` times
    each), ``K_k,c`` the ``centres`` (``m x 3m``), ``E`` within ``spread``
    entrywise (``m x 3m``: full blocks, :func:`residual_blocks`).  ``inputs``
    are the plant's enclosure inputs; ``info`` more entries of its ``info``.
    ``weighting`` ``W`` (``m x m``, invertible): ``spread`` bounds the entries
    of ``W E diag(I, W^-1)`` instead of ``E`` (in ``M_hat^{1/2}`` coordinates
    a relative inertia error is a small symmetric block where ``E``'s own
    entries couple a light wrist to a heavy shoulder).  ``g_norm``: the
    acceleration columns ``G`` of the (weighted) residual are one full block
    of norm at most ``g_norm`` instead of entry bounds.  ``g_offset`` ``g0``:
    the LFT is centred at ``K_0 = [0, g0 I]`` (``a = (v + w) / (1 - g0)`` at
    ``Δ = 0``, and the model's nominal there): the set of ``I - G =
    M_hat^-1 M`` of a heavy payload is not centred at the identity; an
    ``m x m`` matrix ``G0`` (weighted like ``g_norm``) centres it at ``K_0 =
    [0, W^-1 G0 W]``.  ``g_shape`` ``S`` (``m x m``, symmetric positive
    definite, largest eigenvalue 1): the block is ``g_norm S^1/2 Delta
    S^1/2`` (weighted), thin where the set is
    (:func:`~polyrob.plant.models.inner_links_inertia.shape_of`).
    ``residual``: ``"block"`` carries the state columns' residual in a full
    complex block (:func:`residual_blocks`); ``"real"`` gives each of its
    entries a real scalar of its own (``|E_ij| <= spread_ij``, weighted as
    above): what the residual is (a real matrix, each entry bounded), at the
    price of one μ block per entry.  A complex block lets the stiffness
    residual act as a damping of either sign, which real scalars cannot.
    ``state_residual_norm`` ``rho`` (``residual="block"`` only): the state
    columns' block covers ``||W_l^-1 E_J W_r^-1|| <= rho`` instead of 1,
    ``W_l``, ``W_r`` the weights :func:`residual_blocks` gives ``spread``
    (whose entry box needs ``rho = 1``: a Frobenius covering); for a caller
    that bounds that norm itself (:func:`~polyrob.plant.models.inner_links.inner_links_plant`).
    ``motion_spread`` (``m x 3m``, weighted like ``spread``): more full blocks
    (:func:`residual_blocks`) for the part of the factor that moves with the
    state, marked ``moving`` in ``info["residual_blocks"]`` (the others
    ``moving: False``): :mod:`polyrob.plant.moving_links`.
    ``motion_norms`` ``(rho_x, rho_a)``: the motion's state and acceleration
    blocks cover norms up to these in their weights instead of 1 (as
    ``state_residual_norm`` does for the constant state block).
    ``low_rank``: each ``theta_k`` repeated ``rank(K_k,c)`` times instead of
    ``m`` (``K_k,c = L_k R_k`` from its SVD): the same LFT with fewer
    channels, for a model with one scalar per parameter (a link's mass
    moves the loop of the joints up to it only).
    ``payload``: a :class:`~polyrob.plant.payload_lft.PayloadLFT` (``K``'s own
    coordinates) whose channels follow the others, one repeated real per
    scalar, and whose ``offset`` joins ``K_0`` (state columns too).
    """
    m, n = pldi.m, 2 * pldi.m
    ranges = np.asarray(ranges, float)
    if residual not in ("block", "real"):
        raise ArgumentError(f"residual must be 'block' or 'real', got {residual!r}")
    spread = np.array(spread, float)
    if g_norm is not None:
        spread[:, n:] = 0.0
    carried_spread = spread.copy()
    entries = np.zeros((0, 2), int)
    if residual == "real":  # the state columns' entries as real scalars; the acceleration columns as before
        # an entry whose sampled radius is round-off (1e-35 on ur5) gets no scalar: the membership test
        # holds it to the factor's own tolerance instead (rtol 1e-9 of the factor's size)
        entries = np.argwhere(spread[:, :n] > NEGLIGIBLE_ENTRY * max(1.0, float(spread[:, :n].max())))
        entry_radii = spread[entries[:, 0], entries[:, 1]]
        spread[:, :n] = 0.0
    else:
        entry_radii = np.zeros(0)
    blocks = residual_blocks(spread, n)
    if state_residual_norm is not None and residual == "block" and blocks and blocks[0]["cols"].max() < n:
        if not 0.0 < state_residual_norm <= 1.0:
            raise ArgumentError(f"state_residual_norm must lie in (0, 1], got {state_residual_norm!r}")
        # the block's ball shrinks to the stated norm: its left weights carry rho
        blocks[0]["B"], blocks[0]["W_l"] = state_residual_norm * blocks[0]["B"], state_residual_norm * blocks[0]["W_l"]
    if g_norm is not None and g_norm > 0:
        root = np.sqrt(g_norm)
        C = np.zeros((m, 3 * m))
        if g_shape is None:
            C[:, n:] = root * np.eye(m)
            blocks.append({"B": root * np.eye(m), "C": C, "rows": np.arange(m), "cols": np.arange(n, 3 * m),
                           "W_l": np.full(m, root), "W_r": np.full(m, root)})  # fmt: skip
        else:  # the residual's block is root H Delta root H, H = S^1/2: its scaled form H^-1 E H^-1 / g_norm
            values, vectors = np.linalg.eigh(np.asarray(g_shape, float))
            H = root * (vectors * np.sqrt(values)) @ vectors.T
            C[:, n:] = H
            blocks.append({"B": H, "C": C, "rows": np.arange(m), "cols": np.arange(n, 3 * m), "W_l": H, "W_r": H})
    if motion_spread is not None:  # the part that moves with the state: the blocks the moving robot varies in time
        for b in residual_blocks(np.asarray(motion_spread, float), n):
            rho = 1.0 if motion_norms is None else float(motion_norms[int(b["cols"].max() >= n)])
            if not 0.0 < rho <= 1.0:
                raise ArgumentError(f"motion_norms must lie in (0, 1], got {motion_norms!r}")
            blocks.append({**b, "B": rho * b["B"], "W_l": rho * np.asarray(b["W_l"]), "moving": True})
    G0 = np.asarray(g_offset, float) * np.eye(m) if np.ndim(g_offset) == 0 else np.asarray(g_offset, float)
    if weighting is not None:
        W = np.asarray(weighting, float)
        G0 = np.linalg.solve(W, G0 @ W)  # into K's own coordinates
        back = np.eye(3 * m)
        back[n:, n:] = W
        for b in blocks:
            b["B"], b["C"] = np.linalg.solve(W, b["B"]), b["C"] @ back
    J0 = np.zeros((m, n))
    if payload is not None:  # its constant part joins K_0's (state columns too)
        J0, G0 = J0 + payload.offset[:, :n], G0 + payload.offset[:, n:]
    sizes = [b["B"].shape[1] for b in blocks]
    Bf = np.hstack([b["B"] for b in blocks]) if blocks else None
    Cf = np.vstack([b["C"] for b in blocks]) if blocks else None
    k, P, n_e = sum(sizes), len(names), len(entries)
    # an entry scalar e_ij in [-1, 1] adds spread_ij e_ij to entry (i, j) of the weighted residual:
    # it reads column j (state columns: the weighting leaves them) and enters row i through W^-1
    B_e = np.eye(m)[:, entries[:, 0]] if n_e else np.zeros((m, 0))
    if n_e and weighting is not None:
        B_e = np.linalg.solve(np.asarray(weighting, float), B_e)
    C_e = np.zeros((n_e, 3 * m))
    C_e[np.arange(n_e), entries[:, 1]] = entry_radii
    # channels: the residual block, then each theta repeated m times, then the entry scalars; every channel
    # enters the accelerations: a = u + sum_j d_j + B_f d_f, and every output reads [x; a]
    gain = np.linalg.inv(np.eye(m) - G0)  # a = gain (u + J0 x + to_a d) around K_0 = [J0, G0]
    left, right = _repeated_factors(centres, m, low_rank)
    repeats = [L.shape[1] for L in left]
    pay_B, pay_C, pay_names, pay_sizes = np.zeros((m, 0)), np.zeros((0, 3 * m)), (), ()
    if payload is not None:
        from polyrob.plant.payload_lft import PAYLOAD_SCALARS

        live = [s for s, r in enumerate(payload.sizes) if r]  # a centre of mass without width has no channel
        pay_B, pay_C = payload.B, payload.C
        pay_names, pay_sizes = tuple(PAYLOAD_SCALARS[s] for s in live), tuple(payload.sizes[s] for s in live)
    to_a = gain @ np.hstack([Bf if k else np.zeros((m, 0)), *left, B_e, pay_B])  # a = gain (u + J0 x) + to_a d
    reads = np.vstack(([Cf] if k else []) + [r * R for r, R in zip(ranges, right)] + [C_e, pay_C])
    C_v, D_vu, D_vd = reads[:, :n] + reads[:, n:] @ gain @ J0, reads[:, n:] @ gain, reads[:, n:] @ to_a
    if payload is not None:  # the payload's channels also read each other (its polynomial's Horner form)
        D_vd[-len(payload.parameter) :, -len(payload.parameter) :] += payload.D
    entry_names = [f"residual[{i},{j}]" for i, j in entries]
    channels = Channels(
        into_accelerations(m) @ to_a,
        C_v,
        D_vu,
        [[size, size] for size in sizes] + [[-r, 0] for r in repeats] + [[-1, 0]] * n_e
        + [[-r, 0] for r in pay_sizes],
        [f"res#{i}" for i in range(k)] + [f"{nm}#{i}" for nm, r in zip(names, repeats) for i in range(r)] + entry_names
        + [f"{nm}#{i}" for nm, r in zip(pay_names, pay_sizes) for i in range(r)],
        [-1] * k + [j for j in range(P) for _ in range(repeats[j])] + list(range(P, P + n_e))
        + [P + n_e + s for s, r in enumerate(pay_sizes) for _ in range(r)],
        D_vd,
    )  # fmt: skip
    centre = (arm_state_matrix(gain @ J0), into_accelerations(m) @ gain)
    centred = bool(np.any(G0 != 0.0) or np.any(J0 != 0.0))
    return model_plant(
        pldi,
        model,
        centre,
        channels,
        (
            tuple(names) + tuple(entry_names) + tuple(pay_names),
            -np.r_[ranges, entry_radii, np.ones(len(pay_names))],
            np.r_[ranges, entry_radii, np.ones(len(pay_names))],
        ),
        A_nom=np.asarray(pldi.A0, float) if not centred else centre[0],
        B_nom=np.asarray(pldi.B0, float) if not centred else centre[1],
        info={
            **enclosure_info(inputs),  # "certified" only on proved factor ranges
            "factors": tuple(names),
            "theta_range": ranges,
            "K_centres": np.array(centres),
            "residual_gain": float(np.linalg.norm(carried_spread)),
            "n_directions": P,
            "residual_blocks": [
                {key: b[key] for key in ("rows", "cols", "W_l", "W_r")}
                | ({} if motion_spread is None else {"moving": bool(b.get("moving", False))})
                for b in blocks
            ],
            **({} if state_residual_norm is None else {"state_residual_norm": float(state_residual_norm)}),
            "residual_spread": carried_spread,
            "residual": residual,
            "residual_entries": entries,
            "residual_entry_radii": entry_radii,
            **({} if weighting is None else {"residual_weighting": np.asarray(weighting, float)}),
            **({} if g_norm is None else {"residual_g_norm": float(g_norm)}),
            "K_offset": np.hstack([J0, G0]),
            **({} if g_shape is None else {"residual_g_shape": np.asarray(g_shape, float)}),
            **(info or {}),
        },
    )


def _repeated_factors(centres, m: int, low_rank: bool):
    """``(left, right)``: ``K_k = L_k R_k`` per centre, ``(I, K_k)`` or, with ``low_rank``, from the SVD at its rank
    (singular values above ``1e-9`` of the largest of all centres; at least one channel per scalar)."""
    centres = [np.asarray(K, float) for K in centres]
    if not low_rank:
        return [np.eye(m)] * len(centres), centres
    svds = [np.linalg.svd(K, full_matrices=False) for K in centres]
    top = max([float(s[0]) for _, s, _ in svds] + [1e-300])
    left, right = [], []
    for U, s, Vt in svds:
        r = max(1, int(np.sum(s > 1e-9 * top)))
        root = np.sqrt(s[:r])
        left.append(U[:, :r] * root)
        right.append(root[:, None] * Vt[:r])
    return left, right


def residual_blocks(spread: np.ndarray, n: int) -> list[dict]:
    """The full blocks of a factor residual within ``spread`` (``m x 3m`` entry radii): ``B``, ``C``, ``rows``, ``cols``, ``W_l``, ``W_r``.

    One block for the state columns (``J``: stiffness and damping, per unit
    of the factor) and one for the acceleration columns (``G``: a relative
    gain, orders of magnitude smaller).  A single block bounds entry
    ``(i, j)`` by ``W_l[i] W_r[j]``, a rank-one pattern: it would let the
    ``G`` entries grow to the size of the ``J`` entries of their row, and
    ``G`` is fed back through the model's static loop (``D_vd``): with a
    payload that cost every per-joint PID of so101 and panda its
    certificate.  ``C`` reads the whole ``[x; a]``.
    """
    out = []
    for cols in (np.arange(n), np.arange(n, spread.shape[1])):
        Bf, Cf, gains = residual_of_radii(spread[:, cols])
        if Bf is None:
            continue
        C = np.zeros((Cf.shape[0], spread.shape[1]))
        C[:, cols] = Cf
        out.append({"B": Bf, "C": C, "rows": gains["residual_rows"], "cols": cols[gains["residual_cols"]],
                    "W_l": gains["W_l"], "W_r": gains["W_r"]})  # fmt: skip
    return out
