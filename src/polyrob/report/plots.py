"""Figures of the report (matplotlib, Agg, PNG), after the paper's Figs. 3-5.

Every function takes the object of its stage and a path, writes one PNG
atomically and returns the path.  Figures are built with
:class:`matplotlib.figure.Figure` (no pyplot state, no display needed).
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
]

DPI = 100
GREY = "0.65"


def save_figure(fig: Figure, path) -> Path:
    """Write ``fig`` as PNG to ``path`` atomically."""
    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    atomic_write(path, lambda f: f.write(buf.getvalue()), binary=True)
    return path


def _mag_db(H):
    return 20 * np.log10(np.maximum(np.abs(H), 1e-300))


def plot_pldi_bode(unc, path, *, n: int = 20, omega=None, seed: int = 0) -> Path:
    """Bode magnitude of every ``G_ij`` of ``n`` sampled plants and 16 corners (paper Fig. 3)."""
    from polyrob.validate.monte_carlo import frequency_response

    omega = np.logspace(-2, 3, 300) if omega is None else np.asarray(omega, float)
    deltas = list(unc.delta_samples(n, kind="uniform", seed=seed))
    deltas += list(unc.delta_samples(16, kind="corners", seed=seed + 1))
    m = unc.m
    fig = Figure(layout="tight", figsize=(3.2 * m, 2.6 * m))
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
            ax.set_title(f"G{i + 1}{j + 1}", fontsize=9)
            ax.grid(True, which="both", lw=0.3)
            if i == m - 1:
                ax.set_xlabel("ω (rad/s)")
            if j == 0:
                ax.set_ylabel("dB")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"PLDI: {len(deltas)} sampled/corner plants (grey) and nominal", fontsize=10)
    return save_figure(fig, path)


def plot_sensitivities(mc, path) -> Path:
    """``|S_ii|``, ``|T_ii|`` of the Monte Carlo plants against ``1/|W_S|``, ``1/|W_T|`` (paper Fig. 4)."""
    m = mc.m
    fig = Figure(layout="tight", figsize=(3.4 * m, 5.2))
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
            ax.set_title(f"{name}{i + 1}{i + 1}: {mc.n} {mc.kind} samples", fontsize=9)
            ax.grid(True, which="both", lw=0.3)
            ax.set_ylabel("dB")
            ax.set_xlabel("ω (rad/s)")
            ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_steps(mc, path) -> Path:
    """Step responses ``r_j -> y_i`` of the Monte Carlo plants."""
    m = mc.m
    fig = Figure(layout="tight", figsize=(3.2 * m, 2.6 * m))
    axes = np.array(fig.subplots(m, m, squeeze=False))
    for i in range(m):
        for j in range(m):
            ax = axes[i, j]
            for k in range(mc.n):
                ax.plot(mc.t, mc.step_y[k, i, j], color=GREY, lw=0.7)
            ax.plot(mc.t, mc.step_y_nominal[i, j], color="k", lw=1.4)
            ax.set_title(f"r{j + 1} → q{i + 1}", fontsize=9)
            ax.grid(True, lw=0.3)
            if i == m - 1:
                ax.set_xlabel("t (s)")
    return save_figure(fig, path)


def plot_controllers(controllers: dict, path, *, omega=None) -> Path:
    """``|K_ij|`` of several controllers (paper Fig. 5: full order vs fixed structure)."""
    from polyrob.validate.monte_carlo import frequency_response

    omega = np.logspace(-3, 4, 400) if omega is None else np.asarray(omega, float)
    resp = {name: frequency_response(K, omega) for name, K in controllers.items()}
    p, q = next(iter(resp.values())).shape[1:]
    fig = Figure(layout="tight", figsize=(3.4 * q, 2.6 * p))
    axes = np.array(fig.subplots(p, q, squeeze=False))
    for name, H in resp.items():
        for i in range(p):
            for j in range(q):
                axes[i, j].semilogx(omega, _mag_db(H[:, i, j]), lw=1.2, label=name)
    for i in range(p):
        for j in range(q):
            axes[i, j].set_title(f"K{i + 1}{j + 1}", fontsize=9)
            axes[i, j].grid(True, which="both", lw=0.3)
    axes[0, 0].legend(fontsize=7)
    return save_figure(fig, path)


def plot_mu(curves: dict, path, *, title: str = "μ bounds") -> Path:
    """μ upper (solid) and lower (dashed) bounds over frequency; ``curves[name] = (omega, upper, lower)``."""
    fig = Figure(layout="tight", figsize=(6.4, 3.6))
    ax = fig.subplots()
    for k, (name, (w, up, lo)) in enumerate(curves.items()):
        color = f"C{k}"
        ax.semilogx(w, up, color=color, lw=1.4, label=f"{name}: upper")
        if lo is not None:
            ax.semilogx(w, lo, color=color, lw=1.0, ls="--", label=f"{name}: lower")
    ax.axhline(1.0, color="r", lw=0.8)
    ax.set_xlabel("ω (rad/s)")
    ax.set_ylabel("μ")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_tracking(sims, path, *, joint_names=None) -> Path:
    """Joint positions against references and torques against limits; domain exits in red."""
    sims = list(sims)
    m = sims[0].q.shape[0]
    names = joint_names or [f"joint {j + 1}" for j in range(m)]
    fig = Figure(layout="tight", figsize=(4.0 * len(sims), 2.2 * (m + 1)))
    axes = np.array(fig.subplots(m + 1, len(sims), squeeze=False))
    for c, sim in enumerate(sims):
        label = f"{sim.controller}" + (f" {sim.rate:.4g} Hz" if sim.rate else "")
        for j in range(m):
            ax = axes[j, c]
            ax.plot(sim.t, sim.r[j], "k--", lw=1.0, label="r")
            ax.plot(sim.t, sim.q[j], lw=1.3, label="q")
            ax.set_ylabel(f"{names[j]} (rad)")
            ax.grid(True, lw=0.3)
        ax = axes[m, c]
        for j in range(m):
            ax.plot(sim.t, sim.u[j], lw=1.0, label=f"u{j + 1}")
        lims = [mt.effort_limit for mt in sim.metrics if np.isfinite(mt.effort_limit)]
        for lim in set(lims):
            ax.axhline(lim, color="r", lw=0.6)
            ax.axhline(-lim, color="r", lw=0.6)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("torque")
        ax.grid(True, lw=0.3)
        ax.legend(fontsize=7)
        title = f"{label}: " + ("LEFT THE DOMAIN" if sim.left_domain else "inside the domain")
        axes[0, c].set_title(title, fontsize=9, color="red" if sim.left_domain else "black")
        if sim.first_exit_time is not None:
            for j in range(m + 1):
                axes[j, c].axvspan(sim.first_exit_time, sim.t[-1], color="red", alpha=0.08)
        axes[0, c].legend(fontsize=7)
    return save_figure(fig, path)
