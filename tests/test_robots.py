"""Loading robots: sources, reduction to the serial chain, refusals."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from conftest import BAD_URDFS, cached_robot, urdf_text

from polyrob import Robot, RobotError, load_robot
from polyrob.model.robots import available_robots, example_robot_data_dir

A1, A2, A3 = 48.125, 13.125, 6.25


def paper_mass_matrix(q2):
    c = np.cos(q2)
    return np.array([[A1 + 2 * A3 * c, A2 + A3 * c], [A2 + A3 * c, A2]])


def test_planar_2r_mass_matrix_and_B_match_the_paper():
    robot = cached_robot("planar_2r")
    rng = np.random.default_rng(0)
    for q in rng.uniform(-np.pi, np.pi, size=(100, 2)):
        M = robot.mass_matrix(q)
        np.testing.assert_allclose(M, paper_mass_matrix(q[1]), rtol=0, atol=1e-9)
        _, B = robot.jacobians(q, [0.0, 0.0], [0.0, 0.0])
        np.testing.assert_allclose(B[2:], np.linalg.inv(paper_mass_matrix(q[1])), rtol=0, atol=1e-9)
        assert np.all(B[:2] == 0)


def test_planar_2r_B_spans_the_paper_intervals():
    robot = cached_robot("planar_2r")
    q2 = np.linspace(-np.pi, np.pi, 20001)
    q = np.column_stack([np.zeros_like(q2), q2])
    _, B = robot.jacobians_batch(q, np.zeros_like(q), np.zeros_like(q))
    b = B[:, 2:, :]
    lo, hi = b.min(axis=0), b.max(axis=0)
    # The paper prints 3-4 significant digits: b31, b32 = b41, b42.
    assert (round(lo[0, 0], 4), round(hi[0, 0], 4)) == (0.0286, 0.0312)
    assert (round(lo[0, 1], 4), round(hi[0, 1], 4)) == (-0.0461, -0.0164)
    assert (round(lo[1, 0], 4), round(hi[1, 0], 4)) == (-0.0461, -0.0164)
    assert (round(lo[1, 1], 4), round(hi[1, 1], 3)) == (0.0848, 0.144)


def test_planar_2r_has_no_gravity_and_no_damping():
    robot = cached_robot("planar_2r")
    acc = robot.acceleration([0.3, -1.2], [0.0, 0.0], [0.0, 0.0])
    np.testing.assert_allclose(acc, 0.0, atol=1e-12)
    assert np.all(robot.damping == 0)
    np.testing.assert_allclose(robot.position_lower, -np.pi)
    np.testing.assert_allclose(robot.position_upper, np.pi)


@pytest.mark.parametrize(
    "name, m, locked",
    [
        ("panda", 7, ("panda_finger_joint1", "panda_finger_joint2")),
        ("ur5", 6, ()),
        ("z1", 6, ("jointGripper",)),
        ("so100", 5, ("gripper",)),
        ("finger_edu", 3, ()),
        ("double_pendulum", 2, ()),
        ("TwoDofs", 2, ()),
    ],
)
def test_example_robot_data_arms_reduce_to_their_serial_joints(name, m, locked):
    robot = cached_robot(name)
    assert isinstance(robot, Robot)
    assert robot.m == m
    assert robot.locked == locked
    assert robot.model.nv == m
    assert all(robot.model.parents[i] == i - 1 for i in range(1, robot.model.njoints))


def test_kinova_continuous_joints_use_the_angle():
    robot = cached_robot("kinova")
    assert robot.joint_kinds.count("continuous") == 3
    assert robot.model.nq == 9 and robot.m == 6
    q = np.array([0.4, 2.0, 1.0, -0.7, 1.5, 3.0])
    config = robot.configuration(q)
    i = robot.model.joints[1].idx_q
    np.testing.assert_allclose(config[i : i + 2], [np.cos(0.4), np.sin(0.4)])
    # a full turn of a continuous joint is the same configuration
    q2 = q.copy()
    q2[0] += 2 * np.pi
    np.testing.assert_allclose(robot.mass_matrix(q2), robot.mass_matrix(q), atol=1e-12)


def test_lock_by_name_and_unknown_joint():
    robot = load_robot("panda", lock=["panda_joint7", "panda_finger_joint1", "panda_finger_joint2"])
    assert robot.m == 6 and "panda_joint7" not in robot.joint_names
    with pytest.raises(RobotError, match="cannot lock nope"):
        load_robot("panda", lock=["nope"])
    # lock=[] keeps finger 1 (prismatic), which finger 2 mimics: refused with the lock that runs
    with pytest.raises(RobotError, match="give --lock panda_finger_joint2 to run on the robot with"):
        load_robot("panda", lock=[])
    robot = load_robot("panda", lock=["panda_finger_joint2"])
    assert robot.m == 8 and robot.joint_kinds[-1] == "prismatic"
    assert robot.locked == ("panda_finger_joint2",)


def test_load_robot_from_a_path(tmp_path):
    erd = example_robot_data_dir()
    path = erd / "ur_description/urdf/ur3_robot.urdf"
    robot = load_robot(str(path))
    assert robot.name == "ur3_robot" and robot.m == 6


@pytest.mark.parametrize(
    "kind, message",
    [
        ("malformed", "malformed URDF"),
        ("floating", "floating"),
        ("tree", "branches off"),
        ("no_joint", "no movable joint"),
        ("not_urdf", "not a URDF"),
    ],
)
def test_bad_urdfs_are_refused_with_the_file_named(write_urdf, kind, message):
    path = write_urdf(BAD_URDFS[kind], f"{kind}.urdf")
    with pytest.raises(RobotError, match=message) as info:
        load_robot(str(path))
    assert str(path) in str(info.value)


def test_missing_file_and_unknown_name():
    with pytest.raises(RobotError, match="no such URDF file"):
        load_robot("/nonexistent/robot.urdf")
    with pytest.raises(RobotError, match="unknown robot 'robotron'"):
        load_robot("robotron")


def test_legged_robot_is_refused_as_a_tree():
    with pytest.raises(RobotError, match="serial chain"):
        load_robot("solo12")


def test_available_robots_lists_the_bundled_and_shipped_arms():
    names = dict(available_robots())
    for name in ("planar_2r", "paper_2r", "panda", "ur5", "kinova", "double_pendulum", "finger_edu"):
        assert name in names


# --------------------------------------------------------------------------- physical data

ONE_LINK = """<?xml version="1.0"?><robot name="bad">
<link name="base"/>
<link name="arm"><inertial><origin xyz="0.5 0 0"/><mass value="{mass}"/>
<inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
<limit lower="-1" upper="1" velocity="1" effort="1"/></joint></robot>"""


def one_link(mass=1.0, ixx=0.1, iyy=0.1, izz=0.1):
    return ONE_LINK.format(mass=mass, ixx=ixx, iyy=iyy, izz=izz)


@pytest.mark.parametrize(
    "text, message",
    [
        (one_link(mass=0.0, ixx=0.0, iyy=0.0, izz=0.0), r"joint 'j1' moves no inertia .* \(arm\)"),
        (one_link(izz=-10.0), r"link 'arm' has an inertia that is not positive semidefinite \(principal moments -10"),
        (one_link(mass=-2.0), r"link 'arm' has mass -2"),
        (
            one_link(ixx=0.1, iyy=0.1, izz=0.5),
            r"link 'arm' has principal moments of inertia 0.1, 0.1, 0.5 that violate",
        ),
        (one_link(mass=0.0), r"link 'arm' has mass 0 but a non-zero inertia"),
    ],
)
def test_unphysical_inertial_data_is_refused_naming_the_link(write_urdf, text, message):
    path = write_urdf(text, "bad.urdf")
    with pytest.raises(RobotError, match=message) as info:
        load_robot(str(path))
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_a_physical_one_link_arm_loads_with_the_analytic_inertia(write_urdf):
    robot = load_robot(str(write_urdf(one_link(), "good.urdf")))
    # about the joint axis: izz + m r^2 = 0.1 + 1 * 0.5^2
    assert robot.mass_matrix([0.3])[0, 0] == pytest.approx(0.35, rel=1e-12)


def test_massless_frames_are_accepted():
    # ur5's ee_link, base and tool0 carry mass 0 and inertia 0
    assert cached_robot("ur5").m == 6


# --------------------------------------------------------------------------- names


def test_available_robot_names_are_unique_and_each_reachable():
    pairs = available_robots()
    names = [n for n, _ in pairs]
    assert len(names) == len(set(names))
    anymals = [n for n in names if n == "anymal" or n.endswith("/anymal")]
    assert len(anymals) == 2
    from polyrob.model.robots import resolve_urdf

    paths = {resolve_urdf(n) for n in anymals}
    assert len(paths) == 2  # the qualified name reaches the second file
    with pytest.raises(RobotError, match="serial chain|floating"):
        load_robot(anymals[1])


# a new user's trial: xacro files, missing attributes in words, mimic joints noted

_XACRO_NS = 'xmlns:xacro="http://www.ros.org/wiki/xacro"'
_INERTIAL = '<inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>'
#: A xacro file Pinocchio's parser (urdfdom) complains about on stderr: its links come from a macro.
XACRO_ARM = f"""<?xml version="1.0"?>
<robot name="arm" {_XACRO_NS}>
  <xacro:macro name="body" params="name"><link name="${{name}}">{_INERTIAL}</link></xacro:macro>
  <xacro:body name="base"/>
  <xacro:body name="l1"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
