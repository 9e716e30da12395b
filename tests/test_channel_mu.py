"""Which weighted channel μ rests on (polyrob.synthesis.channel_mu) and the bandwidth search's stop line."""

from __future__ import annotations

import numpy as np
import pytest
from test_weights_limits import _pd, _plant, _stand_in, one_joint

from polyrob.analysis.mu.frequency import freqresp
from polyrob.errors import SynthesisError
from polyrob.fleet.autoweights import limit_hyperparameters
from polyrob.pipeline import default_hyperparameters
from polyrob.synthesis.bandwidth import max_bandwidth_scaling, scaled_hyperparameters
from polyrob.synthesis.channel_mu import DEFAULT_OMEGA, channel_mu, channel_words


@pytest.fixture(scope="module")
def joint():
    robot, dom, unc = one_joint()
    M = float(robot.mass_matrix(np.zeros(1))[0, 0])
    h = default_hyperparameters(1, limit_hyperparameters(robot, dom).hyperparameters())
    return M, unc, h


def _stacked_peak(P, K, labels) -> float:
    """max over the grid of sigma_max of the listed channels stacked: mu of one full block, computed directly."""
    w = DEFAULT_OMEGA
    G = freqresp(P.uncertain.nominal_system(), w)
    Kw = freqresp(K, w)
    S = np.linalg.inv(np.eye(1)[None] + G @ Kw)
    loops = {"W_S e": (P.W_S, S), "W_T y": (P.W_T, G @ Kw @ S), "W_KS u": (P.W_KS, Kw @ S)}
    rows = [freqresp(loops[lab][0], w) @ loops[lab][1] for lab in labels]
    return float(np.linalg.norm(np.concatenate(rows, axis=1), ord=2, axis=(1, 2)).max())


def test_without_uncertainty_each_figure_is_the_norm_of_the_channels_left(joint):
    """One joint with an exact model: mu of the single performance block is sigma_max of the channels stacked."""
    M, unc, h0 = joint
    P = _plant(unc)(13.0, scaled_hyperparameters(13.0, h0, ("omega_b", "omega_bt")))
    K = _pd(M, 13.0)
    f = channel_mu(P, K)
    assert f["all"] == pytest.approx(_stacked_peak(P, K, ["W_S e", "W_T y", "W_KS u"]), rel=1e-3)
    assert f["W_KS u"] == pytest.approx(_stacked_peak(P, K, ["W_S e", "W_T y"]), rel=1e-3)
    assert f["W_S e"] == pytest.approx(_stacked_peak(P, K, ["W_T y", "W_KS u"]), rel=1e-3)
    assert f["none"] == 0.0  # nothing uncertain: nothing to destabilise
    # the noise channel binds there: 1.10 with it, 0.69 without it
    assert f["all"] > 1.0 > f["W_KS u"]
    assert channel_words(f).startswith("encoder noise against the effort limit (W_u K S W_n) binds: grid mu 1.1")


def test_an_unstable_nominal_loop_has_no_share():
    import control

    from polyrob.synthesis.channel_mu import channel_mu as cm

    robot, dom, unc = one_joint()
    h = default_hyperparameters(1, limit_hyperparameters(robot, dom).hyperparameters())
    P = _plant(unc)(1.0, h)
    f = cm(P, control.ss([], [], [], [[-1.0]]))  # positive feedback on a double integrator
    assert all(v == np.inf for v in f.values())
    assert channel_words(f).startswith("the nominal loop is not stable")


def test_the_words_name_the_uncertainty_or_no_single_channel():
    assert channel_words({"all": 1.4, "W_S e": 1.3, "W_T y": 1.35, "none": 1.2}).startswith(
        "the uncertainty itself: robust stability alone has grid mu 1.2 >= 1"
    )
    words = channel_words({"all": 1.4, "W_S e": 1.1, "W_T y": 1.35, "none": 0.6})
    assert words.startswith("no single channel: grid mu 1.4 with every channel; the largest drop without tracking")
    assert channel_words({"all": 0.8, "W_S e": 0.7, "none": 0.2}, {"W_S e": "the error"}).startswith(
        "no single channel: grid mu 0.8 with every channel; the largest drop without the error, to 0.7"
    )


def test_a_failed_synthesis_is_diagnosed_on_its_own_weights_with_the_certified_controller(joint):
    """Before: the nominal-peak rule on the certified factor's own weights (alpha = 8's), not the failing one's."""
    M, unc, h0 = joint
    stand_in = _stand_in(M, 1.0)

    def synthesize(P, K0):
        if P.info["alpha"] > 10.0:
            raise SynthesisError("no controller at this factor (a stand-in)")
        return stand_in(P, K0)

    res = max_bandwidth_scaling(
        unc, h0, synthesize=synthesize, plant=_plant(unc), alphas=(8.0, 16.0), rtol=1.0, progress=False
    )
    assert (res.alpha, res.bracket[1]) == (8.0, 16.0)
    on_failing = channel_words(
        channel_mu(_plant(unc)(16.0, scaled_hyperparameters(16.0, h0, ("omega_b", "omega_bt"))), _pd(M, 8.0))
    )
    on_own = channel_words(
        channel_mu(_plant(unc)(8.0, scaled_hyperparameters(8.0, h0, ("omega_b", "omega_bt"))), _pd(M, 8.0))
    )
    assert on_failing != on_own
    assert res.bound_hit == f"alpha = 16 failed to synthesise; alpha = 8's controller on its weights: {on_failing}"
