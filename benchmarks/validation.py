"""Discretisation and quantisation of the paper's fixed-structure controller K*, as JSON.

    python benchmarks/validation.py [--rate HZ] [--grid N]
    python benchmarks/validation.py --controller K.json [--true-robots 20] [--rate HZ] [--encoder-bits 18]
        [--friction-viscous 1] [--friction-coulomb 2] [--seed 0]

On the paper's problem (``paper_2r --domain paper``, the paper's weights, the
box of 10 real parameters): the peak μ of the continuous loop on a grid,
the lowest sample rate whose discretised loop (plant by ZOH, K* by Tustin
pre-warped at the loop crossover, and by ZOH) keeps μ within 5 %, the
shortest coefficient word length (biquads per entry) at that rate and at
``--rate``, and whether the generated C reproduces the Python controller.

With ``--controller`` (a file as ``polyrob synth -o`` writes it, with its
robot, inner layer and task domain): the validation at the rate instead
(:func:`polyrob.validate.at_rate.runs.validate_at_rate`): the controller,
discretised, closed on ``--true-robots`` robots drawn from the default set
(per-link ±10 %, an instrument of 0-1.5 kg, capped at the rated payload,
centre of mass within 0.1 m of the flange), one sample of delay, quantised
encoders, friction not in the inner model; a step and the task's trajectory
on each; the aggregated figures and the per-run ones as JSON.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from _results import add_results_option, save_run


def _hz(rate) -> str:
    return "none found" if rate is None else f"{rate:.0f} Hz"


def validation_figure(out: dict) -> str:
    """One line of the JSON: the lowest rates and the shortest word lengths."""
    rates = ", ".join(
        f"{method} {_hz(out[f'min_rate_{method}'].get('min_rate_hz'))}"
        for method in ("tustin", "zoh")
        if f"min_rate_{method}" in out
    )
    words = ", ".join(
        f"{out[key]['min_word_length']} bits at {_hz(out[key]['rate_hz'])}"
        for key in ("word_length_at_min_rate", "word_length_at_rate")
        if key in out
    )
    return f"continuous mu {out['mu_continuous_grid']:.4g}; lowest rate {rates}; word length {words}"


def at_rate(args) -> None:
    """``--controller FILE``: the validation at the rate on drawn true robots."""
    import sys

    from polyrob.domains.task import domain_from_dict
    from polyrob.io.controller import load_controller, read_controller_file
    from polyrob.model.inner import inner_loop
    from polyrob.model.robots import load_robot
    from polyrob.progress import JobProgress
    from polyrob.validate.at_rate.loop import RealLoopConditions
    from polyrob.validate.at_rate.runs import validate_at_rate

    info = read_controller_file(args.controller).get("info") or {}
    robot = load_robot(info["robot"])
    words = str(info.get("inner", "") or "none")
    layer = next(
        (k for k in ("computed-torque", "gravity", "none") if words.startswith((f"inner layer: {k}", k))), None
    )
    if layer is None:
        raise SystemExit(f"{args.controller}: its inner layer {words[:60]!r} is not one this script reads")
    found = re.search(r"link masses/inertias ±([0-9.]+) %", words)  # the common factor the certificate covers
    error = float(found.group(1)) / 100.0 if found else 0.0
    arm = robot if layer == "none" else inner_loop(robot, layer, model_error=error)
    domain = domain_from_dict(info["domain"], robot=arm)
    conditions = RealLoopConditions(
        rate=args.rate,
        encoder_bits=args.encoder_bits,
        friction_viscous=args.friction_viscous,
        friction_coulomb=args.friction_coulomb,
    )
    t0 = time.perf_counter()
    job = JobProgress(["validation at the rate"], terminal=False, stream=sys.stderr).start()
    job.begin(1, "validation at the rate")
    try:
        res = validate_at_rate(
            arm,
            load_controller(args.controller),
            domain,
            conditions=conditions,
            true_robots=args.true_robots,
            seed=args.seed,
            q0=domain.pose,
        )
    finally:
        job.stop()
    out = {"controller": args.controller, "robot": robot.name, "inner": layer, **res.summary()}
    out["seconds"] = round(time.perf_counter() - t0, 1)
    save_run(args.results, "validation_at_rate", "The controller at the rate on drawn true robots", res.verdict(), out)
    print(json.dumps(out, indent=1, default=float))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--grid", type=int, default=30)
    ap.add_argument("--controller", default=None, help="a controller file: the validation at the rate instead")
    ap.add_argument("--true-robots", type=int, default=20)
    ap.add_argument("--encoder-bits", type=int, default=18)
    ap.add_argument("--friction-viscous", type=float, default=1.0)
    ap.add_argument("--friction-coulomb", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=0)
    add_results_option(ap)
    args = ap.parse_args()
    if args.controller:
        at_rate(args)
        return

    import polyrob
    from polyrob.plant.weights import paper_weights
    from polyrob.validate.discretize import continuous_mu, min_sample_rate, sampled_data_mu
    from polyrob.validate.export_c import write_c
    from polyrob.validate.quantize import min_word_length, sos_realization

    t0 = time.perf_counter()
    pldi = polyrob.bound_pldi(polyrob.load_robot("paper_2r"), samples=512, coverage=0, progress=False)
    P = polyrob.generalized_plant(polyrob.uncertain_plant(pldi), *paper_weights())
    K = polyrob.paper_controller()
    w = np.logspace(-3, 3.5, args.grid)
    out = {
        "problem": "paper_2r --domain paper, paper weights, box (10 real parameters), controller K*",
        "grid_points": args.grid,
    }
    t = time.perf_counter()
    mu_c = continuous_mu(P, K, w)
    out["mu_continuous_grid"] = mu_c
    for method in ("tustin", "zoh"):
        mr = min_sample_rate(P, K, mu_continuous=mu_c, omega=w, method=method, rate_bounds=(1.0, 1e5), rel_tol=0.02)
        out[f"min_rate_{method}"] = mr.summary()
    out["seconds_rate_search"] = round(time.perf_counter() - t, 1)
    for label, rate in (("at_min_rate", out["min_rate_tustin"]["min_rate_hz"]), ("at_rate", args.rate)):
        if rate is None:
            continue
        sd = sampled_data_mu(P, K, rate, omega=w)
        sos = sos_realization(sd.controller)
        t = time.perf_counter()
        wl = min_word_length(P, sos, threshold=1.05 * mu_c, omega=w, lengths=(8, 48))
        out[f"word_length_{label}"] = {
            "rate_hz": rate,
            "mu_discrete": sd.mu_upper_grid,
            **wl.summary(),
            "seconds": round(time.perf_counter() - t, 1),
        }
    cc = shutil.which("cc")
    if cc:
        sos = sos_realization(sampled_data_mu(P, K, args.rate, omega=w[:3]).controller)
        d = Path(tempfile.mkdtemp())
        write_c(sos, d)
        (d / "m.c").write_text(
            '#include <stdio.h>\n#include "controller.h"\nint main(void){controller_state_t s;'
            "double e[2]={1.0,0.0},u[2];int k;controller_reset(&s);for(k=0;k<1000;++k){"
            'controller_step(&s,e,u);printf("%.17g %.17g\\n",u[0],u[1]);}return 0;}\n'
        )
        subprocess.run(
            [cc, "-std=c99", "-Wall", "-Werror", "-o", str(d / "h"), str(d / "m.c"), str(d / "controller.c")],
            check=True,
        )
        c_out = np.loadtxt(
            subprocess.run([str(d / "h")], capture_output=True, text=True, check=True).stdout.splitlines()
        )
        py = sos.run(np.vstack([np.ones(1000), np.zeros(1000)])).T
        out["c_vs_python_max_rel_diff"] = float(np.max(np.abs(c_out - py) / np.maximum(1, np.abs(py))))
    out["seconds_total"] = round(time.perf_counter() - t0, 1)
    out = json.loads(json.dumps(out, default=float))
    save_run(args.results, "validation", "Sample rate and word length of the paper's K*", validation_figure(out), out)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
