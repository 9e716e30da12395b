"""PLDI files: a full round trip, one stem for both files, the format check, locked joints."""

from __future__ import annotations

import dataclasses
import functools
import json

import numpy as np
import pytest

from polyrob import PLDI, Domain, bound_pldi, load_robot
from polyrob.errors import BoundsError


@functools.cache
def small_pldi():
    """planar_2r with joint2 locked: a one-joint arm, bounded in a fraction of a second."""
    robot = load_robot("planar_2r", lock=["joint2"])
    return robot, bound_pldi(robot, Domain.from_robot(robot), samples=64, screen=0, coverage=200, progress=False)


def assert_same(a, b, where=""):
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=where)
    elif dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), where
    elif isinstance(a, dict):
        assert set(a) == set(b), where
        for key in a:
            assert_same(a[key], b[key], f"{where}[{key}]")
    else:
        assert a == b, where


def test_every_field_survives_a_round_trip(tmp_path):
    _, pldi = small_pldi()
    pldi.save(tmp_path / "p.json")
    back = PLDI.load(tmp_path / "p.json")
    for f in dataclasses.fields(PLDI):
        if f.name == "domain":
            assert back.domain.to_dict() == pldi.domain.to_dict()
            continue
        if f.name == "source_robot":  # the live robot object, not saved: the file's PLDI loads it again
            assert pldi.source_robot is not None and back.source_robot is None
            assert (back.robot.name, back.robot.joint_names) == (pldi.robot.name, pldi.robot.joint_names)
            continue
        assert_same(getattr(pldi, f.name), getattr(back, f.name), f.name)


@pytest.mark.parametrize("given", ["q.npz", "q.json", "q"])
def test_both_files_come_from_one_stem_whatever_the_suffix(tmp_path, given):
    _, pldi = small_pldi()
    paths = pldi.save(tmp_path / given)
    assert paths == (tmp_path / "q.json", tmp_path / "q.npz")
    assert json.loads(paths[0].read_text())["format"] == "polyrob.pldi/1"
    np.load(paths[1]).close()  # the npz is an npz, not JSON written over it
    for name in ("q.json", "q.npz", "q"):
        assert PLDI.load(tmp_path / name).entries == pldi.entries


def test_another_format_version_is_refused(tmp_path):
    _, pldi = small_pldi()
    path, _ = pldi.save(tmp_path / "p.json")
    meta = json.loads(path.read_text())
    meta["format"] = "polyrob.pldi/2"
    path.write_text(json.dumps(meta))
    with pytest.raises(BoundsError, match=r"format 'polyrob.pldi/2' is not supported .* 'polyrob.pldi/1'"):
        PLDI.load(path)
    del meta["format"]
    path.write_text(json.dumps(meta))
    with pytest.raises(BoundsError, match="not a PLDI file written by polyrob"):
        PLDI.load(path)


def test_a_missing_array_file_is_one_error(tmp_path):
    _, pldi = small_pldi()
    path, npz = pldi.save(tmp_path / "p.json")
    npz.unlink()
    with pytest.raises(BoundsError, match="not a PLDI file"):
        PLDI.load(path)


def test_the_reloaded_robot_has_the_same_joints_locked(tmp_path):
    robot, pldi = small_pldi()
    assert robot.joint_names == ("joint1",)
    pldi.save(tmp_path / "p")
    again = PLDI.load(tmp_path / "p").robot
    assert again.joint_names == ("joint1",) and again.locked == ("joint2",)
    np.testing.assert_allclose(again.mass_matrix([0.3]), robot.mass_matrix([0.3]))
