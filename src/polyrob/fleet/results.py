"""What one robot of a batch gave: :class:`RobotResult`, and the controller as plain arrays.

The controller travels back from a worker as plain arrays
(:func:`controller_data`), since python-control systems hold lambdas and do
not pickle; :func:`controller_system` rebuilds it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["RobotResult", "controller_data", "controller_system"]


@dataclass(frozen=True, eq=False)
class RobotResult:
    """What one job gave (or why it failed).

    ``ok`` is False when the job raised; then ``error`` is the exception
    class name and ``message`` its one line, and the figures are ``None``.
    ``status`` is the controller's :class:`~polyrob.analysis.certificate.Certificate`
    status on the robot's problem (the analysis' certificate when it ran, the
    design's otherwise: the same call), ``verdict`` its line; ``mu_upper`` is
    the μ bound proved at every frequency (``None``: none was), ``mu_upper_grid``
    the peak upper bound on the frequency grid, ``mu_lower`` the lower bound.  ``validation`` is the nonlinear simulation's
    verdict line when it ran (``None`` otherwise); ``validation_at_rate`` the validation at
    the rate on true robots drawn from the set (:mod:`polyrob.validate.at_rate`): its figures
    per reference, whether every run met the bar and its verdict line (``None``: not run).  ``reason`` says, for a
    robot left without a certificate, what stands in the way: the
    performance limit of its unstable poles at the weights used
    (:mod:`polyrob.analysis.limits`), a model whose ``B = M^-1`` is not
    positive definite (:func:`polyrob.plant.coverage.input_definiteness`),
    or neither found (then μ ≥ 1 is the synthesis' best).  ``domain`` is the
    domain's name (a task domain's says pose, radius and rate bounds),
    ``inner`` the inner layer with its ranges (``"none"``), ``inner_layer``
    its kind alone (``"computed-torque"``, ``"gravity"``, ``"none"``),
    ``uncertainty`` the set of true robots in one phrase (``None``: none is
    stated; the model is the Jacobians over the domain), and
    ``reflected_inertia`` whether and whence rotor inertia is in ``M(q)``.
    ``structure`` is the controller's (``"pid"``: per-joint PID; ``"full"``:
    full order, reduced to ``order`` when the reduction kept one) and
    ``bandwidth`` the nominal loop's largest gain crossover in rad/s
    (:func:`~polyrob.synthesis.bandwidth_stop.loop_crossover`).  A job that
    fails after its problem is built keeps what the problem says (joints,
    model, domain, inner layer, uncertainty).
    ``moving`` is the moving-robot certificate when the batch computed it
    (``Settings.moving``): its status, bound and verdict line; once computed
    it decides :attr:`certified` with μ.
    """

    name: str
    robot: str
    ok: bool
    error: str | None = None
    message: str | None = None
    joints: int | None = None
    entries: int | None = None
    parameters: int | None = None
    model: str | None = None
    enclosure: str | None = None
    domain: str | None = None
    inner: str | None = None
    inner_layer: str | None = None
    uncertainty: str | None = None
    reflected_inertia: str | None = None
    mu_upper: float | None = None
    mu_upper_grid: float | None = None
    mu_lower: float | None = None
    status: str | None = None
    order: int | None = None
    structure: str | None = None
    alpha: float | None = None
    bandwidth: float | None = None
    verdict: str | None = None
    validation: str | None = None
    validation_at_rate: dict | None = None
    moving: dict | None = None
    reason: str | None = None
    seconds: float = 0.0
    timings: dict = field(default_factory=dict)
    controller: dict | None = None
    certificate: dict = field(default_factory=dict)
    problem: dict = field(default_factory=dict)
    details: dict = field(default_factory=dict)

    @property
    def certified(self) -> bool:
        """Reads the status (decided in polyrob.analysis.certificate) and, once computed, the moving-robot one."""
        from polyrob.analysis.certificate import Status
        from polyrob.analysis.lpv.moving_result import refuses

        return self.status is not None and Status(self.status).certified and not refuses(self.moving)

    def controller_system(self):
        """The controller as a python-control system (``None`` for a failed job)."""
        return None if self.controller is None else controller_system(self.controller)

    def row(self) -> dict:
        """The summary table's row (JSON-ready)."""
        keys = (
            "name",
            "robot",
            "ok",
            "error",
            "message",
            "joints",
            "entries",
            "parameters",
            "model",
            "enclosure",
            "domain",
            "inner",
            "inner_layer",
            "uncertainty",
            "reflected_inertia",
            "mu_upper",
            "mu_upper_grid",
            "mu_lower",
            "status",
            "order",
            "structure",
            "alpha",
            "bandwidth",
            "verdict",
            "validation",
            "validation_at_rate",
            "moving",
            "reason",
        )
        out = {k: getattr(self, k) for k in keys}
        out["certified"] = self.certified
        out["seconds"] = round(float(self.seconds), 2)
        out["timings"] = {k: round(float(v), 2) for k, v in self.timings.items()}
        return out


def controller_data(K) -> dict:
    """A controller as plain arrays (python-control systems do not pickle: they hold lambdas)."""
    import control
    import numpy as np

    from polyrob.controller import Controller

    if isinstance(K, Controller):
        return {"type": "ss", **dict(zip("ABCD", K.matrices))}
    if isinstance(K, control.TransferFunction):
        return {
            "type": "tf",
            "num": [[np.asarray(K.num[i][j], float) for j in range(K.ninputs)] for i in range(K.noutputs)],
            "den": [[np.asarray(K.den[i][j], float) for j in range(K.ninputs)] for i in range(K.noutputs)],
        }
    K = control.ss(K)
    return {"type": "ss", **{k: np.asarray(getattr(K, k), float) for k in "ABCD"}}


def controller_system(data: dict):
    """The python-control system of :func:`controller_data`."""
    import control

    if data["type"] == "tf":
        return control.tf(data["num"], data["den"])
    return control.ss(data["A"], data["B"], data["C"], data["D"])
