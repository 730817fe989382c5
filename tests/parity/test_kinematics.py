"""DH forward kinematics against hand-computed poses in both conventions."""

import math

import hmlvs
import numpy as np
import pytest
import reference_model as ref


def test_standard_two_link_planar_by_hand():
    robot = hmlvs.Robot.from_dh([(300, 0, 0), (200, 0, 0)])
    t = robot.poses([math.pi / 2, -math.pi / 2])[0]
    # link 1 points along y, link 2 turns back to x: end at (200, 300, 0), orientation identity
    np.testing.assert_allclose(t[:3, 3], [200, 300, 0], atol=1e-12)
    np.testing.assert_allclose(t[:3, :3], np.eye(3), atol=1e-12)


def test_standard_dh_single_link_by_hand():
    robot = hmlvs.Robot.from_dh([(10, math.pi / 2, 5)])
    t = robot.poses([math.pi / 2])[0]
    # Rz(90) Tz(5) Tx(10) Rx(90): origin (0, 10, 5); x -> y, y -> z, z -> x
    expected = np.array([[0, 0, 1, 0], [1, 0, 0, 10], [0, 1, 0, 5], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(t, expected, atol=1e-12)


def test_modified_dh_single_link_by_hand():
    robot = hmlvs.Robot.from_dh([(10, math.pi / 2, 5)], convention="modified")
    t = robot.poses([math.pi / 2])[0]
    # Rx(90) Tx(10) Rz(90) Tz(5): origin (10, -5, 0); x -> z, y -> -x, z -> -y
    expected = np.array([[0, -1, 0, 10], [0, 0, -1, -5], [1, 0, 0, 0], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(t, expected, atol=1e-12)


@pytest.mark.parametrize("convention", ["standard", "modified"])
def test_chain_matches_oracle(rng, convention):
    table = [(rng.uniform(-300, 300), rng.uniform(-3, 3), rng.uniform(-300, 300),
              rng.uniform(-1, 1)) for _ in range(6)]
    robot = hmlvs.Robot.from_dh(table, convention=convention)
    joints = rng.uniform(-3, 3, (20, 6))
    got = robot.poses(joints)
    link = ref.dh_standard if convention == "standard" else ref.dh_modified
    for i in range(20):
        t = np.eye(4)
        for (a, alpha, d, off), q in zip(table, joints[i]):
            t = t @ link(a, alpha, d, q + off)
        np.testing.assert_allclose(got[i], t, atol=1e-9)


def test_degrees_and_tool_and_prismatic():
    tool = np.eye(4)
    tool[2, 3] = 100.0
    link = hmlvs.geometry.robot.DHLink
    robot = hmlvs.Robot((link(0, 0, 0), link(0, 0, 0, prismatic=True)),
                        flange_from_hand=tool)
    t = robot.poses([[90.0, 50.0]], degrees=True)[0]
    np.testing.assert_allclose(t[:3, 3], [0, 0, 150], atol=1e-12)
    np.testing.assert_allclose(t[:3, 0], [0, 1, 0], atol=1e-12)


def test_scorbot_zero_pose():
    t = hmlvs.Robot.scorbot_er7().poses(np.zeros(5))[0]
    # stretched along x: 50 + 300 + 350 = 700 mm out, 358.5 - 251 mm up, flange pointing down
    np.testing.assert_allclose(t[:3, 3], [700, 0, 358.5 - 251], atol=1e-9)
    np.testing.assert_allclose(t[:3, 2], [0, 0, -1], atol=1e-12)


def test_bad_joint_input():
    robot = hmlvs.Robot.scorbot_er7()
    with pytest.raises(ValueError, match=r"shape \(m, 5\) for this 5-joint robot"):
        robot.poses(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="joint reading 1 is not finite"):
        robot.poses([[0, 0, 0, 0, 0], [0, np.nan, 0, 0, 0]])
    with pytest.raises(ValueError, match="convention must be"):
        hmlvs.Robot.from_dh([(1, 0, 0)], convention="craig")
