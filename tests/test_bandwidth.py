"""The bandwidth-factor search (polyrob.synthesis.bandwidth) with stand-in syntheses.

The real syntheses take minutes per α on the paper's robot; the search logic
is tested here against μ(α) curves whose answer is known in closed form.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from polyrob.errors import PolyrobError, SynthesisError
from polyrob.synthesis.bandwidth import max_bandwidth_scaling, scaled_hyperparameters


def _result(mu, K, status=None):
    """A stand-in synthesis result: its certificate is CERTIFIED exactly when mu < 1 (unless told otherwise)."""
    status = status or ("CERTIFIED" if mu < 1 else "NOT_CERTIFIED")
    cert = SimpleNamespace(certified=status == "CERTIFIED", bound=mu, status=status)
    return SimpleNamespace(certificate=cert, peak_mu=mu, controller=K, order=3)


def _search(mu_of_alpha, **options):
    calls = []

    def synthesize(P, K0):
        calls.append((P.alpha, K0))
        return _result(mu_of_alpha(P.alpha), f"K({P.alpha:g})")

    res = max_bandwidth_scaling(
        None, synthesize=synthesize, plant=lambda a, h: SimpleNamespace(alpha=a, h=h), progress=False, **options
    )
    return res, calls


def test_u_shaped_mu_gives_the_largest_alpha():
    # mu < 1 exactly for alpha in (0.5, 3): too small a bandwidth fails too
    mu = lambda a: 1 + (a - 3) * (a - 0.5) / 10  # noqa: E731
    res, calls = _search(mu, rtol=0.01)
    assert res.alpha < 3 < res.bracket[1] <= res.alpha * 1.01
    assert res.peak_mu == pytest.approx(mu(res.alpha)) and res.peak_mu < 1
    assert res.hyperparameters["omega_b"] == pytest.approx((0.5 * res.alpha, 0.1 * res.alpha))
    # warm starts: every synthesis after the first starts from the nearest solved alpha
    assert calls[0][1] is None and all(K0 is not None for _, K0 in calls[1:])
    assert [a for a, _ in res.history] == [a for a, _ in calls]


def test_largest_grid_point_already_certified():
    res, _ = _search(lambda a: 0.5, alphas=(1, 2, 4))
    assert res.alpha == 4 and res.bracket == (4.0, math.inf) and len(res.history) == 1


def test_no_alpha_reaches_the_target_lists_the_evidence():
    with pytest.raises(SynthesisError, match=r"no bandwidth factor alpha .* 0.25: NOT_CERTIFIED 1\.500"):
        _search(lambda a: 1.5, alphas=(0.25, 1, 4))


def test_a_floor_above_the_target_everywhere_runs_no_synthesis_and_says_so():
    with pytest.raises(SynthesisError, match=r"excludes every factor \(no synthesis ran\); alpha: mu = 4: >= 2\.000"):
        _search(lambda a: pytest.fail("no synthesis may run"), alphas=(1, 4), floor=lambda a, h: 2.0)


def test_failed_syntheses_count_as_not_certified():
    def mu(a):
        if a > 2:
            raise SynthesisError("infeasible")
        return 0.9

    res, _ = _search(mu, alphas=(1, 2, 4), rtol=0.1)
    assert 2 <= res.alpha < 4 and (4.0, math.inf) in [(a, m) for a, m in res.history]


def test_bad_arguments():
    with pytest.raises(PolyrobError, match="alphas"):
        _search(lambda a: 0.5, alphas=(0, 1))
    with pytest.raises(PolyrobError, match="unknown weight hyperparameter"):
        scaled_hyperparameters(2.0, scale=("omega_x",))


def test_a_grid_only_certificate_does_not_count():
    """mu < 1 on the grid but not proved between its points (GRID_ONLY) is not a certified factor."""

    def synthesize(P, K0):
        # every factor has a grid peak 0.9; only alpha <= 2 is proved at every frequency
        return _result(0.9, f"K({P.alpha:g})", "CERTIFIED" if P.alpha <= 2 else "GRID_ONLY")

    res = max_bandwidth_scaling(
        None, synthesize=synthesize, plant=lambda a, h: SimpleNamespace(alpha=a), progress=False, rtol=0.01
    )
    assert 2 <= res.alpha < 2.02 and res.result.certificate.certified
    assert all(math.isinf(mu) for a, mu in res.history if a > 2)


def test_a_search_time_limit_keeps_the_best_factor_so_far_and_says_so(monkeypatch):
    """No new factor starts after the limit: the largest certified one found stands, the result says why the
    search ended; none certified before the limit is a SynthesisError naming the limit."""
    from types import SimpleNamespace

    import polyrob.synthesis.bandwidth as bandwidth
    from polyrob.analysis.certificate import Certificate, Scope, decide_gain
    from polyrob.errors import SynthesisError
    from polyrob.synthesis.bandwidth import max_bandwidth_scaling

    clock = [0.0]  # a synthesis takes 1 s of this clock: the test does not depend on the machine's speed
    monkeypatch.setattr(bandwidth, "time", SimpleNamespace(perf_counter=lambda: clock[0]))

    def synthesis(P, K0):  # certified mu < 1 up to alpha = 4.8
        clock[0] += 1.0
        mu = 0.5 * P.alpha / 4 + 0.4
        cert = Certificate(decide_gain(True, mu, True)[0], mu, mu, 0.0, None, Scope())
        return SimpleNamespace(certificate=cert, controller=None, order=0)

    plant = lambda a, h: SimpleNamespace(alpha=a)  # noqa: E731
    full = max_bandwidth_scaling(None, synthesize=synthesis, plant=plant, progress=False)
    assert full.stopped_by == "" and full.bracket[1] / full.bracket[0] - 1 <= 0.05 and len(full.history) == 8
    clock[0] = 0.0
    cut = max_bandwidth_scaling(None, synthesize=synthesis, plant=plant, progress=False, search_time_limit=5.5)
    # 32, 16, 8 fail, 4 certifies, 5.66 fails, 4.76 certifies: then 5.5 s have passed
    assert len(cut.history) == 6 and cut.alpha == pytest.approx(4.757, rel=1e-3) and cut.peak_mu < 1
    assert cut.bracket[1] / cut.bracket[0] - 1 > 0.05
    assert "time limit of 5.5 s you set, before alpha = 5.187" in cut.stopped_by
    assert cut.summary()["stopped_by"] == cut.stopped_by
    clock[0] = 0.0
    with pytest.raises(SynthesisError, match="none certifies before the search's time limit of 2.5 s"):
        max_bandwidth_scaling(None, synthesize=synthesis, plant=plant, progress=False, search_time_limit=2.5)


def test_a_judge_ranks_the_factors_by_another_certificate():
    """The moving-robot search: each factor's controller judged by a second, stricter certificate."""
    judged = []

    def judge(P, result):  # stricter: mu + alpha / 10 (e.g. the robot in motion)
        judged.append(P.alpha)
        return _result(result.peak_mu + P.alpha / 10, result.controller).certificate

    res, calls = _search(lambda a: 0.5, alphas=(1, 2, 4, 8), rtol=0.01, judge=judge)
    assert judged == [a for a, _ in calls]
    assert 4 < res.alpha < 5 <= res.bracket[1] <= res.alpha * 1.01  # 0.5 + alpha / 10 < 1: alpha < 5
    assert [mu for _, mu in res.history][:2] == [math.inf, pytest.approx(0.9)]