</robot>"""


@pytest.mark.parametrize(
    "name, expanded", [("arm.urdf.xacro", "arm.urdf"), ("arm.xacro", "arm.urdf"), ("arm.urdf", "arm_expanded.urdf")]
)
def test_a_xacro_file_is_refused_before_any_parser_prints(write_urdf, capfd, name, expanded):
    path = write_urdf(XACRO_ARM, name)
    with pytest.raises(RobotError) as info:
        load_robot(str(path))
    assert (
        str(info.value)
        == f"{path}: a xacro file must be expanded to URDF first: xacro {path} > {path.parent / expanded}"
    )
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # nothing from urdfdom's C++ parser


def test_an_expanded_urdf_that_keeps_the_xacro_namespace_loads(write_urdf):
    # xacro keeps xmlns:xacro on <robot> (panda.urdf of example-robot-data does): not a xacro file
    text = urdf_text(["base", "l1"], [("j1", "revolute", "base", "l1")]).replace(
        '<robot name="test">', f'<robot name="test" {_XACRO_NS}>'
    )
    assert load_robot(str(write_urdf(text))).m == 1


_CHAIN = urdf_text(["base", "l1", "l2"], [("j1", "revolute", "base", "l1"), ("j2", "revolute", "l1", "l2")])


@pytest.mark.parametrize(
    "old, new, message",
    [
        ('<joint name="j2"', "<joint", "a <joint> without a name attribute (the 2nd <joint>)"),
        ('<link name="l2">', "<link>", "a <link> without a name attribute (the 3rd <link>)"),
        ('<robot name="test">', "<robot>", "the <robot> element has no name attribute"),
        ('name="j2" type="revolute"', 'name="j2"', "joint 'j2' has no type attribute"),
        ('<parent link="l1"/>', "<parent/>", "joint 'j2': <parent> has no link attribute"),
        ('<child link="l2"/>', '<child link="l9"/>', "joint 'j2': child link 'l9' is not a <link> of the file"),
        ('velocity="1" effort="1"/></joint></robot>', 'velocity="1"/></joint></robot>', "joint 'j2': <limit> has no effort attribute"),
        ('<axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint></robot>',
         '<axis xyz="0 0 1"/></joint></robot>', "joint 'j2' is revolute but has no <limit>"),
        ('<axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint></robot>',
         '<axis xyz="0 0 1"/><mimic/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint></robot>',
         "joint 'j2': <mimic> has no joint attribute"),
    ],
)  # fmt: skip
def test_a_missing_attribute_is_named_in_words(write_urdf, capfd, old, new, message):
    assert old in _CHAIN
    path = write_urdf(_CHAIN.replace(old, new))
    with pytest.raises(RobotError) as info:
        load_robot(str(path))
    assert str(info.value).startswith(f"{path}: malformed URDF: {message}")
    assert "KeyError" not in str(info.value)
    assert capfd.readouterr().err == ""  # nothing from urdfdom's C++ parser


_MIMIC = urdf_text(
    ["base", "l1", "l2", "l3"],
    [("j1", "revolute", "base", "l1"), ("j2", "revolute", "l1", "l2"), ("j3", "revolute", "l2", "l3")],
).replace(
    '<joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><axis xyz="0 0 1"/>',
    '<joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><axis xyz="0 0 1"/>'
    '<mimic joint="j2" multiplier="-1" offset="0.5"/>',
)


class _Records(logging.Handler):
    """The records of the ``polyrob.model.urdf`` logger (caplog misses them once a CLI test
    has stopped the ``polyrob`` logger's propagation to the root)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.records = []

    def emit(self, record):
        self.records.append(record)


@pytest.fixture
def urdf_log():
    handler, log = _Records(), logging.getLogger("polyrob.model.urdf")
    log.addHandler(handler)
    yield handler
    log.removeHandler(handler)


def test_a_mimic_joint_of_an_actuated_joint_is_refused_with_the_lock_that_runs(write_urdf, urdf_log, capfd):
    """Pinocchio's derivatives refuse mimic joints: no silent lock (another robot), one line with the option."""
    path = write_urdf(_MIMIC)
    with pytest.raises(RobotError) as info:
        load_robot(str(path))
    assert str(info.value) == (
        f"{path}: joint 'j3' mimics actuated joint 'j2' (q = -1 * q_j2 + 0.5) and polyrob cannot model mimic "
        "joints: give --lock j3 to run on the robot with 'j3' fixed at its neutral position (or --lock j3,j2 to fix both)"
    )
    assert capfd.readouterr().err == ""
    # locked as asked: named in the robot's notes (every result), no warning
    robot = load_robot(str(path), lock=["j3"])
    assert robot.joint_names == ("j1", "j2") and robot.locked == ("j3",)
    (note,) = robot.notes
    assert note == (
        "mimic joint 'j3' follows actuated joint 'j2' (q = -1 * q_j2 + 0.5) in the URDF; it is locked as asked "
        "(lock/--lock) at q = 0, so every result is for the robot with 'j3' fixed while 'j2' moves"
    )
    assert not urdf_log.records
    described = robot.describe()
    assert described["locked"] == ["j3"] and described["notes"] == [note]
    assert load_robot(str(path), lock=["j2", "j3"]).joint_names == ("j1",)


def test_an_inertial_without_inertia_is_refused(write_urdf, capfd):
    """urdfdom reads it as a point mass and says so on stderr only: refused in one line naming the link."""
    text = urdf_text(["base", "l1", "l2"], [("j1", "revolute", "base", "l1"), ("j2", "revolute", "l1", "l2")])
    link = '<link name="l2"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>'
    assert link in text
    path = write_urdf(text.replace(link, '<link name="l2"><inertial><mass value="1"/>'))
    with pytest.raises(RobotError) as info:
        load_robot(str(path))
    assert str(info.value) == (
        f"{path}: link 'l2' has an <inertial> without <inertia> (it would be read as a point mass): add "
        '<inertia ixx="..." iyy="..." izz="..." ixy="0" ixz="0" iyz="0"/> (kg m^2, about its centre of mass)'
    )
    assert capfd.readouterr().err == ""  # nothing from urdfdom's C++ parser


def test_a_mimic_joint_of_a_locked_gripper_is_noted_without_a_warning(urdf_log):
    robot = load_robot("panda")
    assert robot.notes == (
        "mimic joint 'panda_finger_joint2' (follows 'panda_finger_joint1', locked too) is locked at q = 0",
    )
    assert not urdf_log.records
