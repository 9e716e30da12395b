"""Controller files (JSON ss/tf, MATLAB .mat) and output paths: clear errors, no half-written files."""

from __future__ import annotations

import json

import control
import numpy as np
import pytest

from polyrob.errors import ArgumentError, ControllerFileError
from polyrob.io.controller import FORMAT, load_controller, read_controller_file, save_controller
from polyrob.io.paths import check_output_path, pair_paths

K_SS = control.ss([[-1.0, 0.5], [0.0, -3.0]], [[1.0], [2.0]], [[1.0, -1.0]], [[0.25]])


def _response(K, w=(0.1, 1.0, 10.0)):
    return np.array([complex(control.evalfr(K, 1j * x)) for x in w])


def test_round_trip_keeps_the_response_and_the_info(tmp_path):
    info = {"robot": "paper_2r", "weights": {"omega_b": [0.5, 0.1]}}
    path = save_controller(K_SS, tmp_path / "K.json", certificate={"peak_mu_upper": 0.9}, info=info)
    np.testing.assert_allclose(_response(load_controller(path)), _response(K_SS), rtol=1e-12)
    doc = read_controller_file(path)
    assert doc["format"] == FORMAT and doc["info"] == info and doc["certificate"]["peak_mu_upper"] == 0.9


@pytest.mark.parametrize(
    "fmt, needle",
    [
        ("polyrob.controller/2", "version '2'"),
        ("polyrob.pldi/1", "not a controller file"),
        ("xyz", "not a controller file"),
    ],
)
def test_other_formats_and_versions_are_refused(tmp_path, fmt, needle):
    path = tmp_path / "K.json"
    path.write_text(json.dumps({"format": fmt, "type": "ss", "A": [[-1]], "B": [[1]], "C": [[1]], "D": [[0]]}))
    with pytest.raises(ControllerFileError, match=needle):
        load_controller(path)


def test_hand_written_transfer_function_without_format(tmp_path):
    path = tmp_path / "K.json"
    path.write_text(json.dumps({"type": "tf", "num": [[[2.0]]], "den": [[[1.0, 4.0]]]}))
    K = load_controller(path)
    assert complex(control.evalfr(K, 0)) == pytest.approx(0.5)


@pytest.mark.parametrize("bad", ["NaN", "Infinity"])
def test_non_finite_entries_are_one_clear_error(tmp_path, bad):
    """Before: numpy's LinAlgError from deep inside the realisation."""
    path = tmp_path / "K.json"
    path.write_text(f'{{"type": "ss", "A": [[-1, {bad}], [0, -2]], "B": [[1], [1]], "C": [[1, 0]], "D": [[0]]}}')
    with pytest.raises(ControllerFileError, match="A has 1 non-finite"):
        load_controller(path)
    path.write_text(f'{{"type": "tf", "num": [[[{bad}]]], "den": [[[1, 1]]]}}')
    with pytest.raises(ControllerFileError, match="num has 1 non-finite"):
        load_controller(path)


def test_matlab_mat_file(tmp_path):
    from scipy.io import savemat

    path = tmp_path / "K.mat"
    savemat(path, {k: np.asarray(getattr(K_SS, k)) for k in "ABCD"})
    np.testing.assert_allclose(_response(load_controller(path)), _response(K_SS), rtol=1e-12)
    savemat(path, {k: np.asarray(getattr(K_SS, k)) for k in "ABC"})
    with pytest.raises(ControllerFileError, match="missing D"):
        load_controller(path)
    (tmp_path / "junk.mat").write_text("not a mat file")
    with pytest.raises(ControllerFileError, match="not a MATLAB"):
        load_controller(tmp_path / "junk.mat")


def test_pair_paths_share_one_stem():
    for given in ("out/q", "out/q.json", "out/q.npz", "out/q.NPZ"):
        assert [str(p) for p in pair_paths(given)] == ["out/q.json", "out/q.npz"]
    assert [p.name for p in pair_paths("q.v2")] == ["q.v2.json", "q.v2.npz"]


def test_output_paths_refused_before_the_work(tmp_path):
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    for bad, needle in [
        (tmp_path, "is a directory"),
        (f"{tmp_path}/", "is a directory"),
        ("/proc/polyrob.json", "/proc"),
        ("/sys/x/polyrob.json", "/sys"),
        (afile / "out.json", "is a file, not a directory"),
    ]:
        with pytest.raises(ArgumentError, match=needle) as info:
            check_output_path(bad, "-o")
        assert str(info.value).startswith("-o ")
    ok = tmp_path / "new" / "deeper" / "K.json"
    assert check_output_path(ok) == ok and not (tmp_path / "new").exists()  # nothing created
