"""The message conversions, against rclpy's own where rclpy has one."""
from builtin_interfaces.msg import Time as TimeMsg
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from rclpy.time import Time
from robotenis_ros import cdr, convert
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


def _serialized_image(pixels, frame_id='camera_optical', step=None, encoding='mono8'):
    height, width = pixels.shape
    step = step or width
    padded = np.zeros((height, step), np.uint8)
    padded[:, :width] = pixels
    msg = Image(height=height, width=width, step=step, encoding=encoding,
                data=padded.tobytes())
    msg.header.stamp, msg.header.frame_id = TimeMsg(sec=7, nanosec=123_456_789), frame_id
    return serialize_message(msg)


def test_cdr_image_reads_what_rclpy_serializes():
    pixels = np.random.default_rng(0).integers(0, 256, (5, 7), dtype=np.uint8)
    for frame_id in ('', 'c', 'camera_optical', 'odd_frame'):       # every alignment after it
        for step in (7, 9):
            frame = cdr.image(_serialized_image(pixels, frame_id, step))
            assert (frame.sec, frame.nanosec, frame.frame_id) == (7, 123_456_789, frame_id)
            np.testing.assert_array_equal(frame.pixels, pixels)
            assert not frame.pixels.flags.writeable     # a view of the bytes, not a copy


def test_cdr_image_names_what_is_wrong():
    pixels = np.zeros((4, 4), np.uint8)
    with pytest.raises(ValueError, match='rgb8'):
        cdr.image(_serialized_image(pixels, encoding='rgb8'))
    with pytest.raises(ValueError, match='too short'):
        cdr.image(_serialized_image(pixels)[:-3])
    with pytest.raises(ValueError, match='not a CDR'):
        cdr.image(b'\x00\x07\x00\x00' + bytes(40))
    with pytest.raises(ValueError, match='sensor_msgs/Image'):
        cdr.image(_serialized_image(pixels)[:20])
