"""What each arm's certificate covers beside the engineer's set, and whether the model can hold that set (JSON).

    python benchmarks/default_set.py [ARM ...] [--results PATH]

For every serial arm of three joints or more (default: those of
``polyrob batch --all-serial``): the default task's own set (one factor on
all links, the payload range at the flange, :class:`polyrob.domains.
default_task.DefaultTask`) and the engineer's set of ``--robot-uncertainty
default`` (:func:`polyrob.uncertainty_set.default_set.default_set`), with
the ``inner-links`` model's answer on the default task
(:func:`polyrob.plant.models.inner_links.carried`, the check ``synth`` makes
before its bounds): carried or refused, with the bound of the inertia block
and the room its centre leaves (:func:`~polyrob.plant.models.inner_links.light_model`'s
``info``), and when refused the range of the true robots' inertia against
the model's.  Seconds per arm; no synthesis.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time

from _results import add_results_option, save_run

REFUSAL = re.compile(
    r"its bound ([\d.e+-]+) .* not below the ([\d.e+-]+) the centre leaves; "
    r"the true robots' inertia ranges from ([\d.e+-]+) to ([\d.e+-]+) times"
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("arms", nargs="*", help="robot names (default: the batch's serial arms of 3+ joints)")
    add_results_option(ap)
    args = ap.parse_args()

    from polyrob.domains.default_task import DEFAULT_TASK, applies_to, default_task_domain
    from polyrob.errors import NotApplicable
    from polyrob.fleet.batch import serial_arms
    from polyrob.model.inner import inner_loop_of_set
    from polyrob.model.robots import load_robot
    from polyrob.plant.models.inner_links import light_model
    from polyrob.uncertainty_set.default_set import default_set

    rows, out = [], []
    for name in args.arms or serial_arms():
        robot = load_robot(name)
        if not applies_to(robot.m):
            continue
        t0 = time.perf_counter()
        payload = DEFAULT_TASK.payload_range(robot)
        task_set = (
            f"links x[{1 - DEFAULT_TASK.model_error:g}, {1 + DEFAULT_TASK.model_error:g}] together, "
            f"0-{payload.mass_upper:.2g} kg at the flange"
        )
        spec = default_set(robot)
        loop = inner_loop_of_set(robot, "computed-torque", spec)
        try:
            info = light_model(loop, default_task_domain(loop, DEFAULT_TASK)).info
            why = None
        except NotApplicable as exc:
            why = str(exc).removeprefix("inner-links: ")
        entry = {"robot": name, "joints": robot.m, "default_task_set": task_set, "set": spec.words(),
                 "source": spec.source, "carried": why is None, "why": why}  # fmt: skip
        found = REFUSAL.search(why or "")
        if found:
            entry.update(zip(("g_bound", "g_room", "inertia_low", "inertia_high"), map(float, found.groups())))
            verdict = (
                f"refused: block bound {entry['g_bound']:.3g} against {entry['g_room']:.3g}; true inertia "
                f"{entry['inertia_low']:.2g} to {entry['inertia_high']:.2g} times the model's"
            )
        elif why is None:
            entry.update(g_bound=info["residual_g_norm"], g_room=1.0 - float(info["K_offset"][-1, -1]))
            verdict = f"carried: block bound {entry['g_bound']:.3g} against {entry['g_room']:.3g}"
        else:
            verdict = f"refused: {why}"
        instrument = "no instrument (rating unknown)" if spec.payload is None else (
            f"instrument 0-{spec.payload.mass_upper:g} kg within {spec.payload.com_radius:g} m")  # fmt: skip
        entry["seconds"] = time.perf_counter() - t0
        out.append(entry)
        rows.append([name, robot.m, task_set, f"per-link ±10 %, {instrument}", verdict])
        print(f"{name}: {verdict} ({entry['seconds']:.1f} s)", file=sys.stderr, flush=True)
    doc = {"arms": out}
    print(json.dumps(doc, indent=1, default=float))
    table = {
        "columns": ["arm", "joints", "the default task's certified set", "the engineer's set (--robot-uncertainty default)",
                    "inner-links model"],
        "rows": rows,
    }  # fmt: skip
    held = sum(e["carried"] for e in out)
    figure = f"{held} of {len(out)} arms' default sets carried; refused: " + ", ".join(
        e["robot"] for e in out if not e["carried"]
    )
    save_run(args.results, "default_set", "The engineer's set on each arm: carried or refused", figure, doc, table)


if __name__ == "__main__":
    main()
