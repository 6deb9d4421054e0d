"""The project's own interfaces are generated, importable and survive serialisation."""
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message

from robotenis_interfaces.msg import CalibrationProgress, RestMarker, SphereDetection
from robotenis_interfaces.srv import Calibrate


def test_sphere_detection_round_trip():
    msg = SphereDetection()
    msg.header.frame_id = 'camera_optical'
    msg.position.x, msg.position.y, msg.position.z = 0.01, -0.02, 0.2
    msg.covariance = list(np.diag([1e-10, 2e-10, 3e-9]).ravel())
    msg.frames, msg.edge_points, msg.fit_rms_px, msg.method = 500, 180, 0.05, 'conic'
    back = deserialize_message(serialize_message(msg), SphereDetection)
    assert back.position.z == 0.2 and back.frames == 500 and back.method == 'conic'
    np.testing.assert_array_equal(np.reshape(back.covariance, (3, 3)),
                                  np.diag([1e-10, 2e-10, 3e-9]))


def test_calibrate_service_fields():
    request = Calibrate.Request(num_poses=300, frames_per_pose=500, settle_time=4.0, seed=7,
                                pose_selection='boundary', bag_path='')
    back = deserialize_message(serialize_message(request), Calibrate.Request)
    assert (back.num_poses, back.settle_time, back.pose_selection) == (300, 4.0, 'boundary')
    response = Calibrate.Response(success=False, message='busy', effects=['backlash'])
    response_back = deserialize_message(serialize_message(response), Calibrate.Response)
    assert response_back.effects == ['backlash']


def test_progress_and_rest_markers():
    progress = CalibrationProgress(stage='measuring', pose_index=3, pose_count=300, fraction=0.01)
    assert deserialize_message(serialize_message(progress),
                               CalibrationProgress).stage == 'measuring'
    marker = RestMarker(pose_index=4, start=True)
    assert deserialize_message(serialize_message(marker), RestMarker).start
