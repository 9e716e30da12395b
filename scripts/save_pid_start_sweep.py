"""Save the μ sweep of a PID start's certificate: the fixture of tests/test_mu_between.py.

Runs ``polyrob synth ROBOT --max-iter 1`` (the per-joint PID tuned to the
weights, certified; no D-K step) and saves the sweep that the check between
the grid points receives: the closed loop's state space, the block structure,
the grid with its bounds and D-G scalings.  Usage::

    python scripts/save_pid_start_sweep.py panda tests/fixtures/panda_pid_start_sweep.npz

(about 5 minutes on an idle 2-core x86_64; much longer on a loaded one).
"""

from __future__ import annotations

import dataclasses
import sys

import control
import numpy as np

import polyrob.analysis.mu.between as between

SAVED = {}


def _saving(verify):
    def verify_and_save(M, mu, **kwargs):
        A, B, C, D = (np.asarray(x) for x in control.ssdata(control.ss(M)))
        fields = {f.name: getattr(mu, f.name) for f in dataclasses.fields(mu)}
        SAVED.update(
            A=A,
            B=B,
            C=C,
            D=D,
            blk=np.asarray(mu.structure.matlab),
            omega=fields["omega"],
            upper=fields["upper"],
            lower=fields["lower"],
            Dscale=fields["D"],
            Gscale=fields["G"],
            peak_upper=fields["peak_upper"],
            peak_upper_frequency=fields["peak_upper_frequency"],
            peak_lower=fields["peak_lower"],
            critical_frequency=fields["critical_frequency"],
            worst_delta=fields["worst_delta"],
            method=fields["method"],
        )
        return verify(M, mu, **kwargs)

    return verify_and_save


def main(robot: str, path: str) -> int:
    from polyrob.cli import main as polyrob

    between.verify_between = _saving(between.verify_between)
    code = polyrob(["synth", robot, "--max-iter", "1", "--quiet"])
    if not SAVED:
        print("no check between grid points was made (the grid's peak is not below 1?)", file=sys.stderr)
        return 1
    np.savez_compressed(path, **SAVED)
    print(f"wrote {path} (synth exit status {code})")
    return 0


if __name__ == "__main__":  # the bounds' worker processes import this module again
    sys.exit(main(*sys.argv[1:3]))
