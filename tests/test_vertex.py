"""Multi-vertex fixed-structure synthesis for the time-varying certificate."""

from __future__ import annotations

import control
import numpy as np
import pytest

from polyrob.analysis.time_varying.quadratic import quadperf
from polyrob.synthesis.fixed.vertex import vertex_peak, vertex_synthesis

W_S = control.tf([0.5, 0.2], [1.0, 0.002])  # |W_S| = 100 at DC, 0.5 at high frequency
W_T = control.tf([0.1, 0.5], [0.01, 1.0])


def _vertices():
    """A joint with stiffness -1..1 (gravity either way) and input gain 0.9..1.1."""
    return [(np.array([[0.0, 1.0], [k, -0.2]]), np.array([[0.0], [b]])) for k in (-1.0, 1.0) for b in (0.9, 1.1)]


def test_synthesis_lowers_the_worst_vertex_and_the_certificate_bounds_it():
    K0 = control.tf([2.0, 1.0], [0.05, 1.0])
    r = vertex_synthesis(_vertices(), W_S, W_T, structure="tf1", initial=K0, max_iter=40)
    assert r.grid_peak < r.initial_grid_peak
    # the optimiser's figure is what an independent evaluation of the returned controller gives
    assert abs(vertex_peak(_vertices(), r.controller, W_S, W_T) - r.grid_peak) <= 1e-9 * r.grid_peak
    # the sampled peak is a lower bound of every vertex norm, and these of the common-P level
    qp = quadperf(_vertices(), r.controller, W_S, W_T)
    assert qp.gamma >= qp.worst_vertex_hinf * (1 - 1e-6) >= r.grid_peak * (1 - 1e-6)
    assert r.quadstab.holds  # the certified controller is quadratically stabilising here
    assert r.order == 1 and r.n_vertices == 4 and r.vertex_source == "given"
    if r.quadperf is None:  # skipped only when it cannot hold
        assert r.grid_peak >= 1 and r.info["quadperf_skipped"]
    else:
        assert r.quadperf.holds == (r.quadperf.gamma < 1) and abs(r.quadperf.gamma - qp.gamma) <= 1e-6 * qp.gamma


def test_no_stabilising_gain_is_an_error():
    from polyrob.errors import SynthesisError

    # u = K e with K < 0 at every gain of the scan: positive feedback on every vertex
    with pytest.raises(SynthesisError):
        vertex_synthesis(_vertices(), W_S, W_T, structure="tf1", initial=control.tf([-5.0], [0.1, 1.0]), certify=False)


def test_the_one_vertex_enumeration_box_corners_and_halfspaces_agree():
    """Box corners and a polytope's vertices have one implementation each (polyrob.bounds.polytope)."""
    from polyrob.bounds.polytope import box_corners, halfspace_vertices

    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([1.0, 0.5, 3.0])
    corners = box_corners(lo, hi)
    assert corners.shape == (8, 3) and corners[0].tolist() == lo.tolist() and corners[-1].tolist() == hi.tolist()
    assert corners[1].tolist() == [-1.0, 0.0, 3.0]  # the last coordinate fastest
    assert box_corners([1.0, 2.0], [1.0, 3.0]).tolist() == [[1.0, 2.0], [1.0, 3.0]]  # lo == hi: one value
    assert box_corners([], []).shape == (1, 0)
    G, g = np.r_[np.eye(3), -np.eye(3)], np.r_[hi, -lo]
    # the box as half-spaces, with a row that does not constrain (a constant entry, g below 0 by rounding)
    v = halfspace_vertices(np.r_[G, np.zeros((1, 3))], np.r_[g, -1e-17])
    assert sorted(np.round(v, 12).tolist()) == sorted(corners.tolist())
    assert halfspace_vertices(G, np.r_[hi, -hi - 1.0]) is None  # empty


def test_its_rounds_move_the_jobs_progress_line(monkeypatch):
    """``--init true-robots`` tunes for minutes on a six-joint arm: each round moves the line, within its span."""
    import io

    from clocks import FakeClock

    import polyrob.synthesis.fixed.vertex as vertex
    from polyrob.progress import JobProgress, span

    job = JobProgress(["synthesis"], stream=io.StringIO(), clock=FakeClock(now=0.0))
    job.start()
    job._stop.set()  # no real-time ticks: the shares are read directly
    seen, real_report = [], vertex.report

    def spy(done, total):
        real_report(done, total)
        seen.append(job.share)

    monkeypatch.setattr(vertex, "report", spy)
    try:
        job.begin(1, "synthesis (full)")
        with span(0.0, 0.5):
            vertex_synthesis(
                _vertices(), W_S, W_T, structure="tf1", initial=control.tf([2.0, 1.0], [0.05, 1.0]),
                max_iter=40, certify=False,
            )  # fmt: skip
        after = job.share
    finally:
        job.stop()
    assert seen and 0 < seen[0] <= 0.5 and after == 0.5
