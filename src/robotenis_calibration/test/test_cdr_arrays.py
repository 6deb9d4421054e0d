"""Decoding JointState CDR bytes one message at a time, against rclpy's own deserialization."""
from rclpy.serialization import deserialize_message, serialize_message

from robotenis_calibration.cdr_arrays import JointStateDecoder
from robotenis_ros.convert import joint_state, joint_vector
from sensor_msgs.msg import JointState

JOINTS = ('motor_1', 'motor_2', 'motor_3')


def message(names, position, sec=0, frame_id=''):
    msg = JointState(name=list(names), position=[float(v) for v in position])
    msg.header.stamp.sec, msg.header.frame_id = sec, frame_id
    return serialize_message(msg)


def test_positions_are_rclpy_s_in_the_joints_order_whatever_the_layout():
    decoder = JointStateDecoder(JOINTS)
    cases = [
        message(JOINTS, [0.1, -0.2, 0.3], sec=1),
        message(JOINTS, [1e-5, 2.5, -3.25], sec=2),                   # the same layout again
        message(('motor_3', 'motor_1', 'motor_2'), [0.3, 0.1, 0.2]),   # same length, other order
        message(JOINTS, [0.1, 0.2, 0.3], frame_id='base'),             # longer: another layout
        message(('motor_1', 'motor_2', 'motor_3', 'gripper'), [1.0, 2.0, 3.0, 4.0]),
        message(('mot_1', 'mot_2', 'mot_3'), [1.0, 2.0, 3.0]),         # a joint missing
    ]
    for data in cases * 2:
        want = joint_vector(deserialize_message(data, JointState), 'position', JOINTS)
        got = decoder.positions(data)
        assert (got is None) == (want is None)
        if want is not None:
            assert list(got) == list(want)


def test_a_message_without_one_position_per_name_or_not_cdr_gives_none():
    decoder = JointStateDecoder(JOINTS)
    stamp = JointState().header.stamp
    assert decoder.positions(serialize_message(joint_state(stamp, velocity=[1, 2, 3]))) is None
    assert decoder.positions(b'\x00\x07\x00\x00 not a message') is None
