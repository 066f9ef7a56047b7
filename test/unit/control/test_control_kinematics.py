"""Plate kinematics against finite differences of forward kinematics, and the tilt wiring."""
import math
from pathlib import Path

import numpy as np
import pytest

from ball_balance.control.kinematics import (
    Chain,
    KinematicsError,
    PlateKinematics,
    ShaperConfig,
    axis_rotation,
    matrix_to_rotvec,
    rotvec_to_matrix,
    skew,
)

ROOT = Path(__file__).resolve().parents[3]
URDF = ROOT / "config" / "ur5e_ball_balance.urdf"
UR_JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
             "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
LEVEL_HOME = [0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, 0.0]

SYNTHETIC = """<robot name="synthetic">
  <link name="base_link"/><link name="a"/><link name="b"/><link name="c"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="a"/>
    <origin xyz="0.1 0 0.3" rpy="0.2 0 0.5"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="continuous"><parent link="a"/><child link="b"/>
    <origin xyz="0 0.2 0" rpy="1.5707963 0 0"/><axis xyz="0 1 1"/></joint>
  <joint name="j3" type="revolute"><parent link="b"/><child link="c"/>
    <origin xyz="0.05 0 0.1" rpy="0 -0.4 1.0"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="fixed_tip" type="fixed"><parent link="c"/><child link="tip"/>
    <origin xyz="0 0 0.05" rpy="0.3 0.2 0.1"/></joint>
</robot>"""


def _chains():
    return [(Chain.from_urdf(SYNTHETIC, ["j1", "j2", "j3"], tip="tip"), ["j1", "j2", "j3"]),
            (Chain.from_urdf(URDF.read_text(), UR_JOINTS), UR_JOINTS[3:])]


@pytest.mark.parametrize("chain, wrist", _chains())
def test_rotational_jacobian_matches_finite_differences_of_fk(chain, wrist):
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(5):
        q = rng.uniform(-1.5, 1.5, len(chain.joint_names))
        J_r = chain.rotational_jacobian(q, wrist)
        R0, _ = chain.fk(q)
        for col, name in enumerate(wrist):
            dq = np.zeros_like(q)
            dq[chain.joint_names.index(name)] = h
            R_plus, _ = chain.fk(q + dq)
            R_minus, _ = chain.fk(q - dq)
            # world angular velocity: log(R(q+h) R(q-h)^T) / 2h
            omega = matrix_to_rotvec(R_plus @ R_minus.T) / (2 * h)
            np.testing.assert_allclose(J_r[:, col], omega, atol=1e-6)


def test_rotvec_round_trip():
    w = np.array([0.3, -0.2, 0.5])
    np.testing.assert_allclose(matrix_to_rotvec(rotvec_to_matrix(w)), w, atol=1e-12)


def test_axis_rotation_is_rodrigues_and_to_the_bit_about_a_coordinate_axis():
    # the chain's joints use it in place of rotvec_to_matrix: on the UR chain (every axis a
    # coordinate axis) the IK's commands stay the same to the bit
    angles = [0.0, 1e-14, -1e-14, 0.3, -0.3, 1.7, -3.1, 2 * math.pi + 0.2]
    for axis in np.eye(3):
        K = skew(axis)
        for a in angles:
            assert np.array_equal(axis_rotation(K, K @ K, a), rotvec_to_matrix(axis * a)), (axis, a)
    axis = np.array([0.3, -0.4, 0.5]) / np.linalg.norm([0.3, -0.4, 0.5])
    K = skew(axis)
    for a in angles:
        np.testing.assert_allclose(axis_rotation(K, K @ K, a), rotvec_to_matrix(axis * a), atol=1e-15)


def test_missing_joint_and_broken_chain_are_named():
    with pytest.raises(KinematicsError, match="j9"):
        Chain.from_urdf(SYNTHETIC, ["j1", "j2", "j9"], tip="tip")
    with pytest.raises(KinematicsError, match="no chain"):
        Chain.from_urdf(SYNTHETIC, ["j1"], tip="nowhere")


