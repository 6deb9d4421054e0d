"""The camera model against OpenCV's own plumb_bob, and its camera_info YAML and message fields."""
import cv2
import numpy as np
import pytest

from robotenis_vision import camera as cm
from robotenis_vision.camera import CameraError


@pytest.fixture
def cam():
    return cm.Camera(cm.DEFAULT_K, [-0.21, 0.12, 1.5e-3, -8e-4, -0.02], 640, 480)


def test_project_matches_opencv(cam):
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-0.15, 0.15, 200), rng.uniform(-0.1, 0.1, 200),
                         rng.uniform(0.15, 0.6, 200)])
    ours = cam.project(X)
    theirs, _ = cv2.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.D)
    np.testing.assert_allclose(ours, theirs.reshape(-1, 2), atol=1e-9)


def test_undistort_inverts_distort_over_the_image(cam):
    u, v = np.meshgrid(np.linspace(0, 639, 41), np.linspace(0, 479, 31))
    uv = np.stack([u, v], axis=-1)
    xy = cam.pixel_rays(uv)
    assert np.all(np.isfinite(xy))
    np.testing.assert_allclose(cam.to_pixels(cam.distort(xy)), uv, atol=1e-9)
    np.testing.assert_allclose(cam.distort_pixels(cam.undistort_pixels(uv)), uv, atol=1e-9)


def test_undistort_agrees_with_opencv(cam):
    uv = np.array([[10.0, 12.0], [600.0, 30.0], [320.0, 240.0], [500.5, 470.25]])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    theirs = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, cam.D, criteria=criteria)
    # OpenCV iterates a fixed point to its own tolerance: agreement to 1e-4 px (f = 500) is its
    # precision
    np.testing.assert_allclose(cam.pixel_rays(uv), theirs.reshape(-1, 2), atol=2e-7)


def test_principal_point_and_bad_points(cam):
    np.testing.assert_allclose(cam.project([0.0, 0.0, 0.3]), [319.5, 239.5])
    with pytest.raises(CameraError, match='in front'):
        cam.project([0.0, 0.0, -1.0])


def test_yaml_round_trip_and_shipped_default(tmp_path):
    path = tmp_path / 'cam.yaml'
    cam = cm.Camera(cm.DEFAULT_K, [0.1, -0.2, 0.001, 0.002, 0.03], 800, 600, 'test_cam')
    cm.save(cam, str(path))
    back = cm.load(str(path))
    np.testing.assert_array_equal(back.K, cam.K)
    np.testing.assert_array_equal(back.D, cam.D)
    assert (back.width, back.height, back.name) == (800, 600, 'test_cam')
    shipped = cm.load(cm.default_path())
    np.testing.assert_array_equal(shipped.K, cm.default().K)
    np.testing.assert_array_equal(shipped.D, cm.default().D)
    assert (shipped.width, shipped.height) == (640, 480)


def test_camera_info_fields_round_trip():
    cam = cm.default()
    fields = cam.camera_info_fields()
    assert (fields['distortion_model'] == 'plumb_bob' and len(fields['k']) == 9
            and len(fields['p']) == 12)
    back = cm.from_camera_info(fields)
    np.testing.assert_array_equal(back.K, cam.K)
    np.testing.assert_array_equal(back.D, cam.D)


@pytest.mark.parametrize('edit, message', [
    (lambda d: d.pop('camera_matrix'), 'camera_matrix: missing key'),
    (lambda d: d['camera_matrix'].update(data=[1.0, 2.0]), 'camera_matrix'),
    (lambda d: d.update(distortion_model='equidistant'), 'distortion_model'),
    (lambda d: d.update(image_width=-3), 'image_width'),
    (lambda d: d['distortion_coefficients'].update(data=['a', 0, 0, 0, 0]),
     'distortion_coefficients'),
])
def test_bad_camera_info_names_the_key(edit, message):
    data = cm.default().to_yaml_dict()
    edit(data)
    with pytest.raises(CameraError, match=message):
        cm.from_yaml_dict(data)


def test_unreadable_file_is_a_clear_error(tmp_path):
    with pytest.raises(CameraError, match='cannot read'):
        cm.load(str(tmp_path / 'missing.yaml'))
    (tmp_path / 'bad.yaml').write_text('image_width: [1,\n')
    with pytest.raises(CameraError, match='not valid YAML'):
        cm.load(str(tmp_path / 'bad.yaml'))
