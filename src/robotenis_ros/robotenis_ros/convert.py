"""
Conversions between the messages the nodes exchange and numpy arrays (SI units, REP-103).

Every function reads or builds one message type; the readers accept any object with the message's
fields (an rclpy message, or one deserialized by the rosbags library from a bag).
"""
import array

from geometry_msgs.msg import PointStamped, TwistStamped
import numpy as np
from robotenis_ros.cdr import mono8_pixels
from robotenis_ros.names import JOINTS
from sensor_msgs.msg import CameraInfo, Image


def stamp_seconds(stamp):
    """Return a builtin_interfaces/Time (a header stamp) in seconds, as rclpy's Time does."""
    return (stamp.sec * 1_000_000_000 + stamp.nanosec) * 1e-9


def xyz(vector):
    """Return the (x, y, z) of a geometry_msgs Point or Vector3 as an array (3,)."""
    return np.array([vector.x, vector.y, vector.z], dtype=float)


def point_stamped(position, stamp, frame_id):
    """Build a geometry_msgs/PointStamped at ``position`` (3,), m, in ``frame_id``."""
    msg = PointStamped()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.point.x, msg.point.y, msg.point.z = (float(v) for v in position)
    return msg


def twist_stamped(linear, stamp, frame_id):
    """Build a geometry_msgs/TwistStamped of linear velocity ``linear`` (3,), m/s."""
    msg = TwistStamped()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (float(v) for v in linear)
    return msg


def joint_vector(msg, field, joints=JOINTS):
    """
    Return the ``joints`` entries of a JointState field (position, velocity) as an array.

    The names may come in any order. None when the field does not hold one value per name or a
    joint is missing.
    """
    values = getattr(msg, field)
    if len(values) != len(msg.name):
        return None
    index = {name: i for i, name in enumerate(msg.name)}
    if any(j not in index for j in joints):
        return None
    return np.array([values[index[j]] for j in joints], dtype=float)


def image_array(msg):
    """
    Return a mono8 sensor_msgs/Image as a (height, width) uint8 array.

    Raises
    ------
    ValueError
        if the encoding is not mono8 or the data is shorter than the image.

    """
    return mono8_pixels(bytes(msg.data), msg.encoding, msg.height, msg.width, msg.step)


def image_message(pixels, header):
    """Build a mono8 sensor_msgs/Image of a (height, width) uint8 array."""
    msg = Image()
    msg.header = header
    msg.height, msg.width = pixels.shape
    msg.encoding, msg.is_bigendian, msg.step = 'mono8', 0, pixels.shape[1]
    # from the array's buffer: by way of tobytes(), 0.6 ms a 640x480 frame instead of 0.01 ms
    data = array.array('B')
    data.frombytes(np.ascontiguousarray(pixels, dtype=np.uint8).data)
    msg.data = data
    return msg


def camera_info_message(fields, header):
    """Build a sensor_msgs/CameraInfo from its fields (a camera's ``camera_info_fields()``)."""
    msg = CameraInfo()
    msg.header = header
    for key, value in fields.items():
        setattr(msg, key, value)
    return msg
