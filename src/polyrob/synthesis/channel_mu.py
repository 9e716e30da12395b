"""Which weighted channel μ rests on: μ of the robust-performance test with each channel left out.

The nominal-peak rule (:func:`polyrob.synthesis.bandwidth.binding_bound`)
names the channel nearest its bound on the *nominal* loop.  μ is a worst
case over the uncertainty set with every weighted channel in one
performance block, and a channel that is slack on the nominal loop can be
the one the worst plant of the set breaks, and a failed factor may fail
for its synthesis alone (ur5 with 14-bit encoders: the rule said tracking,
0.59 against 0.43 for the noise channel, while μ of the last certified
controller on the failing factor's weights is 0.758: no bound was hit;
docs/synthesis.md).  :func:`channel_mu` asks μ itself: the peak μ upper bound of the loop with
every channel, with each channel removed from the performance block, and
with none (robust stability).  Removing a channel can only lower μ, so

* a channel without which μ falls below 1, while μ with every channel is
  above it, **binds**: the weights could be met but for it;
* when no single removal reaches 1, the channel whose removal lowers μ
  most is the one the figure rests on most, and robust stability alone
  at or above 1 says the uncertainty, not a performance channel, binds.

The figures are μ upper bounds at the points of a frequency grid (AB13MD on
the structure, or on its relaxed superset when that is cheaper, as the PID
tuning ranks its candidates): a diagnosis of where a design fails, not a
certificate.

Examples
--------
>>> channel_words({"all": 1.3, "W_S e": 0.8, "W_T y": 1.25, "W_KS u": 1.1, "none": 0.5})
'tracking (W_S) binds: grid mu 1.3 with every channel, 0.8 without it (uncertainty (W_T): 1.25; encoder noise against the effort limit (W_u K S W_n): 1.1; robust stability alone 0.5)'
"""

from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_OMEGA", "CHANNEL_NAMES", "channel_mu", "channel_words"]

#: The grid the channels' μ is computed on [rad/s]: 8 points a decade over the arms' loops.
DEFAULT_OMEGA = np.logspace(-2, 4, 49)
#: What each weighted channel of the generalized plant bounds, in words (keyed by
#: :attr:`~polyrob.plant.generalized.GeneralizedPlant.z_labels`).
CHANNEL_NAMES = {
    "W_S e": "tracking (W_S)",
    "W_T y": "uncertainty (W_T)",
    "W_KS u": "encoder noise against the effort limit (W_u K S W_n)",
    "reg u": "regularisation",
}


def channel_mu(P, controller, omega=None) -> dict:
    """Peak μ upper bounds on a grid: ``"all"`` channels, without each channel (keyed by its label), ``"none"``.

    Parameters
    ----------
    P : GeneralizedPlant
    controller : LTI or array
        ``u = K (r - y)`` as the synthesis returns it.
    omega : array_like, optional
        Frequencies [rad/s] (default :data:`DEFAULT_OMEGA`).

    Returns
    -------
    dict
        ``{"all": mu, label: mu without that channel, ..., "none": robust stability}``; ``inf`` for a loop whose
        nominal closed loop is not stable (μ does not apply).
    """
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.analysis.mu.bounds import mussv
    from polyrob.analysis.mu.frequency import matrix_response
    from polyrob.analysis.mu.sweep import relaxed_is_cheap
    from polyrob.controller import as_controller_ss
    from polyrob.plant.loops import lower_lft_matrices

    omega = DEFAULT_OMEGA if omega is None else np.asarray(omega, float)
    m = int(P.n_u)
    K = as_controller_ss(controller, m, int(P.n_y))
    A, B, C, D = (np.asarray(X, float) for X in (P.system.A, P.system.B, P.system.C, P.system.D))
    Ak, Bk, Ck, Dk = (np.asarray(X, float) for X in (K.A, K.B, K.C, K.D))
    labels = list(P.z_slices)
    cases = {"all": [], **{lab: [lab] for lab in labels}, "none": labels}
    try:
        Acl, Bcl, Ccl, Dcl = lower_lft_matrices(A, B, C, D, Ak, Bk, Ck, Dk, m, int(P.n_y))
    except np.linalg.LinAlgError:
        return dict.fromkeys(cases, np.inf)
    if Acl.size and np.max(np.linalg.eigvals(Acl).real) >= 0:
        return dict.fromkeys(cases, np.inf)
    H = matrix_response(Acl, Bcl, Ccl, Dcl)(omega)  # (N, n_delta + n_z, n_delta + n_w)
    blk = np.asarray(P.block_structure_rp, int)
    nd, nw = int(P.n_delta), int(P.n_w)
    out = {}
    for key, dropped in cases.items():
        gone = set().union(*(range(*P.z_slices[lab].indices(P.n_z)) for lab in dropped)) if dropped else set()
        keep_z = [k for k in range(int(P.n_z)) if k not in gone]
        if keep_z:
            rows = list(range(nd)) + [nd + k for k in keep_z]
            cols = list(range(nd + nw))
            b = blk.copy()
            b[-1] = [nw, len(keep_z)]
        elif nd == 0:  # no performance channel and no uncertainty: nothing can fail
            out[key] = 0.0
            continue
        else:  # no performance channel left: robust stability, d -> v
            rows, cols, b = list(range(nd)), list(range(nd)), blk[:-1]
        st = as_block_structure(b)
        method = "relaxed" if relaxed_is_cheap(st) else "gradient"
        Hk = H[:, rows][:, :, cols]
        out[key] = float(max(mussv(Hk[i], st, method=method, lower=False).upper for i in range(omega.size)))
    return out


def channel_words(figures: dict, names: dict | None = None) -> str:
    """One line from :func:`channel_mu`'s figures: the channel that binds, or the one μ rests on most.

    ``names`` maps the channels' labels to words (default: the labels' own words).
    """
    names = {**CHANNEL_NAMES, **(names or {})}
    labels = [k for k in figures if k not in ("all", "none")]
    full, alone = figures["all"], figures.get("none", np.nan)
    if not np.isfinite(full):
        return "the nominal loop is not stable: no channel's share of mu"
    if not labels:
        return f"grid mu {full:.3g}, no weighted channel"
    best = min(labels, key=lambda k: figures[k])
    others = "; ".join(f"{names.get(k, k)}: {figures[k]:.3g}" for k in labels if k != best)
    tail = f" ({others}; robust stability alone {alone:.3g})" if others else f" (robust stability alone {alone:.3g})"
    if full >= 1.0 and figures[best] < 1.0:
        return (
            f"{names.get(best, best)} binds: grid mu {full:.3g} with every channel, {figures[best]:.3g} without it"
            + tail
        )
    if alone >= 1.0:
        return (
            f"the uncertainty itself: robust stability alone has grid mu {alone:.3g} >= 1 (every channel: {full:.3g})"
        )
    return (
        f"no single channel: grid mu {full:.3g} with every channel; the largest drop without "
        f"{names.get(best, best)}, to {figures[best]:.3g}" + tail
    )
