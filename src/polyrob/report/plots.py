"""Figures of the report (matplotlib, Agg, PNG), after the paper's Figs. 3-5.

Every function takes the object of its stage and a path, writes one PNG
atomically and returns the path.  Figures are built with
:class:`matplotlib.figure.Figure` (no pyplot state, no display needed).
Every axes has a title and axis labels with units: frequencies in rad/s,
magnitudes in dB (with the units of the ratio), μ absolute, time in s,
positions in rad (m for a prismatic joint) and efforts in N·m (N); ``kinds``
(the robot's ``joint_kinds``) chooses the joint units.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from polyrob.io.atomic import atomic_write

__all__ = [
    "plot_pldi_bode",
    "plot_sensitivities",
    "plot_steps",
    "plot_controllers",
    "plot_mu",
    "plot_tracking",
    "save_figure",
    "joint_units",
    "limits_on_scale",
]

DPI = 100
GREY = "0.65"
OMEGA = "ω (rad/s)"


def save_figure(fig: Figure, path) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically."""
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    atomic_write(path, lambda f: f.write(buf.getvalue()), binary=True)
    return path


def _mag_db(H):
    return 20 * np.log10(np.maximum(np.abs(H), 1e-300))


def joint_units(kinds=None, m: int = 0) -> tuple[list, list]:
    """Position and effort units per joint: ``rad`` and ``N·m``; ``m`` and ``N`` for a prismatic joint.

    >>> joint_units(["revolute", "prismatic"])
    (['rad', 'm'], ['N·m', 'N'])
    >>> joint_units(None, 2)  # kinds unknown: revolute
    (['rad', 'rad'], ['N·m', 'N·m'])
    """
    kinds = [] if kinds is None else list(kinds)
    if m and len(kinds) != m:  # unknown, or not this many joints: revolute
        kinds = ["revolute"] * m
    pos = ["m" if k == "prismatic" else "rad" for k in kinds]
    eff = ["N" if k == "prismatic" else "N·m" for k in kinds]
    return pos, eff


def _labels(ax, x: str, y: str, title: str) -> None:
    ax.set_xlabel(x, fontsize=8)
    ax.set_ylabel(y, fontsize=8)
    ax.set_title(title, fontsize=9)
    ax.tick_params(labelsize=7)


