"""Store dkpy's D-K controller for the distillation column as a JSON test fixture.

Runs dkpy's D-K iteration exactly as ``benchmarks/synthesis.py`` does
(``example_skogestad2006_p325``, ``DkIterAutoOrder`` with SLICOT H∞ synthesis,
LMI-bisection μ and SLICOT D-scale fits, 3 iterations, fit orders up to 4, the
61-point grid ``logspace(-3, 3, 61)``) and writes the controller's state-space
matrices, exactly as dkpy returns them (no balancing, no reduction: the
fixture is meant to keep dkpy's badly conditioned realisation), to
``tests/fixtures/dkpy_distillation_controller.json``.

Run once with the bench extra installed (``pip install dkpy``)::

    python benchmarks/make_dkpy_fixture.py

The tests read the stored file; they never run dkpy.
"""

from __future__ import annotations

import importlib.metadata
import json
import pathlib
import sys
import time
import warnings

import control
import numpy as np

OUT = pathlib.Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "dkpy_distillation_controller.json"
DIST_OMEGA = np.logspace(-3, 3, 61)
DIST_BLK = [[1, 1], [1, 1], [2, 2]]


def main() -> int:
    import dkpy

    warnings.simplefilter("ignore")
    eg = dkpy.example_skogestad2006_p325()
    it = dkpy.DkIterAutoOrder(
        controller_synthesis=dkpy.HinfSynSlicot(),
        structured_singular_value=dkpy.SsvLmiBisection(),
        d_scale_fit=dkpy.DScaleFitSlicot(),
        max_mu=1,
        max_mu_fit_error=1e-2,
        max_iterations=3,
        max_fit_order=4,
    )
    t0 = time.perf_counter()
    K, _, mu, _, _ = it.synthesize(eg["P"], eg["n_y"], eg["n_u"], DIST_OMEGA, np.array(DIST_BLK))
    K = control.ss(K)
    doc = {
        "format": "polyrob-test-fixture/statespace",
        "version": 1,
        "source": "dkpy D-K iteration on the distillation column (benchmarks/make_dkpy_fixture.py)",
        "dkpy_version": importlib.metadata.version("dkpy"),
        "control_version": importlib.metadata.version("control"),
        "slycot_version": importlib.metadata.version("slycot"),
        "dkpy_peak_mu_grid": float(mu),
        "seconds": round(time.perf_counter() - t0, 2),
        # repr() of a float round-trips exactly: the realisation is kept bit for bit
        "A": np.asarray(K.A, float).tolist(),
        "B": np.asarray(K.B, float).tolist(),
        "C": np.asarray(K.C, float).tolist(),
        "D": np.asarray(K.D, float).tolist(),
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(doc, indent=1) + "\n")
    print(json.dumps({k: v for k, v in doc.items() if k not in "ABCD"}, indent=1))
    print(f"order {K.nstates}, ||A|| = {np.linalg.norm(K.A, 2):.3g}, written to {OUT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