class TestPlateOnTheUrArm:
    def setup_method(self):
        self.kin = PlateKinematics(Chain.from_urdf(URDF.read_text(), UR_JOINTS), LEVEL_HOME,
                                   shaper=ShaperConfig(max_joint_step_rad=1.0))

    def test_positive_u_x_lifts_plate_plus_x_edge_so_ball_rolls_to_minus_x(self):
        q = self.kin.ik(self.kin.home_q, self.kin.desired_rotation(0.1, 0.0))
        R, _ = self.kin.chain.fk(q)
        x_axis_world, y_axis_world = R[:, 0], R[:, 1]
        gravity_along_x = np.dot([0, 0, -9.81], x_axis_world)
        assert gravity_along_x < 0 and abs(np.dot([0, 0, -9.81], y_axis_world)) < 1e-6
        assert x_axis_world[2] == pytest.approx(math.sin(0.1), abs=1e-6)

    def test_positive_u_y_rolls_ball_to_minus_y(self):
        q = self.kin.ik(self.kin.home_q, self.kin.desired_rotation(0.0, 0.1))
        R, _ = self.kin.chain.fk(q)
        assert np.dot([0, 0, -9.81], R[:, 1]) < 0

    def test_ik_reaches_the_tilt_and_moves_only_the_wrist(self):
        for ux, uy in ((0.1, 0.0), (-0.05, 0.08), (0.12, -0.12)):
            q = self.kin.ik(self.kin.home_q, self.kin.desired_rotation(ux, uy))
            assert self.kin.tilt_of(q) == pytest.approx((ux, uy), abs=1e-6)
            np.testing.assert_array_equal(q[:3], self.kin.home_q[:3])

    def test_total_tilt_is_limited(self):
        q = self.kin.ik(self.kin.home_q, self.kin.desired_rotation(1.0, 1.0))
        assert np.hypot(*self.kin.tilt_of(q)) == pytest.approx(self.kin.shaper.max_tilt_rad, abs=1e-6)

    def test_shaping_clips_each_joint_step_and_respects_limits(self):
        kin = PlateKinematics(self.kin.chain, LEVEL_HOME, shaper=ShaperConfig(max_joint_step_rad=0.01))
        q_prev = kin.home_q.copy()
        q = kin.shape(q_prev + np.array([0, 0, 0, 0.5, -0.5, 0.001]), q_prev)
        np.testing.assert_allclose(q - q_prev, [0, 0, 0, 0.01, -0.01, 0.00002])
        far = kin.shape(np.full(6, 100.0), np.full(6, 100.0))
        assert np.all(far <= kin.q_max)


@pytest.mark.parametrize("chain, wrist", _chains())
def test_geometric_jacobian_linear_part_matches_finite_differences(chain, wrist):
    q = np.random.default_rng(5).uniform(-1.0, 1.0, len(chain.joint_names))
    J = chain.geometric_jacobian(q, chain.joint_names)
    h = 1e-6
    for col in range(len(q)):
        dq = np.zeros_like(q)
        dq[col] = h
        np.testing.assert_allclose(J[3:, col], (chain.fk(q + dq)[1] - chain.fk(q - dq)[1]) / (2 * h), atol=1e-6)


@pytest.mark.parametrize("chain, wrist", _chains())
def test_pose_and_jacobian_in_one_pass_equal_fk_and_the_rotational_jacobian(chain, wrist):
    q = np.random.default_rng(6).uniform(-1.0, 1.0, len(chain.joint_names))
    R, p, J = chain.pose_and_jacobian(q, chain.joint_names)
    R_fk, p_fk = chain.fk(q)
    np.testing.assert_array_equal(R, R_fk)
    np.testing.assert_array_equal(p, p_fk)
    np.testing.assert_array_equal(J[:3], chain.rotational_jacobian(q, chain.joint_names))


def test_pivot_mode_tilts_the_plate_about_its_own_centre():
    kin = PlateKinematics(Chain.from_urdf(URDF.read_text(), UR_JOINTS), LEVEL_HOME, mode="pivot")
    wrist = PlateKinematics(kin.chain, LEVEL_HOME, mode="wrist")
    for ux, uy in ((0.1, 0.0), (-0.06, 0.09)):
        q = kin.ik(kin.home_q, kin.desired_rotation(ux, uy))
        assert kin.tilt_of(q) == pytest.approx((ux, uy), abs=1e-6)
        np.testing.assert_allclose(kin.chain.fk(q)[1], kin.p_WP_home, atol=1e-6)
        q_w = wrist.ik(wrist.home_q, wrist.desired_rotation(ux, uy))
        assert np.linalg.norm(wrist.chain.fk(q_w)[1] - wrist.p_WP_home) > 0.005  # wrist mode moves it


def test_step_limit_keeps_the_ik_direction():
    kin = PlateKinematics(Chain.from_urdf(URDF.read_text(), UR_JOINTS), LEVEL_HOME, mode="pivot",
                          shaper=ShaperConfig(max_joint_step_rad=0.01))
    q = kin.command(0.1, 0.0, kin.home_q)
    assert np.max(np.abs(q - kin.home_q)) == pytest.approx(0.01)
    np.testing.assert_allclose(kin.chain.fk(q)[1], kin.p_WP_home, atol=2e-4)  # still (nearly) on the pivot
