"""JointState CDR bytes read and written without messages, against rclpy's and rosbags' CDR."""
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from robotenis_ros import cdr
from robotenis_ros.convert import joint_vector
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import JointState

JOINTS = ('motor_1', 'motor_2', 'motor_3')
ROSBAGS = get_typestore(Stores.ROS2_JAZZY)


def message(names, sec=0, nanosec=0, frame_id='', **arrays):
    msg = JointState(name=list(names), **{k: [float(v) for v in a] for k, a in arrays.items()})
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    msg.header.frame_id = frame_id
    return msg


def rosbags_bytes(sec, nanosec, frame_id, **arrays):
    """Serialize a JointState with rosbags (its alignment padding is zeros, as the writer's)."""
    t = ROSBAGS.types
    header = t['std_msgs/msg/Header'](t['builtin_interfaces/msg/Time'](sec, nanosec), frame_id)
    values = {f: np.asarray(arrays.get(f, []), dtype=float) for f in cdr.JOINT_ARRAYS}
    msg = t['sensor_msgs/msg/JointState'](header, list(JOINTS), **values)
    return bytes(ROSBAGS.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))


def test_the_writer_gives_the_cdr_bytes_rosbags_and_rclpy_read():
    rng = np.random.default_rng(0)
    for frame_id in ('', 'b', 'base', 'odd_frame'):                # every alignment after it
        for fields in (('position', 'velocity'), ('velocity',), ('position', 'effort')):
            write = cdr.JointStateWriter(JOINTS, fields, frame_id)
            values = {f: rng.normal(size=3) for f in fields}
            data = write(12, 345_678_901, **values)
            assert data == rosbags_bytes(12, 345_678_901, frame_id, **values)
            back = deserialize_message(data, JointState)
            assert (back.header.stamp.sec, back.header.stamp.nanosec) == (12, 345_678_901)
            for f in fields:
                np.testing.assert_array_equal(getattr(back, f), values[f])


def test_the_writer_names_a_wrong_field():
    with pytest.raises(ValueError, match='no field'):
        cdr.JointStateWriter(JOINTS, ('speed',))
    with pytest.raises(ValueError, match='expected the fields velocity'):
        cdr.JointStateWriter(JOINTS, ('velocity',))(0, 0, position=(1.0, 2.0, 3.0))


def test_the_reader_gives_rclpys_values_in_the_joints_order_whatever_the_layout():
    reader = cdr.JointStateReader(JOINTS)
    cases = [
        message(JOINTS, 1, 2, position=[0.1, -0.2, 0.3], velocity=[1.0, 2.0, 3.0]),
        message(JOINTS, 3, 4, position=[1e-5, 2.5, -3.25], velocity=[4.0, 5.0, 6.0]),
        # the same length, the numbers elsewhere: no velocities, three efforts
        message(JOINTS, position=[0.1, 0.2, 0.3], effort=[4.0, 5.0, 6.0]),
        message(('motor_3', 'motor_1', 'motor_2'), position=[0.3, 0.1, 0.2]),
        message(JOINTS, frame_id='base', velocity=[0.1, 0.2, 0.3]),
        message(JOINTS + ('gripper',), position=[1.0, 2.0, 3.0, 4.0]),
        message(('mot_1', 'mot_2', 'mot_3'), position=[1.0, 2.0, 3.0]),      # a joint missing
        message(JOINTS, position=[1.0, 2.0]),                                # one value short
    ]
    for msg in cases * 2:                          # the second time, from the layouts learnt
        sec, nanosec, position, velocity = reader.read(serialize_message(msg))
        assert (sec, nanosec) == (msg.header.stamp.sec, msg.header.stamp.nanosec)
        for got, field in ((position, 'position'), (velocity, 'velocity')):
            want = joint_vector(msg, field, JOINTS)
            assert (got is None) == (want is None)
            if want is not None:
                assert list(got) == list(want)


def test_the_reader_gives_none_for_bytes_that_are_not_a_joint_state():
    reader = cdr.JointStateReader(JOINTS)
    assert reader.read(b'\x00\x07\x00\x00 not a message') is None
    assert reader.read(serialize_message(message(JOINTS, position=[1.0, 2.0, 3.0]))[:40]) is None
    with pytest.raises(ValueError, match='sensor_msgs/JointState'):
        cdr.joint_state_layout(b'\x00\x01\x00\x00' + bytes(10))
