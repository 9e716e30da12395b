"""Wall time and exit status of every `polyrob` command the README shows, as JSON.

    python benchmarks/readme_commands.py [--skip WORD ...] [--timeout SECONDS] [--workdir DIR]

Runs the commands of README.md's ```bash blocks one after the other, as
written, in ``--workdir`` (a fresh temporary folder by default, so ``-o``
outputs and the controller files one command writes for the next stay
there), each in its own process.  Prints one JSON document:
per command the seconds, the exit status (0 CERTIFIED or success, 1 ran but
not certified, 2 bad input), its last line of output (stderr after
stdout: often a progress line), and the load average before it: a figure measured on a loaded
machine says so.  ``--skip`` leaves out commands containing a word (e.g.
``tf3`` for the 5-start fixed-structure synthesis of about ten minutes).
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

from _results import append_record, new_record, stamp

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_commands() -> list[str]:
    """The `polyrob ...` commands of the README's bash blocks, in order (comments dropped)."""
    out = []
    for block in re.findall(r"```bash\n(.*?)```", README.read_text(), flags=re.S):
        for line in block.splitlines():
            line = line.split("  #")[0].strip()
            for part in line.split("&&"):
                part = part.strip()
                if part.startswith("polyrob "):
                    out.append(part)
    return out


def run(command: str, cwd: Path, timeout: float) -> dict:
    argv = [sys.executable, "-m", "polyrob.cli", *shlex.split(command)[1:]]
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=timeout)
        code, text = proc.returncode, (proc.stdout + proc.stderr).strip()
    except subprocess.TimeoutExpired:
        code, text = None, f"stopped after {timeout:g} s"
    lines = [x for x in text.splitlines() if x.strip()]
    return {
        "command": command,
        "seconds": round(time.perf_counter() - t0, 1),
        "exit_status": code,
        "last_line": lines[-1][:300] if lines else "",
        "load_average_before": round(load, 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip", nargs="*", default=[], help="leave out commands containing any of these words")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per command")
    ap.add_argument("--workdir", default=None, help="where the commands run (default: a temporary folder)")
    ap.add_argument("--results", default=None, help="also append a record to this results file")
    args = ap.parse_args()
    commands = [c for c in readme_commands() if not any(w in c for w in args.skip)]
    with tempfile.TemporaryDirectory() as tmp:
        cwd = Path(args.workdir or tmp)
        cwd.mkdir(parents=True, exist_ok=True)
        results = []
        for c in commands:
            results.append(run(c, cwd, args.timeout))
            print(f"{results[-1]['seconds']:8.1f} s  exit {results[-1]['exit_status']}  {c}", file=sys.stderr)
    doc = {"cores": os.cpu_count(), "skipped": args.skip, "commands": results}
    print(json.dumps(doc, indent=1))
    if args.results:
        table = {
            "columns": ["command", "seconds", "exit status", "last line"],
            "rows": [[r["command"], f"{r['seconds']:g}", str(r["exit_status"]), r["last_line"][:120]] for r in results],
        }
        record = new_record(
            "commands-" + stamp(), "Wall time of each README command", f"{len(results)} commands", table=table, data=doc
        )
        append_record(args.results, "readme_commands", "benchmarks/readme_commands.py", record)


if __name__ == "__main__":
    main()
