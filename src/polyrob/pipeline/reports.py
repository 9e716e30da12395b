"""Plain, JSON-ready descriptions of a robot and of a PLDI (what ``polyrob info``/``bounds`` print).

Examples
--------
>>> import polyrob
>>> robot = polyrob.load_robot("planar_2r")
>>> info = robot_report(robot, polyrob.Domain.from_robot(robot))
>>> info["neutral"]["M"]
[[60.625, 19.375], [19.375, 13.125]]
"""

from __future__ import annotations

__all__ = ["robot_report", "pldi_report", "model_report", "format_matrix"]


def format_matrix(rows, precision: int = 5) -> str:
    """A plain-text matrix of a list of lists; round-off (below 1e-10 of the largest entry) prints as 0."""
    from polyrob.report.numbers import zero_round_off

    cells = [[f"{x:.{precision}g}" for x in row] for row in zero_round_off(rows).tolist()]
    width = max((len(c) for row in cells for c in row), default=1)
    return "\n".join("[" + " ".join(c.rjust(width) for c in row) + "]" for row in cells)


def robot_report(robot, domain) -> dict:
    """Joints, limits, the domain, and ``M``/``B`` at the neutral point (``q = 0`` clipped into the domain)."""
    import numpy as np

    q0 = np.clip(np.zeros(robot.m), domain.q_lower, domain.q_upper)
    M = robot.mass_matrix(q0)
    _, B = robot.jacobians(q0, np.zeros(robot.m), np.zeros(robot.m))
    info = robot.describe()
    info["domain"] = domain.to_dict()
    info["neutral"] = {"q": q0.tolist(), "M": M.tolist(), "B": B.tolist()}
    true_robot = getattr(robot, "true_robot", None)
    if getattr(robot, "inner", "none") == "computed-torque" and true_robot is not None:
        # "M" is what the outer controller sees (M_hat^-1 M, the identity when nominal); this is the robot's own
        info["neutral"]["M_robot"] = true_robot.mass_matrix(q0).tolist()
    return info


def pldi_report(pldi, joint_names=None) -> dict:
    """The figures of a PLDI a user reads: entries, polytope, search, coverage, time, and an arm's factor proof."""
    import numpy as np

    poly = pldi.polytope
    names = list(joint_names or pldi.domain.joint_names)
    out = {
        "robot": pldi.robot_name,
        "domain": pldi.domain.to_dict(),
        "enclosure": pldi.enclosure,
        "entries": [
            {"name": n, "lower": float(lo), "upper": float(hi), "nominal": float(nm)}
            for n, lo, hi, nm in zip(pldi.entries, pldi.lower, pldi.upper, pldi.nominal)
        ],
        "polytope": {
            "halfspaces": int(poly.n_halfspaces),
            "vertices": None if poly.vertices is None else int(len(poly.vertices)),
            "reduced_dim": int(poly.reduced_dim),
            "volume_samples": int(poly.volume_samples),
            "volume_hits": int(poly.volume_hits),
            "volume_ratio": float(poly.volume_ratio) if poly.volume_hits else None,
            "volume_ratio_bound": float(poly.volume_ratio_bound) if poly.volume_samples else None,
        },
        "coverage": float(pldi.coverage) if pldi.coverage_points else None,
        "coverage_points": int(pldi.coverage_points),
        "dropped_positions": [names[j] for j in pldi.dropped_q],
        "seconds": float(pldi.info.get("seconds_total", float("nan"))),
    }
    if len(pldi.entries) and pldi.enclosure == "sampled":
        worst = int(np.argmax(pldi.refinement))
        out["refinement"] = {
            "max_percent": float(100 * pldi.refinement[worst]),
            "entry": pldi.entries[worst],
            "verification_rounds": int(pldi.info.get("verification_rounds", 0)),
        }
    proof = (pldi.info or {}).get("certify") or {}
    if proof.get("factors"):  # an arm's factor proof: how far it got, without its ranges (they are in the file)
        out["factor_proof"] = {key: v for key, v in proof.items() if key != "factors"}
    return out


def model_report(pldi, robot, models=("box", "auto"), *, coverage: int = 2000) -> dict:
    """Size and coverage of each uncertainty model built on ``pldi`` (what ``polyrob bounds`` prints).

    For every model: its real parameters and Δ channels, the fraction of
    ``coverage`` fresh domain samples whose Jacobians it contains (must be
    1.0), its volume over the PLDI's polytope (reduced coordinates; near 0
    for a model whose ``B`` lies on a curve or sheet) and the fraction of its
    members whose ``B = M(q)^-1`` is not positive definite
    (:func:`~polyrob.plant.coverage.input_definiteness`; the robot's always
    is).  ``"auto"`` is reported under the model it resolves to.
    """
    from polyrob.analysis.mu.blocks import as_block_structure
    from polyrob.errors import PolyrobError
    from polyrob.plant.coverage import input_definiteness
    from polyrob.plant.uncertainty import uncertain_plant

    out = {}
    for requested in models:
        try:
            unc = uncertain_plant(pldi, model=requested, robot=robot, coverage=coverage)
        except PolyrobError as exc:  # e.g. lft on an arm whose inertia is not affine in single angles
            out[requested] = {"error": str(exc)}
            continue
        out.setdefault(
            unc.model,
            {
                "parameters": int(unc.n_params),
                "delta_shape": [int(x) for x in as_block_structure(unc.block_structure).delta_shape],
                "coverage": float(unc.coverage),
                "coverage_points": int(unc.coverage_points),
                "volume_over_polytope": float(unc.volume_ratio),
                "input_not_positive_definite": input_definiteness(unc)["fraction"],
            },
        )
    return out
