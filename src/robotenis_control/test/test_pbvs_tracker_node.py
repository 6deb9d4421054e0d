"""The pbvs_tracker node's wiring via its callbacks: detections, joint readings in, eq. 23 out."""
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from robotenis_control import pbvs
from robotenis_control.pbvs_tracker_node import PbvsTrackerNode
from robotenis_kinematics import delta, description
from sensor_msgs.msg import JointState

FRAME = 1.0 / 120.0


class Recorder:
    def __init__(self):
        self.messages = []

    def publish(self, msg):
        self.messages.append(msg)

    def velocities(self):
        return np.array([[m.twist.linear.x, m.twist.linear.y, m.twist.linear.z]
                         for m in self.messages])


@pytest.fixture
def node():
    rclpy.init()
    n = PbvsTrackerNode()
    n.pub = Recorder()
    try:
        yield n
    finally:
        n.destroy_node()
        rclpy.try_shutdown()


def stamp(msg, t):
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int(round((t % 1) * 1e9))
    return msg


def joints(node, t, Theta=(0.0, 0.0, 0.0)):
    node.on_joint_states(stamp(JointState(name=['motor_3', 'motor_1', 'motor_2'],
                                          position=[Theta[2], Theta[0], Theta[1]]), t))


def sphere(node, t, s, frame='camera_optical'):
    msg = stamp(PointStamped(), t)
    msg.header.frame_id = frame
    msg.point.x, msg.point.y, msg.point.z = (float(v) for v in s)
    node.on_sphere(msg)


def test_a_still_ball_off_the_reference_gives_minus_kp_times_the_error(node):
    """
    Check that a still ball off the reference gives minus K_p times the error.

    Ball 10 mm beyond 600 mm on the optical axis (base +x): u_r = K_p * 0.01 m along +x, twice
    (the second detection repeats the first, so the filter's velocity stays zero).
    """
    for k in range(2):
        joints(node, 1.0 + k * FRAME)
        sphere(node, 1.0 + k * FRAME, pbvs.S_DESIRED + [0.0, 0.0, 0.01])
    np.testing.assert_allclose(node.pub.velocities(), [[pbvs.K_P * 0.01, 0.0, 0.0]] * 2,
                               atol=1e-12)
    assert node.pub.messages[0].header.frame_id == 'base'


def test_a_moving_ball_is_fed_forward(node):
    """
    Check that a moving ball is fed forward.

    The robot still, the ball moving at v (base frame) from the reference: after 60 frames the
    command is -K_p e_r + v_p with v_p = v (on noise-free positions of a constant-velocity ball
    the filter's velocity is exact to rounding within 20 frames); with feedforward off, -K_p e_r.
    """
    assert node.set_parameters([Parameter('max_speed', value=10.0)])[0].successful
    v = np.array([0.3, -0.2, 0.1])
    R = description.nominal().camera_rotation
    P = delta.forward(description.nominal(), np.zeros(3))
    ball0 = P + R @ pbvs.S_DESIRED
    for k in range(60):
        t = 2.0 + k * FRAME
        joints(node, t)
        sphere(node, t, R.T @ (ball0 + v * k * FRAME - P))
    s = R.T @ (ball0 + v * 59 * FRAME - P)
    expected = pbvs.cartesian_command(pbvs.relative_error(s, R), v)
    np.testing.assert_allclose(node.pub.velocities()[-1], expected, atol=1e-9)
    # feedforward off: the next detection is answered by the proportional term alone
    assert node.set_parameters([Parameter('feedforward', value=False)])[0].successful
    joints(node, 2.0 + 60 * FRAME)
    s = R.T @ (ball0 + v * 60 * FRAME - P)
    sphere(node, 2.0 + 60 * FRAME, s)
    np.testing.assert_allclose(node.pub.velocities()[-1], -pbvs.K_P * pbvs.relative_error(s, R),
                               atol=1e-12)


def test_commands_are_clipped_and_bad_detections_ignored(node):
    joints(node, 1.0)
    sphere(node, 1.0, [0.0, 0.0, 1.6])                      # a metre too far: 16.8 m/s asked
    assert np.linalg.norm(node.pub.velocities()[-1]) == pytest.approx(2.5)
    sphere(node, 1.0 + FRAME, pbvs.S_DESIRED, frame='base')  # not the camera's frame
    sphere(node, 1.5, pbvs.S_DESIRED)                        # no joint reading near it
    sphere(node, 1.0, pbvs.S_DESIRED)                        # older than the last one used
    assert len(node.pub.messages) == 1


def test_parameters_apply_while_running_and_bad_ones_are_refused(node):
    assert not node.set_parameters([Parameter('kp', value=-1.0)])[0].successful
    assert not node.set_parameters([Parameter('camera_sigma', value=[1e-4, 1e-4])])[0].successful
    assert not node.set_parameters(
        [Parameter('description_path', value='/nonexistent.yaml')])[0].successful
    assert node.set_parameters(
        [Parameter('kp', value=10.0), Parameter('distance', value=0.5)])[0].successful
    joints(node, 1.0)
    sphere(node, 1.0, [0.0, 0.0, 0.6])                      # 100 mm beyond the new 500 mm
    np.testing.assert_allclose(node.pub.velocities()[-1], [1.0, 0.0, 0.0], atol=1e-12)
    assert node.set_parameters([Parameter('enabled', value=False)])[0].successful
    joints(node, 1.0 + FRAME)
    sphere(node, 1.0 + FRAME, [0.0, 0.0, 0.6])
    assert len(node.pub.messages) == 1


def test_a_detection_waits_for_the_joint_reading_of_its_exposure(node):
    """
    Check that a detection waits for the joint reading of its exposure.

    The robot moving at 1 m/s along base z: readings at 1 ms. A detection handed over before the
    reading of its exposure is held until that reading comes, and the ball is placed with it:
    with the older reading the filter would see the ball 5 mm off and command its velocity.
    """
    desc = description.nominal()
    R, P0, v = desc.camera_rotation, np.array([0.0, 0.0, 0.9]), np.array([0.0, 0.0, 1.0])
    ball = P0 + R @ pbvs.S_DESIRED
    at = lambda t: delta.inverse(desc, P0 + v * (t - 1.0)) - desc.theta0  # noqa: E731
    for k in range(6):
        joints(node, 1.0 + 1e-3 * k, at(1.0 + 1e-3 * k))
    sphere(node, 1.005, R.T @ (ball - P0 - v * 0.005))  # first detection: its reading is there
    sphere(node, 1.010, R.T @ (ball - P0 - v * 0.010))  # its reading is not yet
    assert len(node.pub.messages) == 1
    for k in range(6, 11):
        joints(node, 1.0 + 1e-3 * k, at(1.0 + 1e-3 * k))
    assert len(node.pub.messages) == 2
    # the still ball seen from the right place: no velocity, the command is the proportional term
    e_r = pbvs.relative_error(R.T @ (ball - P0 - v * 0.010), R)
    np.testing.assert_allclose(node.pub.velocities()[-1], -pbvs.K_P * e_r, atol=1e-9)
    # switched off while a detection waits: its reading comes, and nothing is published
    sphere(node, 1.015, R.T @ (ball - P0 - v * 0.015))
    assert node.set_parameters([Parameter('enabled', value=False)])[0].successful
    for k in range(11, 16):
        joints(node, 1.0 + 1e-3 * k, at(1.0 + 1e-3 * k))
    assert len(node.pub.messages) == 2
