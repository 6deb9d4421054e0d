"""The sphere_detector node's message translation (no ROS graph needed)."""
import numpy as np
import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from robotenis_vision import detector
from robotenis_vision.sphere_detector_node import detection_message, image_array


def test_mono8_with_row_padding():
    arr = np.arange(12, dtype=np.uint8).reshape(3, 4)
    msg = Image(height=3, width=4, encoding='mono8', step=6)
    msg.data = np.hstack([arr, np.zeros((3, 2), np.uint8)]).tobytes()
    np.testing.assert_array_equal(image_array(msg), arr)


def test_other_encodings_and_short_data_are_refused():
    with pytest.raises(ValueError, match='mono8'):
        image_array(Image(height=1, width=1, encoding='rgb8', step=3, data=b'abc'))
    with pytest.raises(ValueError, match='too short'):
        image_array(Image(height=2, width=2, encoding='mono8', step=2, data=b'ab'))


def test_detection_message_fields():
    det = detector.Detection(np.array([0.01, -0.02, 0.2]), np.diag([1e-10, 2e-10, 3e-9]),
                             np.zeros((57, 2)), 0.08, 'conic')
    header = Header(frame_id='camera_optical')
    msg = detection_message(det, header, 500)
    assert (msg.position.z, msg.frames, msg.edge_points, msg.method) == (0.2, 500, 57, 'conic')
    np.testing.assert_array_equal(np.reshape(msg.covariance, (3, 3)), det.covariance)
    assert msg.header.frame_id == 'camera_optical'
