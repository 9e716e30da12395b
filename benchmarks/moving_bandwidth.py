"""What bandwidth costs in motion: the main job's frozen μ and its moving gain found, per bandwidth factor, as JSON.

    python benchmarks/moving_bandwidth.py [--factors 0.5,1,8,32] [--results benchmarks/results/moving_bandwidth.json]

For each factor ``f`` runs ``polyrob run --json --quiet --bandwidth-scale f``
(the main job, both bandwidths of the paper's weights times ``f``) in a fresh
process, as a user would, and reads from its JSON: the frozen robot's
certificate (status, bound), the controller's order, and the moving robot's
largest L2 gain found along admissible motions of the task
(:func:`polyrob.analysis.time_varying.trajectory_gains.trajectory_lower_bound`:
simulated, a lower bound, not a certificate).  A found gain at or above 1
means robust performance fails for the linearised robot along that motion,
whatever the frozen verdict says.  ``--results PATH`` also appends the runs as
one record (``benchmarks/results/moving_bandwidth.json``, shown in
docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

from _results import append_record, new_record, stamp


def one(factor: float) -> dict:
    """One factor's run: the frozen certificate, the order and the moving gain found."""
    cmd = [sys.executable, "-m", "polyrob.cli", "run", "--json", "--quiet", "--bandwidth-scale", f"{factor:g}"]
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    out = {"factor": factor, "seconds": round(time.perf_counter() - t0, 1), "exit_status": proc.returncode,
           "load_average_before": round(load, 2)}  # fmt: skip
    try:
        doc = json.loads(proc.stdout)
    except json.JSONDecodeError:
        out["error"] = (proc.stderr.strip().splitlines() or ["no JSON on stdout"])[-1]
        return out
    analysis = doc.get("analysis") or {}
    cert = (analysis.get("robust_performance") or {}).get("certificate") or {}
    lower = (analysis.get("moving") or {}).get("lower") or {}
    out.update(
        frozen_status=cert.get("status"),
        frozen_bound=cert.get("bound"),
        controller_order=analysis.get("controller_order"),
        moving_found=lower.get("gamma"),
        moving_at_rest=lower.get("frozen_gamma"),
        moving_worst=lower.get("worst"),
        verdict=doc.get("verdict"),
    )
    return out


def record(runs: list) -> dict:
    """The runs as one results-file record, one table row per factor."""
    rows, words = [], []
    for r in runs:
        if "error" in r:
            rows.append([f"{r['factor']:g}", r["error"], "", "", "", "", f"{r['seconds']:g} s"])
            continue
        found = r.get("moving_found")
        fails = found is not None and found >= 1.0
        rows.append([
            f"{r['factor']:g}",
            f"{r.get('frozen_status')} (mu <= {r['frozen_bound']:.4g})" if r.get("frozen_bound") else str(r.get("frozen_status")),
            str(r.get("controller_order")),
            "–" if found is None else f"{found:.4g}" + (" (fails in motion)" if fails else ""),
            "–" if r.get("moving_at_rest") is None else f"{r['moving_at_rest']:.4g}",
            r.get("moving_worst") or "–",
            f"{r['seconds']:g} s",
        ])  # fmt: skip
        words.append(f"x{r['factor']:g}: frozen {r.get('frozen_status')}, moving found "
                     + ("–" if found is None else f"{found:.4g}"))  # fmt: skip
    table = {"columns": ["bandwidth factor", "frozen robot", "order", "moving robot: gain found (lower)",
                         "at rest", "worst motion", "time"], "rows": rows}  # fmt: skip
    return new_record("moving-bandwidth-" + stamp(), "The main job per bandwidth factor: frozen mu and the gain found "
                      "in motion", "; ".join(words), table=table, data={"runs": runs})  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factors", default="0.5,1,8,32", help="bandwidth factors, comma-separated")
    ap.add_argument("--results", default=None, help="also append a record to this results file")
    args = ap.parse_args(argv)
    runs = [one(float(f)) for f in args.factors.split(",")]
    print(json.dumps({"runs": runs}, indent=1))
    if args.results:
        append_record(args.results, "moving_bandwidth", "benchmarks/moving_bandwidth.py", record(runs))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
