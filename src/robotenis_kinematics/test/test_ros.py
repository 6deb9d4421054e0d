"""The helpers every node shares (robotenis_kinematics.ros), against rclpy's own conversions."""
import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from rclpy.time import Time
from sensor_msgs.msg import JointState

from robotenis_kinematics.ros import joint_vector, stamp_seconds


def test_stamp_seconds_is_rclpys_nanoseconds_in_seconds():
    for sec, nanosec in ((0, 0), (1, 999_999_999), (1_700_000_000, 123_456_789)):
        stamp = TimeMsg(sec=sec, nanosec=nanosec)
        assert stamp_seconds(stamp) == Time.from_msg(stamp).nanoseconds * 1e-9


def test_joint_vector_reads_the_motors_in_any_order():
    msg = JointState(name=['motor_3', 'motor_1', 'motor_2'], position=[3.0, 1.0, 2.0])
    np.testing.assert_array_equal(joint_vector(msg, 'position'), [1.0, 2.0, 3.0])
    assert joint_vector(msg, 'velocity') is None
