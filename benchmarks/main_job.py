"""Wall time and outcome of the main job, ``polyrob run`` (README's first command), as JSON.

    python benchmarks/main_job.py [--output-dir DIR] [--repeat N] [--results benchmarks/results/main_job.json]

Runs ``polyrob run --json`` (no robot: the main job, see
``polyrob.cli.run.MAIN_JOB``) as a user would, in a fresh process, and
``polyrob run -o DIR`` (the same job with the validation and ``report.html``)
when ``--output-dir`` is given.  Prints one JSON document: per command the
wall-clock seconds, the exit status, the certificate's status and bound, the
moving-robot and arbitrarily fast verdicts' statuses, the controller's order, and the machine (cores, load average before the run):
a figure measured on a loaded machine says so.  The install is not timed.
``--results PATH`` also appends the runs as one record to a results file
(``benchmarks/results/main_job.json``: the docs' figures are generated from it).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from _results import append_record, new_record, stamp


def _run(cmd: list[str]) -> dict:
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    out = {"command": " ".join(cmd[2:]), "seconds": round(seconds, 1), "exit_status": proc.returncode}
    out["load_average_before"] = round(load, 2)
    try:
        doc = json.loads(proc.stdout)
    except json.JSONDecodeError:
        out["error"] = (proc.stderr.strip().splitlines() or ["no JSON on stdout"])[-1]
        return out
    cert = doc.get("analysis", {}).get("robust_performance", {}).get("certificate", {})
    analysis = doc.get("analysis", {})
    moving = analysis.get("moving") or {}
    fast = analysis.get("time_varying") or {}
    out.update(
        moving_status=moving.get("status") or "not computed",
        moving_verdict=moving.get("verdict"),
        time_varying_status=fast.get("status") or "not computed",
        status=cert.get("status"),
        bound=cert.get("bound"),
        controller_order=doc.get("analysis", {}).get("controller_order"),
        verdict=doc.get("verdict"),
        report=doc.get("report"),
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--output-dir", default=None, help="also time `polyrob run -o DIR` (validation and report)")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each command")
    ap.add_argument("--results", default=None, help="also append a record to this results file")
    args = ap.parse_args()
    base = [sys.executable, "-m", "polyrob.cli", "run", "--json", "--quiet"]
    runs = [_run(base) for _ in range(args.repeat)]
    if args.output_dir:
        for k in range(args.repeat):
            target = Path(args.output_dir) / f"run{k}" if args.repeat > 1 else Path(args.output_dir)
            runs.append(_run(base + ["-o", str(target)]))
    doc = {
        "machine": {
            "cores": os.cpu_count(),
            "python": platform.python_version(),
            "platform": platform.platform(),
        },
        "runs": runs,
    }
    print(json.dumps(doc, indent=1))
    if args.results:
        append_record(args.results, "main_job", "benchmarks/main_job.py", main_job_record(doc))


def main_job_record(doc: dict) -> dict:
    """The runs as one results-file record: the first run's verdict, every run's seconds."""
    first = doc["runs"][0]
    seconds = ", ".join(f"{r['seconds']:g} s" + (" (with -o)" if " -o " in r["command"] else "") for r in doc["runs"])
    figure = f"{first.get('status')}, mu <= {first.get('bound')}, controller of order {first.get('controller_order')}; {seconds}"
    return new_record("main-job-" + stamp(), "The main job: polyrob run (no robot)", figure, data=doc)


if __name__ == "__main__":
    main()
