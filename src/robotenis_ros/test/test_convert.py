"""The message conversions, against rclpy's own where rclpy has one."""
from builtin_interfaces.msg import Time as TimeMsg
import numpy as np
import pytest
from rclpy.time import Time
from robotenis_ros import convert
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Header


def test_stamp_seconds_is_rclpys_nanoseconds_in_seconds():
    for sec, nanosec in ((0, 0), (1, 999_999_999), (1_700_000_000, 123_456_789)):
        stamp = TimeMsg(sec=sec, nanosec=nanosec)
        assert convert.stamp_seconds(stamp) == Time.from_msg(stamp).nanoseconds * 1e-9


def test_joint_vector_reads_the_motors_in_any_order():
    msg = JointState(name=['motor_3', 'motor_1', 'motor_2'], position=[3.0, 1.0, 2.0])
    np.testing.assert_array_equal(convert.joint_vector(msg, 'position'), [1.0, 2.0, 3.0])
    assert convert.joint_vector(msg, 'velocity') is None
    assert convert.joint_vector(msg, 'position', ('a', 'b', 'c')) is None
    renamed = JointState(name=['c', 'a', 'b'], position=[3.0, 1.0, 2.0])
    np.testing.assert_array_equal(convert.joint_vector(renamed, 'position', ('a', 'b', 'c')),
                                  [1.0, 2.0, 3.0])


def test_joint_state_round_trip():
    stamp = TimeMsg(sec=3, nanosec=5)
    msg = convert.joint_state(stamp, position=[0.1, 0.2, 0.3], velocity=np.array([1.0, 2.0, 3.0]))
    assert list(msg.name) == ['motor_1', 'motor_2', 'motor_3'] and msg.header.stamp == stamp
    np.testing.assert_array_equal(convert.joint_vector(msg, 'velocity'), [1.0, 2.0, 3.0])


def test_point_and_twist_carry_their_frame_and_stamp():
    stamp = TimeMsg(sec=1, nanosec=2)
    p = convert.point_stamped(np.array([0.1, -0.2, 0.3]), stamp, 'base')
    np.testing.assert_array_equal(convert.xyz(p.point), [0.1, -0.2, 0.3])
    assert p.header.frame_id == 'base' and p.header.stamp == stamp
    t = convert.twist_stamped([1.0, 2.0, 3.0], stamp, 'base')
    np.testing.assert_array_equal(convert.xyz(t.twist.linear), [1.0, 2.0, 3.0])


def test_image_round_trip_and_padded_rows():
    pixels = np.arange(12, dtype=np.uint8).reshape(3, 4)
    msg = convert.image_message(pixels, Header(frame_id='camera_optical'))
    assert (msg.width, msg.height, msg.step, msg.encoding) == (4, 3, 4, 'mono8')
    np.testing.assert_array_equal(convert.image_array(msg), pixels)
    padded = Image(height=3, width=4, step=6, encoding='mono8',
                   data=np.pad(pixels, ((0, 0), (0, 2))).tobytes())
    np.testing.assert_array_equal(convert.image_array(padded), pixels)


def test_image_array_names_what_is_wrong():
    with pytest.raises(ValueError, match='rgb8'):
        convert.image_array(Image(height=1, width=1, step=3, encoding='rgb8', data=b'abc'))
    with pytest.raises(ValueError, match='too short'):
        convert.image_array(Image(height=2, width=4, step=4, encoding='mono8', data=b'abcd'))
