"""Batch benchmark: per robot joints, parameters, bound and synthesis time, certified mu, order; 2-worker speed-up.

Prints one JSON document::

    {"machine": {...}, "settings": {...},
     "robots": [{"robot", "joints", "entries" (uncertain parameters before
                 reduction: one per varying Jacobian entry, the paper's box),
                 "parameters" (after: the model "auto" resolves to), "model",
                 "uncertainty" (the set in one phrase), "inner_layer",
                 "bound_s", "synthesis_s", "analysis_s", "mu_upper", "mu_upper_grid",
                 "certified", "order", "structure", "alpha", "bandwidth" (rad/s),
                 "moving" (with --moving), "validation", "reason", "error"}, ...],
     "batch_seconds": ...,
     "speedup": {"robots": [...], "seconds_1_worker", "seconds_2_workers", "speedup"}}

Usage (the figures in docs/fleet.md)::

    python benchmarks/fleet.py --robots planar_2r,paper_2r:paper,TwoDofs,so101 \\
        --speedup-robots planar_2r,TwoDofs --max-iter 2 --samples 256

``--all-serial`` runs ``polyrob batch --all-serial`` instead: the robots of
``polyrob.fleet.serial_arms()`` (those this installation loads) with the command's own defaults for every
option not given here (the figures of "All serial arms" in docs/fleet.md)::

    python benchmarks/fleet.py --all-serial --max-bandwidth --speedup-robots ""

and on the engineer's set of each arm (per-link ±10 %, an instrument of 0-1.5 kg
within 0.1 m of the flange, friction: docs/uncertainty.md)::

    python benchmarks/fleet.py --all-serial --max-bandwidth --speedup-robots "" --robot-uncertainty default

``--moving`` adds each row's moving-robot certificate (``polyrob batch --moving``);
``--only so101,ur5`` keeps those of ``--all-serial``'s robots, with its defaults.
A run stopped with Ctrl-C (or SIGTERM) prints and saves (``--results``) the
robots it finished, as a record titled "(stopped)" that names the others.

A robot is ``NAME`` or ``NAME:DOMAIN`` (a named domain, e.g. ``paper_2r:paper``).
The robots of ``--robots`` run in one batch with ``-j`` workers; the speed-up
runs ``--speedup-robots`` once with 1 worker and once with 2.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import sys
import time

from _results import append_record, new_record, stamp


def _jobs(text: str) -> list:
    jobs = []
    for item in (x.strip() for x in text.split(",") if x.strip()):
        name, _, domain = item.partition(":")
        jobs.append({"robot": name, "domain": domain or None, "label": item.replace(":", "@")})
    return jobs


def _row(r) -> dict:
    t = r.timings

    def secs(key):  # None: the stage did not run (or the robot failed before it)
        return round(t[key], 2) if key in t else None

    return {
        "robot": r.name,
        "domain": r.domain,
        "inner": r.inner,
        "inner_layer": r.inner_layer,
        "uncertainty": r.uncertainty,
        "reflected_inertia": r.reflected_inertia,
        "status": r.status,
        "joints": r.joints,
        "entries": r.entries,
        "parameters": r.parameters,
        "model": r.model,
        "enclosure": r.enclosure,
        "bound_s": secs("bounds"),
        "synthesis_s": secs("synthesis"),
        "analysis_s": secs("analysis"),
        "reduction_s": secs("reduction"),
        "validation_s": secs("validation"),
        "total_s": round(r.seconds, 2),
        "mu_upper": r.mu_upper,
        "mu_upper_grid": r.mu_upper_grid,
        "mu_lower": r.mu_lower,
        "certified": r.certified,
        "order": r.order,
        "structure": r.structure,
        "alpha": r.alpha,
        "bandwidth": r.bandwidth,
        "moving": r.moving,
        "validation": r.validation,
        "reason": r.reason,
        "error": None if r.ok else f"{r.error}: {r.message}",
    }


def main(argv=None) -> int:
    from polyrob.fleet import run_batch

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--robots", default="planar_2r,paper_2r:paper,TwoDofs,so101")
    p.add_argument("--all-serial", action="store_true", help="polyrob.fleet.SERIAL_ARMS with the batch's defaults")
    p.add_argument(
        "--only", default=None, help="with --all-serial: only these of its robots (comma-separated), the same defaults"
    )
    p.add_argument("--speedup-robots", default="planar_2r,TwoDofs")
    p.add_argument("-j", "--workers", type=int, default=2, help="workers of the main batch")
    p.add_argument("--samples", type=int, default=None, help="bounds: Sobol' positions (default 256)")
    p.add_argument("--max-iter", type=int, default=None, help="D-K iterations (default 2)")
    p.add_argument("--omega", default=None, help="frequency grid LO:HI:N (default 0.01:1000:30)")
    p.add_argument("--mc", type=int, default=None, help="Monte Carlo sets of the analysis (default 50)")
    p.add_argument("--max-bandwidth", action="store_true", help="search the largest bandwidth factor")
    p.add_argument("--alphas", default=None, help="factors of the bandwidth search (comma-separated)")
    p.add_argument("--uncertainty", default="auto")
    p.add_argument(
        "--robot-uncertainty",
        default=None,
        help="a robot-uncertainty set for every job: 'default' (the engineer's set of each arm) or a YAML/JSON file",
    )
    p.add_argument("--moving", action="store_true", help="each row's moving-robot certificate too (batch --moving)")
    p.add_argument("--no-validate", action="store_true")
    p.add_argument(
        "--no-analysis", action="store_true", help="skip the mu analysis sweeps (the row: the synthesis certificate)"
    )
    p.add_argument(
        "--results",
        default=None,
        help="also append the batch as a record to this results file (e.g. benchmarks/results/fleet.json)",
    )
    args = p.parse_args(argv)
    if args.all_serial:
        from polyrob.fleet import serial_arms

        only = None if args.only is None else {name.strip() for name in args.only.split(",") if name.strip()}
        if only is not None and not only <= set(serial_arms()):
            raise SystemExit(
                f"--only {args.only}: not serial arms of this installation: {sorted(only - set(serial_arms()))}"
            )
        args.robots = ",".join(name for name in serial_arms() if only is None or name in only)
    else:  # the settings of the first figures of docs/fleet.md
        defaults = {"samples": 256, "max_iter": 2, "omega": "0.01:1000:30", "mc": 50}
        for key, value in defaults.items():
            if getattr(args, key) is None:
                setattr(args, key, value)
    options = dict(
        bound_options={} if args.samples is None else {"samples": args.samples},
        synthesis={} if args.max_iter is None else {"max_iter": args.max_iter},
        validate=not args.no_validate,
        analyze=not args.no_analysis,
        search_bandwidth=args.max_bandwidth,
        moving=args.moving,
        alphas=None if args.alphas is None else tuple(float(a) for a in args.alphas.split(",")),
    )
    if args.omega is not None:
        lo, hi, n = args.omega.split(":")
        options["omega"] = (float(lo), float(hi), int(n))
    if args.mc is not None:
        options["mc"] = args.mc

    extra = {}  # the job field: "default" as given, a file as its set's mapping
    if args.robot_uncertainty == "default":
        extra["robot_uncertainty"] = "default"
    elif args.robot_uncertainty is not None:
        from polyrob.uncertainty_set.spec import RobotUncertainty

        extra["robot_uncertainty"] = RobotUncertainty.from_file(args.robot_uncertainty).to_dict()

    def jobs(text):
        return [dict(j, uncertainty=args.uncertainty, **extra) for j in _jobs(text)]

    finished = []  # the robots done, in the order they finished (what a stopped run keeps)

    def show(r, done, total):
        finished.append(r)
        print(
            f"[{done}/{total}] {r.name}: "
            + (
                f"{r.status} mu (grid) {r.mu_upper_grid:.4g}, order {r.order}, alpha {r.alpha}, {r.validation} ({r.seconds:.0f} s)"
                if r.ok
                else f"FAILED {r.error}: {r.message}"
            ),
            file=sys.stderr,
            flush=True,
        )

    doc = {
        "machine": {
            "platform": platform.platform(),
            "machine": platform.machine(),
            "cores": len(os.sched_getaffinity(0)),
            "load_average_at_start": os.getloadavg(),
        },
        "settings": {
            **options,
            "uncertainty": args.uncertainty,
            "robot_uncertainty": args.robot_uncertainty,
            "workers": args.workers,
        },
    }
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # `kill` stops it as Ctrl-C does: the rows done are kept
    batch_jobs = jobs(args.robots)
    t0 = time.perf_counter()
    try:
        res = run_batch(batch_jobs, workers=args.workers, progress=show, **options)
    except KeyboardInterrupt:  # the batch cancelled its queue and ended its workers: keep the robots it finished
        names = [j["label"] for j in batch_jobs]
        doc.update(robots=[_row(r) for r in finished], stopped=True, batch_seconds=round(time.perf_counter() - t0, 1))
        doc["asked"], doc["unfinished"] = names, [n for n in names if n not in {r.name for r in finished}]
        doc["load_average_at_end"] = os.getloadavg()
        print(json.dumps(doc, indent=1, default=str))
        if args.results:
            append_record(args.results, "fleet", "benchmarks/fleet.py", fleet_record(doc))
        return 130
    doc["robots"] = [_row(r) for r in res.results]
    doc["batch_seconds"] = round(res.seconds, 1)
    if args.speedup_robots:
        sp = jobs(args.speedup_robots)
        one = run_batch(sp, workers=1, progress=show, **options)
        two = run_batch(sp, workers=2, progress=show, **options)
        doc["speedup"] = {
            "robots": [j["label"] for j in sp],
            "seconds_1_worker": round(one.seconds, 1),
            "seconds_2_workers": round(two.seconds, 1),
            "speedup": round(one.seconds / two.seconds, 2),
            "same_mu": [a.mu_upper == b.mu_upper for a, b in zip(one.results, two.results)],
        }
    doc["load_average_at_end"] = os.getloadavg()
    print(json.dumps(doc, indent=1, default=str))
    if args.results:
        append_record(args.results, "fleet", "benchmarks/fleet.py", fleet_record(doc))
    return 0


def fleet_record(doc: dict) -> dict:
    """The batch's results-file record: the robots' table and the count certified, with the command and machine."""
    from polyrob.fleet.outputs import controller_words, moving_words

    rows = doc["robots"]
    asked = bool(doc.get("settings", {}).get("moving"))  # a row that failed before its moving-robot stage: "–"
    certified = sum(bool(r["certified"]) for r in rows)
    columns = ["robot", "uncertainty", "inner layer", "model (real scalars)", "status", "frozen μ at every frequency"]
    columns += ["μ on the grid", "moving robot", "controller", "bandwidth rad/s", "factor α", "validation"]
    columns += ["bounds s", "robot s"]
    why = any(r.get("reason") for r in rows)
    columns += ["what stands in the way"] if why else []
    table = [
        [
            r["robot"],
            r.get("uncertainty") or "–",
            r.get("inner_layer") or "–",
            f"{r['model']} ({r['parameters']})" if r["model"] else "–",
            r["status"] or f"FAILED: {r['error']}",
            "–" if r["mu_upper"] is None else f"{r['mu_upper']:.4f}",
            "–" if r["mu_upper_grid"] is None else f"{r['mu_upper_grid']:.4g}",
            moving_words(r.get("moving")) or ("–" if asked or r.get("error") else "not asked (--moving)"),
            controller_words(r) or "–",
            "–" if r.get("bandwidth") is None else f"{r['bandwidth']:.3g}",
            "–" if r["alpha"] is None else f"{r['alpha']:.4g}",
            r["validation"] or "–",
            "–" if r["bound_s"] is None else f"{r['bound_s']:.0f}",
            f"{r['total_s']:.0f}",
        ]
        + ([r.get("reason") or "–"] if why else [])
        for r in rows
    ]
    figure = f"{certified} of {len(rows)} robots CERTIFIED; {doc['batch_seconds']:.0f} s"
    title = "Batch of " + ", ".join(doc.get("asked") or [r["robot"] for r in rows])
    if doc.get("stopped"):  # a stopped run: the robots it finished, the others named, no whole-batch time
        unfinished = doc.get("unfinished", [])
        figure = f"stopped after {doc['batch_seconds']:.0f} s: {len(rows)} robot(s) done, {certified} CERTIFIED"
        figure += f"; not finished: {', '.join(unfinished)}" if unfinished else ""
        title += " (stopped)"
    return new_record(
        "batch-" + stamp(),
        title,
        figure,
        table={"columns": columns, "rows": table},
        data=doc,
    )


if __name__ == "__main__":
    sys.exit(main())
