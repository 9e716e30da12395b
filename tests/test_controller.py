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
