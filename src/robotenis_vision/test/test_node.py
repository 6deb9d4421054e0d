"""The sphere_detector node's message translation (no ROS graph needed)."""
import numpy as np
from robotenis_vision import detector
from robotenis_vision.sphere_detector_node import detection_message
from std_msgs.msg import Header


def test_detection_message_fields():
    det = detector.Detection(np.array([0.01, -0.02, 0.2]), np.diag([1e-10, 2e-10, 3e-9]),
                             np.zeros((57, 2)), 0.08, 'conic')
    header = Header(frame_id='camera_optical')
    msg = detection_message(det, header, 500)
    assert (msg.position.z, msg.frames, msg.edge_points, msg.method) == (0.2, 500, 57, 'conic')
    np.testing.assert_array_equal(np.reshape(msg.covariance, (3, 3)), det.covariance)
    assert msg.header.frame_id == 'camera_optical'
