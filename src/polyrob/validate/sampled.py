"""A sampled-and-held loop: the robot integrated between the samples of a discrete controller."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["simulate_sampled"]


def simulate_sampled(robot, Kd, r_of_t, t_final, q0, qdot0, u_eq, rtol, atol, limits=None):
    """The robot under the discrete controller ``Kd``: ``e`` sampled every period, ``u`` held in between.

    Returns ``(t, x, u, r, success, info)`` (states ``x = [q; qdot]`` at the
    sampling instants; ``u`` and ``r`` held over each period, reported at its
    end too).  ``limits``: a :class:`~polyrob.validate.simulate.SimulationLimits` or ``None``.
    """
    m = robot.m
    h = float(Kd.dt)
    Ad, Bd, Cd, Dd = (np.asarray(X, float) for X in (Kd.A, Kd.B, Kd.C, Kd.D))
    n_steps = int(np.ceil(t_final / h - 1e-9))
    x = np.concatenate([q0, qdot0])
    xk = np.zeros(Ad.shape[0])
    ts, xs, us, rs = [0.0], [x.copy()], [], []
    ok, message, nfev = True, "reached t_final", 0
    for k in range(n_steps):
        tk = k * h
        if limits is not None and limits.exceeded(nfev):
            ok, message = False, f"{limits.words(nfev)} (stopped at t = {tk:.4g} s of {t_final:.4g} s)"
            break
        rk = r_of_t(tk)
        e = rk - x[:m]
        uk = u_eq + Cd @ xk + Dd @ e
        xk = Ad @ xk + Bd @ e
        sol = solve_ivp(lambda t, z: robot.f(z, uk), (tk, tk + h), x, method="RK45", rtol=rtol, atol=atol)
        nfev += sol.nfev
        if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
            ok, message = False, f"step {k}: {sol.message}"
            break
        x = sol.y[:, -1]
        us.append(uk)
        rs.append(rk)
        ts.append(tk + h)
        xs.append(x.copy())
    # u and r are held over each period: report them at the period's end too
    X = np.array(xs).T
    U = np.array(us + us[-1:]).T if us else np.tile(u_eq[:, None], (1, 1))
    R = np.array(rs + [r_of_t(ts[-1])]).T if rs else np.asarray(r_of_t(0.0))[:, None]
    t = np.array(ts)
    info = {"solver": "solve_ivp RK45 per hold interval", "nfev": int(nfev), "message": message, "period": h}
    return t, X, U, R, ok, info