def plot_pldi_bode(unc, path, *, n: int = 20, omega=None, seed: int = 0, kinds=None) -> Path:
    """Bode magnitude of every ``G_ij`` of ``n`` sampled plants and 16 corners (paper Fig. 3)."""
    from polyrob.validate.monte_carlo import frequency_response

    omega = np.logspace(-2, 3, 300) if omega is None else np.asarray(omega, float)
    deltas = list(unc.delta_samples(n, kind="uniform", seed=seed))
    deltas += list(unc.delta_samples(16, kind="corners", seed=seed + 1))
    m = unc.m
    pos, eff = joint_units(kinds, m)
    fig = Figure(layout="tight", figsize=(3.4 * m, 2.8 * m + 0.4))
    axes = np.array(fig.subplots(m, m, squeeze=False))
    for d in deltas:
        H = frequency_response(unc.plant_at(d), omega)
        for i in range(m):
            for j in range(m):
                axes[i, j].semilogx(omega, _mag_db(H[:, i, j]), color=GREY, lw=0.7)
    Hn = frequency_response(unc.nominal_system(), omega)
    for i in range(m):
        for j in range(m):
            ax = axes[i, j]
            ax.semilogx(omega, _mag_db(Hn[:, i, j]), color="k", lw=1.5, label="nominal" if i + j == 0 else None)
            _labels(ax, OMEGA, f"|G{i + 1}{j + 1}| (dB, {pos[i]}/{eff[j]})", f"G{i + 1}{j + 1}: u{j + 1} → q{i + 1}")
            ax.grid(True, which="both", lw=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Plant magnitude: {len(deltas)} sampled/corner plants (grey) and the nominal (black)", fontsize=10)
    return save_figure(fig, path)


def plot_sensitivities(mc, path) -> Path:
    """``|S_ii|``, ``|T_ii|`` of the Monte Carlo plants against ``1/|W_S|``, ``1/|W_T|`` (paper Fig. 4)."""
    m = mc.m
    fig = Figure(layout="tight", figsize=(3.6 * m, 5.6))
    axes = np.array(fig.subplots(2, m, squeeze=False))
    for row, (name, H, Hn, inv) in enumerate(
        (("S", mc.S, mc.S_nominal, mc.inv_W_S), ("T", mc.T, mc.T_nominal, mc.inv_W_T))
    ):
        for i in range(m):
            ax = axes[row, i]
            for k in range(mc.n):
                ax.semilogx(mc.omega, _mag_db(H[k, :, i, i]), color=GREY, lw=0.7)
            ax.semilogx(mc.omega, _mag_db(Hn[:, i, i]), color="k", lw=1.4, label="nominal")
            if inv is not None:
                ax.semilogx(mc.omega, _mag_db(inv[i]), "r--", lw=1.4, label=f"1/|W_{name}|")
            _labels(ax, OMEGA, f"|{name}{i + 1}{i + 1}| (dB)", f"{name}{i + 1}{i + 1}: {mc.n} {mc.kind} samples")
            ax.grid(True, which="both", lw=0.3)
            ax.legend(fontsize=7)
    fig.suptitle("Sensitivity S and complementary sensitivity T (ratios, in dB) against the weights", fontsize=10)
    return save_figure(fig, path)


def plot_steps(mc, path, *, kinds=None) -> Path:
    """Step responses ``r_j -> q_i`` of the Monte Carlo plants (linear loops, unit steps)."""
    m = mc.m
    pos, _ = joint_units(kinds, m)
    fig = Figure(layout="tight", figsize=(3.4 * m, 2.7 * m + 0.4))
    axes = np.array(fig.subplots(m, m, squeeze=False))
    for i in range(m):
        for j in range(m):
            ax = axes[i, j]
            for k in range(mc.n):
                ax.plot(mc.t, mc.step_y[k, i, j], color=GREY, lw=0.7)
            ax.plot(mc.t, mc.step_y_nominal[i, j], color="k", lw=1.4)
            _labels(ax, "t (s)", f"q{i + 1} ({pos[i]})", f"step of 1 {pos[j]} in r{j + 1} → q{i + 1}")
            ax.grid(True, lw=0.3)
    fig.suptitle("Unit-step responses of the linear loops: samples (grey) and nominal (black)", fontsize=10)
    return save_figure(fig, path)


def plot_controllers(controllers: dict, path, *, omega=None, kinds=None) -> Path:
    """``|K_ij|`` of several controllers (paper Fig. 5: full order vs fixed structure).

    ``K_ij`` maps the position error of joint ``j`` to the effort of joint
    ``i``: its magnitude is in dB of N·m/rad (N/m, ... for prismatic joints).
    """
    from polyrob.validate.monte_carlo import frequency_response

    omega = np.logspace(-3, 4, 400) if omega is None else np.asarray(omega, float)
    resp = {name: frequency_response(K, omega) for name, K in controllers.items()}
    p, q = next(iter(resp.values())).shape[1:]
    pos, _ = joint_units(kinds, q)
    _, eff = joint_units(kinds, p)
    fig = Figure(layout="tight", figsize=(3.6 * q, 2.8 * p + 0.4))
    axes = np.array(fig.subplots(p, q, squeeze=False))
    for name, H in resp.items():
        for i in range(p):
            for j in range(q):
                axes[i, j].semilogx(omega, _mag_db(H[:, i, j]), lw=1.2, label=name)
    for i in range(p):
        for j in range(q):
            ax = axes[i, j]
            _labels(ax, OMEGA, f"|K{i + 1}{j + 1}| (dB, {eff[i]}/{pos[j]})", f"K{i + 1}{j + 1}: e{j + 1} → u{i + 1}")
            ax.grid(True, which="both", lw=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Controller magnitude per entry (position error e → effort u)", fontsize=10)
    return save_figure(fig, path)


def _finite(y):
    y = np.asarray(y, float).copy()
    y[~np.isfinite(y)] = np.nan
    return y


def _peak_words(w, up) -> str:
    up = _finite(up)
    if not np.any(np.isfinite(up)):
        return "no finite value"
    k = int(np.nanargmax(up))
    where = "ω = 0" if w[k] == 0 else f"ω = {w[k]:.3g} rad/s"
    return f"peak {up[k]:.4g} at {where}"


def plot_mu(curves: dict, path, *, title: str = "μ bounds over frequency") -> Path:
    """μ upper (solid) and lower (dashed) bounds over frequency; ``curves[name] = (omega, upper, lower)``.

    The axis spans every curve's grid, from its lowest frequency; a curve
    with a value at ω = 0 has it drawn as a point at the left edge, past a
    dotted line, labelled "ω = 0".  Each curve's legend names its peak and
    where it is.  A lower bound of 0 (none found at that frequency) is left out.
    """
    fig = Figure(layout="constrained", figsize=(9.6, 4.2))
    ax = fig.subplots()
    prepared = []
    for name, (w, up, lo) in curves.items():
        w = np.asarray(w, float).ravel()
        up = _finite(up).ravel()
        lo = None if lo is None else _finite(lo).ravel()
        if lo is not None:
            lo[lo <= 0] = np.nan  # 0: no lower bound found there (a gap, not a plunge to 0)
        prepared.append((name, w, up, lo))
    pos = np.concatenate([w[w > 0] for _, w, _, _ in prepared] or [np.array([])])
    wmin, wmax = (pos.min(), pos.max()) if pos.size else (1e-3, 1e3)
    has_zero = any(np.any(w == 0) for _, w, _, _ in prepared)
    x0 = wmin / 10**0.7  # where ω = 0 is drawn
    for k, (name, w, up, lo) in enumerate(prepared):
        color, lw = f"C{k}", 2.6 if k == 0 else 1.3  # the first (the certificate's) under the others, visible
        keep = w > 0
        ax.semilogx(
            w[keep], up[keep], color=color, lw=lw, zorder=2 - 0.1 * k, label=f"{name}: upper ({_peak_words(w, up)})"
        )
        if lo is not None:
            ax.semilogx(
                w[keep], lo[keep], color=color, lw=0.5 * lw, ls="--", marker=".", ms=2.5, label=f"{name}: lower"
            )
        zero = np.flatnonzero(w == 0)
        if zero.size:
            z = zero[0]
            ax.plot([x0], [up[z]], "o", color=color, ms=6)
            if lo is not None and np.isfinite(lo[z]):
                ax.plot([x0], [lo[z]], "o", color=color, ms=6, mfc="none")
            ax.annotate(
                f"{up[z]:.4g}",
                (x0, up[z]),
                textcoords="offset points",
                xytext=(6, 0),
                va="center",
                fontsize=7,
                color=color,
            )
    ax.axhline(1.0, color="r", lw=0.8, label="μ = 1")
    if has_zero:
        ax.axvline(x0 * 10**0.35, color="0.4", lw=0.8, ls=":")
        ax.annotate(
            "ω = 0",
            (x0, 0.0),
            xycoords=("data", "axes fraction"),
            xytext=(0, 4),
            textcoords="offset points",
            ha="center",
            fontsize=8,
        )
    ax.set_xlim((x0 / 10**0.3) if has_zero else wmin, wmax)
    _labels(ax, OMEGA, "μ (absolute)", title)
    ax.grid(True, which="both", lw=0.3)
    fig.legend(fontsize=7, loc="outside lower center", ncols=2)
    return save_figure(fig, path)


#: A limit line is drawn when the data reach at least this fraction of it; else it is named in words.
LIMIT_SCALE = 0.2


def limits_on_scale(limits, values) -> tuple[list, list]:
    """``(drawn, named)``: the limits the data come within :data:`LIMIT_SCALE` of, and the others.

    A limit 100 times the largest value would flatten the data to a line at 0:
    it is named in words instead of drawn.

    >>> limits_on_scale([12.0, 87.0], [[1.0, -7.0], [3.0, 0.5]])
    ([12.0], [87.0])
    """
    peak = float(np.nanmax(np.abs(values))) if np.size(values) else 0.0
    drawn = [lim for lim in limits if peak >= LIMIT_SCALE * lim]
    return drawn, [lim for lim in limits if lim not in drawn]


def plot_tracking(sims, path, *, joint_names=None, kinds=None) -> Path:
    """Joint positions against references and efforts against limits; domain exits in red."""
    sims = list(sims)
    m = sims[0].q.shape[0]
    names = joint_names or [f"joint {j + 1}" for j in range(m)]
    pos, eff = joint_units(kinds, m)
    effort = f"torque ({eff[0]})" if len(set(eff)) == 1 else "effort (N·m, N)"
    fig = Figure(layout="tight", figsize=(max(6.4, 4.2 * len(sims)), 2.3 * (m + 1) + 0.4))
    axes = np.array(fig.subplots(m + 1, len(sims), squeeze=False))
    for c, sim in enumerate(sims):
        label = f"{sim.controller}" + (f" {sim.rate:.4g} Hz" if sim.rate else "")
        for j in range(m):
            ax = axes[j, c]
            ax.plot(sim.t, sim.r[j], "k--", lw=1.0, label="r")
            ax.plot(sim.t, sim.q[j], lw=1.3, label="q")
            _labels(ax, "t (s)", f"{names[j]} ({pos[j]})", f"{names[j]}: position and reference")
            ax.grid(True, lw=0.3)
        ax = axes[m, c]
        for j in range(m):
            ax.plot(sim.t, sim.u[j], lw=1.0, label=f"u{j + 1}")
        lims = sorted({mt.effort_limit for mt in sim.metrics if np.isfinite(mt.effort_limit)})
        shown, off_scale = limits_on_scale(lims, sim.u)
        for lim in shown:
            ax.axhline(lim, color="r", lw=0.6)
            ax.axhline(-lim, color="r", lw=0.6)
        title = "efforts" + (" (red: limits)" if shown else "")
        if off_scale:  # named, not drawn: a line far above the data would flatten them to 0
            peak = float(np.nanmax(np.abs(sim.u))) if np.size(sim.u) else 0.0
            text = ", ".join(f"±{lim:.4g}" for lim in off_scale)
            title += f"; limits {text} {eff[0]} off scale (peak {100 * peak / min(off_scale):.2g} % of {min(off_scale):.4g})"
        _labels(ax, "t (s)", effort, title)
        ax.grid(True, lw=0.3)
        ax.legend(fontsize=7)
        title = f"{label}: " + ("LEFT THE DOMAIN" if sim.left_domain else "inside the domain")
        axes[0, c].set_title(title, fontsize=9, color="red" if sim.left_domain else "black")
        if sim.first_exit_time is not None:
            for j in range(m + 1):
                axes[j, c].axvspan(sim.first_exit_time, sim.t[-1], color="red", alpha=0.08)
        axes[0, c].legend(fontsize=7)
    fig.suptitle("Nonlinear closed loop: positions, references and efforts", fontsize=10)
    return save_figure(fig, path)
