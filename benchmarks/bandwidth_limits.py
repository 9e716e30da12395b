"""The largest bandwidth certified on each arm's default task, and the bound that stops it (JSON).

    python benchmarks/bandwidth_limits.py [CASE ...] [--results PATH]

A case is an arm and, optionally, more options of ``polyrob synth`` in one
argument: ``ur5``, ``"ur5 --encoder-bits 14"``, ``"ur5 --rate 2000 --alphas
22.6,32"`` (default: ur5 and panda, the arms issue 39 names, at the
defaults).  For each case this runs the command a user types, ``polyrob
synth ARM --max-bandwidth --json [OPTIONS]`` (the limit weights on: 18-bit
encoders, the effort limits, 1 kHz and one sample of delay unless the
options say otherwise), in a child process, and records what it printed: the largest
certified factor α of the automatic weights' bandwidths, its μ bound, the
certified loop's crossover in rad/s against the sample rate's cap, the
bound the search hit (``bound_hit``), the factors tried, the wall time and
the child's peak memory, the machine's load at the start and the end, and the noise channel's gain at high frequency,
``σ̄(W_u K(∞) W_n)`` of the certified controller (``K(∞)`` its
feedthrough ``D``; the channel ``W_u K S W_n`` tends to it where ``S → I``):
how near the encoder-noise / effort bound is when another bound stops the
search (1 = binding).  ``--alphas`` in a case narrows the scan (the same
option of ``polyrob synth``).  Nothing here is timed by a test.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _results import add_results_option, save_run

DEFAULT_ARMS = ("ur5", "panda")


def measure(case: str) -> dict:
    """One ``polyrob synth ARM --max-bandwidth --json [OPTIONS]`` run, read from its JSON."""
    arm, *options = shlex.split(case)
    with tempfile.TemporaryDirectory() as tmp:
        K_path = Path(tmp) / "K.json"
        cmd = [sys.executable, "-m", "polyrob", "synth", arm, "--max-bandwidth", *options, "--json", "--quiet"]
        t0, load0 = time.perf_counter(), os.getloadavg()[0]
        out_path, err_path = Path(tmp) / "out", Path(tmp) / "err"
        with out_path.open("w") as fo, err_path.open("w") as fe:
            child = subprocess.Popen([*cmd, "-o", str(K_path)], stdout=fo, stderr=fe)
            # wait4: this child's own peak memory (RUSAGE_CHILDREN is the largest of every case run so far)
            _, status, usage = os.wait4(child.pid, 0)
        returncode, peak_gb = os.waitstatus_to_exitcode(status), usage.ru_maxrss / 1e6
        child.returncode = returncode  # reaped here: Popen must not wait for it again
        stdout, stderr = out_path.read_text(), err_path.read_text()
        D = np.asarray(json.loads(K_path.read_text())["D"], float) if K_path.exists() else None
    seconds = time.perf_counter() - t0
    load = (load0, os.getloadavg()[0])  # the machine's 1-minute load at the start and the end: shared machines
    if returncode not in (0, 1):  # 1: a verdict that is not CERTIFIED, still a result
        tail = stderr.strip().splitlines()[-1:] or ["(no output)"]
        raise SystemExit(f"{arm}: polyrob synth exited {returncode}: {tail[0]}")
    out = json.loads(stdout)
    b = out["bandwidth_scaling"]
    h = b["hyperparameters"]
    noise_hf = None
    if D is not None and "effort" in h and "noise" in h:
        noise_hf = float(np.linalg.norm(np.diag(h["effort"]) @ D @ np.diag(h["noise"]), 2))
    return {
        "robot": arm,
        "options": " ".join(options),
        "command": " ".join(["polyrob", *cmd[3:]]),
        "alpha": b["alpha"],
        "mu_bound": b["peak_mu"],
        "bracket": b["bracket"],
        "crossover_rad_s": b["crossover_rad_s"],
        "crossover_limit_rad_s": b["crossover_limit_rad_s"],
        "bound_hit": b["bound_hit"],
        "stopped_by": b["stopped_by"],
        "history": b["history"],
        "order": b.get("order"),
        "omega_b_rad_s": [min(b["hyperparameters"]["omega_b"]), max(b["hyperparameters"]["omega_b"])],
        "noise_channel_at_high_frequency": noise_hf,
        "verdict": out.get("verdict"),
        "seconds": round(seconds, 1),
        "load_average": [round(v, 2) for v in load],
        "peak_gb": round(peak_gb, 2),
    }


def bound_cell(text: str) -> str:
    """The bound's name from synth's ``bound_hit`` sentence (``"sample rate: at alpha = ..."`` -> ``"sample rate"``).

    The channel μ rests on (:mod:`polyrob.synthesis.channel_mu`'s words) is shortened to its name and figures.
    """
    if "nearest bound at" in text:  # records made before the line read mu: the nominal-peak rule
        name = text.split("nearest bound at", 1)[1].split(":")[1].strip()
        return f"the next factor's synthesis failed; by the nominal-peak rule: {name}"
    words = text.split(": ", 1)[1] if text.startswith(("at alpha", "alpha")) and ": " in text else None
    if words is None:
        return text.split(":")[0]
    lent = " (the last certified controller on its weights)" if "controller on its weights" in text else ""
    m = re.match(r"(.*) binds: grid mu ([\d.]+) with every channel, ([\d.]+) without it", words)
    if m:
        return f"{m[1]} binds: grid μ {m[2]}, {m[3]} without it{lent}"
    m = re.match(r"no single channel: grid mu ([\d.]+) .*the largest drop without (.*), to ([\d.]+) \(", words)
    if m:
        return f"μ rests most on {m[2]}: grid μ {m[1]}, {m[3]} without it{lent}"
    return words.split(":")[0] + lent


def table_row(entry: dict) -> list:
    """The docs' row of one case."""
    low, high = entry["bracket"]  # high None: the scan's largest factor certified (nothing failed above it)
    bracket = f"{low:.3g}-{high:.3g}" if high is not None else f"{low:.3g} (the scan's top)"
    return [
        entry["robot"], entry["options"] or "(defaults)", f"{entry['alpha']:.3g}", f"{entry['mu_bound']:.4f}",
        f"{entry['omega_b_rad_s'][0]:.3g}-{entry['omega_b_rad_s'][1]:.3g}",
        crossover_cell(entry),
        bound_cell(entry["bound_hit"]),
        "-" if entry["noise_channel_at_high_frequency"] is None else f"{entry['noise_channel_at_high_frequency']:.2f}",
        bracket, entry["order"], f"{entry['seconds']:.0f} s (load {entry['load_average'][0]:.1f}-{entry['load_average'][1]:.1f})",
    ]  # fmt: skip


def crossover_cell(entry: dict) -> str:
    """``"99.2 (cap 100)"``; without a rate (the paper's weights alone) there is no cap."""
    wc, cap = entry["crossover_rad_s"], entry["crossover_limit_rad_s"]
    shown = "-" if wc is None or wc != wc else f"{wc:.1f}"
    return shown + (" (no rate)" if cap is None or cap != cap else f" (cap {cap:.0f})")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("cases", nargs="*", default=list(DEFAULT_ARMS),
                    help="an arm and more synth options in one argument (default: ur5 panda)")  # fmt: skip
    add_results_option(ap)
    args = ap.parse_args()
    rows, out = [], []
    for case in args.cases:
        entry = measure(case)
        out.append(entry)
        rows.append(table_row(entry))
        print(f"{case}: alpha {entry['alpha']:.4g}, crossover {crossover_cell(entry)} rad/s, {entry['bound_hit']} "
              f"({entry['seconds']:.0f} s)", file=sys.stderr, flush=True)  # fmt: skip
    doc = {"arms": out}
    print(json.dumps(doc, indent=1, default=float))
    table = {
        "columns": ["arm", "options", "largest certified α", "μ ≤", "ω_B [rad/s]", "crossover [rad/s]", "bound hit",
                    "noise channel at high frequency (1 binds)", "bracket of α", "order", "wall time"],
        "rows": rows,
    }  # fmt: skip
    figure = "; ".join(
        f"{e['robot']} {e['options']}".strip()
        + f": alpha {e['alpha']:.3g}, crossover {crossover_cell(e)} rad/s, {bound_cell(e['bound_hit'])}"
        for e in out
    )
    save_run(args.results, "bandwidth_limits", "The largest certified bandwidth on each arm's default task", figure,
             doc, table)  # fmt: skip


if __name__ == "__main__":
    main()