def test_the_scan_stops_once_the_failed_factors_figures_grow_as_the_factor_falls():
    # mu = 1 + 1/alpha: 1.03 at 32, 1.06 at 16, 1.125 at 8 -- two rises in a row, so 4 and below are not tried
    with pytest.raises(SynthesisError, match=r"stop rule, before alpha = 4: the mu figures grew .*1\.12 at 8") as err:
        _search(lambda a: 1 + 1 / a)
    assert "none certifies before the scan's stop rule" in str(err.value)
    _, calls = _search(lambda a: 1 + 1 / a if a > 0.5 else 0.9, stop_after_rises=0)
    assert [a for a, _ in calls][:3] == [32, 16, 8] and 0.5 in [a for a, _ in calls]


def test_the_stop_rule_reads_a_screen_figure_and_keeps_a_minimum_that_certifies():
    def mu(a):
        if a > 8:  # a PID screen: its coarse-grid figure, no certificate
            exc = SynthesisError("screened")
            exc.figure = 1 + 1 / a
            raise exc
        return 0.8 if a <= 8 else 2.0

    # the figures 1.03, 1.06 rose once only before 8 certified: no stop
    res, calls = _search(mu, rtol=0.5)
    assert res.alpha == 8 and [a for a, _ in calls][:3] == [32, 16, 8]
    with pytest.raises(SynthesisError, match=r"32: synthesis failed \(screen 1\.031\).* 8: NOT_CERTIFIED 3\.000$"):
        _search(lambda a: mu(a) if a > 8 else 3.0)


