"""One ``Controller`` value type: every form a controller arrives in, normalised in one place."""

from __future__ import annotations

import control
import numpy as np
import pytest

from polyrob.controller import Controller, as_controller_ss
from polyrob.errors import PolyrobError


def _ss():
    return control.ss([[-2.0]], [[1.0, 0.5]], [[3.0], [1.0]], [[0.1, 0.0], [0.0, 0.2]], inputs=["e1", "e2"])


def test_every_form_becomes_the_same_realisation():
    K = _ss()
    forms = [K, (K.A, K.B, K.C, K.D), Controller.of(K)]
    for form in forms:
        c = Controller.of(form, n_u=2, n_y=2)
        assert (c.order, c.n_u, c.n_y) == (1, 2, 2)
        for got, want in zip(c.matrices, (K.A, K.B, K.C, K.D)):
            np.testing.assert_array_equal(got, np.asarray(want))
    gain = Controller.of(np.array([[1.0, 2.0]]))
    assert (gain.order, gain.n_u, gain.n_y) == (0, 1, 2) and gain.system.nstates == 0


def test_a_transfer_function_is_realised_exactly_and_a_result_gives_its_controller():
    tf = control.tf([[[1.0, 2.0]]], [[[1.0, 10.0]]])
    c = Controller.of(tf)
    assert c.order == 1
    assert abs(complex(c.system(1j)) - complex(tf(1j))) < 1e-12

    class Result:  # what a synthesis result or a design carries
        controller = tf

    assert Controller.of(Result()).order == 1


def test_the_given_system_is_kept_and_a_controller_passes_through():
    K = _ss()
    assert as_controller_ss(K, 2, 2) is K  # its signal names stay
    c = Controller.of(K)
    assert Controller.of(c) is c and c.system is K


def test_bad_controllers_are_refused_with_what_to_change():
    with pytest.raises(PolyrobError, match="expected 2 measurements -> 1 controls"):
        Controller.of(_ss(), n_u=1, n_y=2)
    with pytest.raises(PolyrobError, match="discrete-time"):
        Controller.of(control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], dt=0.01))
    with pytest.raises(PolyrobError, match="must be a python-control LTI system or a number"):
        Controller.of("K.json")
    with pytest.raises(PolyrobError, match="non-finite"):
        Controller.of((np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[np.nan]]))


def test_the_time_varying_analysis_takes_a_controller_in_any_form():
    from polyrob.analysis.time_varying.vertices import controller_mats

    K = control.ss([[-1.0]], [[1.0]], [[2.0]], [[0.5]])
    want = controller_mats(K, 1)
    for form in ((K.A, K.B, K.C, K.D), Controller.of(K)):
        for got, ref in zip(controller_mats(form, 1), want):
            np.testing.assert_array_equal(got, ref)


# --------------------------------------------------------------------------- built once at the boundary


class _Box:
    """A one-parameter uncertain plant ``1 / (s + 1 - 0.5 δ)`` (what ``sample_stability`` and ``monte_carlo`` read)."""

    n_params, m = 1, 1

    def delta_samples(self, n=None, kind="uniform", seed=0, max_corners=None):
        return np.array([[-1.0], [1.0]]) if kind == "corners" else np.linspace(-1.0, 1.0, n)[:, None]

    def plant_at(self, delta, strict=True):
        return control.ss([[-1.0 + 0.5 * float(delta[0])]], [[1.0]], [[1.0]], [[0.0]])

    def nominal_system(self):
        return self.plant_at([0.0])


@pytest.fixture
def realisations(monkeypatch):
    """How often a python-control system is turned into a Controller (each normalisation of an LTI does it once)."""
    import polyrob.controller as module

    calls = []
    real = module.as_state_space
    monkeypatch.setattr(module, "as_state_space", lambda *a, **k: calls.append(1) or real(*a, **k))
    return calls


def test_sampled_stability_and_monte_carlo_normalise_the_controller_once(realisations):
    from polyrob.analysis.robust import sample_stability
    from polyrob.validate.monte_carlo import monte_carlo

    K = control.ss([[-3.0]], [[1.0]], [[2.0]], [[1.0]])
    s = sample_stability(_Box(), K, n=7, seed=0)
    assert (s.random_stable, s.corners, s.corners_stable) == (1.0, 2, 1.0)
    assert len(realisations) == 1  # not once per sample (7 + 2 corners)
    realisations.clear()
    mc = monte_carlo(_Box(), K, n=5, omega=np.logspace(-1, 1, 5), t=np.linspace(0.0, 1.0, 11))
    assert len(mc.omega) == 5 and len(realisations) == 1  # not once for the nominal and once per sample


def test_a_controller_file_and_a_synthesis_result_give_one_controller(tmp_path):
    from polyrob.io.controller import load_controller, load_controller_value, save_controller
    from polyrob.synthesis.result import MusynResult

    K = _ss()
    path = save_controller(K, tmp_path / "K.json")
    c = load_controller_value(path)
    assert isinstance(c, Controller) and (c.order, c.n_u, c.n_y) == (1, 2, 2)
    for got, want in zip(c.matrices, (K.A, K.B, K.C, K.D)):
        np.testing.assert_array_equal(got, np.asarray(want))
    tf_path = save_controller(control.tf([1.0, 2.0], [1.0, 10.0]), tmp_path / "K_tf.json")
    assert load_controller_value(tf_path).order == 1 and load_controller(tf_path).dt == 0

    r = MusynResult(K, "full", 1, 0.5, 0.4, 1.0, np.zeros(1), np.zeros(1), (), K, None, 1, 0.0)
    assert r.controller_value is r.controller_value  # built once
    assert r.controller_value.system is K and Controller.of(r.controller_value) is r.controller_value


def test_interior_functions_take_a_controller_as_it_is():
    from polyrob.fleet.results import controller_data, controller_system
    from polyrob.synthesis.fixed.loop import closed_loop_response
    from polyrob.validate.export_c import lowest_rate_of_controller

    P = control.ss([[0.0]], [[1.0, 1.0]], [[1.0], [1.0]], np.zeros((2, 2)))
    want = closed_loop_response(P, -2.0, [1.0, 2.0], n_u=1, n_y=1)  # 1/(s + 2)
    for form in (Controller.of(-2.0), (np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), [[-2.0]])):
        np.testing.assert_allclose(closed_loop_response(P, form, [1.0, 2.0], n_u=1, n_y=1), want, atol=1e-15)
    K = control.ss([[-40.0]], [[1.0]], [[1.0]], [[0.0]])
    assert lowest_rate_of_controller(Controller.of(K)) == lowest_rate_of_controller(K)
    assert lowest_rate_of_controller(Controller.of(K)).rate == pytest.approx(80.0 / np.pi)
    data = controller_data(Controller.of(K))
    assert data["type"] == "ss" and controller_system(data).A.tolist() == [[-40.0]]