def test_the_whole_job_s_progress_moves_with_each_factor_and_ends_near_the_stage_s_end():
    """Before: the search reported nothing, so `synth ARM --max-bandwidth` sat at "25 % of the job" for its
    whole stage while its estimate of the time left grew with the time elapsed (37 min "left" after 12)."""
    import io

    from polyrob.progress import JobProgress, report

    job = JobProgress(["bounds", "largest bandwidth"], stream=io.StringIO(), clock=lambda: 0.0)
    job.start()
    job._stop.set()  # no ticking thread: the test reads the shares itself
    shares = []  # (before, halfway) of each synthesis: the stage's share when it starts and after its own report

    def synthesize(P, K0):
        before = job.share
        report(1, 2)  # the synthesis's own loop, halfway: inside this factor's part of the stage
        shares.append((before, job.share))
        return _result(1 + (P.alpha - 3) * (P.alpha - 0.5) / 10, f"K({P.alpha:g})")

    try:
        job.begin(2, "largest bandwidth factor")
        res = max_bandwidth_scaling(
            None, synthesize=synthesize, plant=lambda a, h: SimpleNamespace(alpha=a, h=h), progress=False
        )
        end = job.share
    finally:
        job.stop()
    assert len(shares) == len(res.history) >= 5
    starts = [b for b, _ in shares]
    assert starts[0] == 0.0 and all(b1 > b0 for b0, b1 in zip(starts, starts[1:]))  # every factor moves it
    # a synthesis's own report stays inside its factor's part: below where the next factor starts
    assert all(b0 < h < b1 for (b0, h), b1 in zip(shares, starts[1:]))
    assert end >= 0.9  # the search's last factor leaves the stage (nearly) done


def test_a_factor_whose_synthesis_fails_counts_when_a_nearby_controller_certifies_on_it():
    """A factor's own synthesis can miss a controller that exists: ur5 with 14-bit encoders stopped at 5.42 when
    the PID re-tuned for 5.66 failed its screen, while 5.42's controller has grid mu 0.758 on 5.66's weights.
    With carry_over the nearest certified factor's controller is certified on the failing factor's plant."""
    carried = []

    def carry(P, result):
        carried.append((P.alpha, result.controller))
        return _result(0.9 if P.alpha <= 6.0 else 1.2, result.controller)  # its own certificate on P

    def mu_of_alpha(a):
        return 0.8 if a <= 4.0 else 1.5  # the factor's own synthesis fails above 4

    res, calls = _search(mu_of_alpha, alphas=(2.0, 4.0, 8.0), rtol=0.01, carry_over=carry)
    assert 5.9 < res.alpha <= 6.0 and res.result.controller == "K(4)"  # 4's controller, certified up to 6
    assert res.bracket[1] <= 6.0 * 1.01
    # 8 was tried first, with no certified factor yet to lend a controller: tried again once 4 certified
    assert all(K == "K(4)" for a, K in carried) and [a for a, _ in carried[:2]] == [8.0, pytest.approx(32**0.5)]
    # without it (a given synthesis: off by default) the search stops at the synthesis' own limit
    res_off, _ = _search(mu_of_alpha, alphas=(2.0, 4.0, 8.0), rtol=0.01)
    assert 3.96 < res_off.alpha <= 4.0
    # the scan's top tried again and certified with the lent controller: the search goes on above it
    res_top, _ = _search(mu_of_alpha, alphas=(2.0, 4.0, 5.0), rtol=0.01, carry_over=carry)
    assert res_top.alpha == 5.0 and res_top.bracket[1] == math.inf and res_top.result.controller == "K(4)"


def test_carry_over_certifies_the_controller_on_the_failing_factor_s_plant():
    """The default carry-over is the controller's own certificate (certify_loop) on a real plant."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    import numpy as np
    from test_weights_limits import _pd, _plant, one_joint

    from polyrob.analysis.certificate import certify_loop
    from polyrob.fleet.autoweights import limit_hyperparameters
    from polyrob.pipeline import default_hyperparameters
    from polyrob.synthesis.bandwidth import certified_on

    robot, dom, unc = one_joint()
    M = float(robot.mass_matrix(np.zeros(1))[0, 0])
    h0 = default_hyperparameters(1, limit_hyperparameters(robot, dom).hyperparameters())
    P16 = _plant(unc)(16.0, scaled_hyperparameters(16.0, h0))
    K8 = _pd(M, 8.0)
    out = certified_on(P16, SimpleNamespace(controller=K8, structure="pd"))
    direct = certify_loop(P16, K8, sweep_unstable=False)
    assert out.certificate.status == direct.status and out.certificate.bound == pytest.approx(direct.bound, rel=1e-9)
    assert np.allclose(out.controller(1j), K8(1j))
    assert out.info["method"].startswith("carried over")
