"""The sphere_detector node through its callbacks: message translation, rest, a lost ball."""
import numpy as np
import pytest
import rclpy
from rclpy.serialization import serialize_message
from robotenis_ros.convert import camera_info_message, image_message
from robotenis_vision import camera as vision_camera, detector
from robotenis_vision.sphere_detector_node import detection_message, SphereDetectorNode
from sensor_msgs.msg import Image
import simple_render
from std_msgs.msg import Header


def test_detection_message_fields():
    det = detector.Detection(np.array([0.01, -0.02, 0.2]), np.diag([1e-10, 2e-10, 3e-9]),
                             np.zeros((57, 2)), 0.08, 'conic')
    header = Header(frame_id='camera_optical')
    msg = detection_message(det, header, 500)
    assert (msg.position.z, msg.frames, msg.edge_points, msg.method) == (0.2, 500, 57, 'conic')
    np.testing.assert_array_equal(np.reshape(msg.covariance, (3, 3)), det.covariance)
    assert msg.header.frame_id == 'camera_optical'


FRAME = 1.0 / 120.0
R = 0.019                       # m: the paper's ball radius R_B


class Recorder:
    def __init__(self):
        self.messages = []

    def publish(self, msg):
        self.messages.append(msg)


@pytest.fixture
def node():
    rclpy.init()
    n = SphereDetectorNode()
    cam = vision_camera.default()
    info = camera_info_message(cam.camera_info_fields(), Header(frame_id='camera_optical'))
    n.on_camera_info(info)
    n.position_pub, n.detection_pub = Recorder(), Recorder()
    try:
        yield n
    finally:
        n.destroy_node()
        rclpy.try_shutdown()


def feed(node, pixels, t):
    header = Header(frame_id='camera_optical')
    header.stamp.sec, header.stamp.nanosec = int(t), int(round((t % 1) * 1e9))
    node.on_image(serialize_message(image_message(pixels, header)))   # as raw=True takes it


def test_at_rest_the_model_fits_mean_images_at_1_8_16_and_corrects_frames(
        node, monkeypatch):
    methods = []
    detect = detector.detect

    def counting(image, camera, radius, method, *args, **kwargs):
        methods.append(method)
        return detect(image, camera, radius, method, *args, **kwargs)

    monkeypatch.setattr(detector, 'detect', counting)
    cam, C = vision_camera.default(), np.array([0.03, -0.02, 0.3])
    clean = simple_render.render(cam, C, R).astype(float)
    rng = np.random.default_rng(3)
    for k in range(20):
        frame = np.clip(np.rint(clean + 2.0 * rng.standard_normal(clean.shape)), 0, 255)
        feed(node, frame.astype(np.uint8), k * FRAME)
    published = [m.method for m in node.detection_pub.messages]
    # still from the fourth frame (rest_frames 3): 17 frames at rest, fitted at 1, 8, 16
    assert published == ['conic'] * 3 + ['conic+model mean'] * 17
    assert methods.count('model') == 3 and methods.count('conic') == 20
    z = [m.point.z for m in node.position_pub.messages[3:]]
    assert abs(np.mean(z) - C[2]) < 2e-4                   # the uniform ball: no shading bias


def test_a_lost_ball_is_searched_again_after_search_interval_of_image_time(node, monkeypatch):
    calls = []
    detect = detector.detect

    def counting(*args):
        calls.append(args[4] is None)                     # no seed: a search
        return detect(*args)

    monkeypatch.setattr(detector, 'detect', counting)
    cam = vision_camera.default()
    empty = np.full((cam.height, cam.width), 80, np.uint8)
    for k in range(60):                                   # 0.5 s without a ball
        feed(node, empty, k * FRAME)
    # searched at 0, 0.2 and 0.4 s (frames 0, 24 and 48); nothing published
    assert calls == [True] * 3 and not node.position_pub.messages
    ball = simple_render.render(cam, np.array([0.0, 0.0, 0.3]), R)
    for k in range(60, 64):
        feed(node, ball, k * FRAME)
    # the ball is back at 0.5 s: found at the next search (0.6 s, frame 72), not before
    assert len(calls) == 3
    feed(node, ball, 72 * FRAME)
    assert len(calls) == 4 and len(node.position_pub.messages) == 1
    feed(node, ball, 73 * FRAME)
    assert calls[-1] is False                             # then seeded by the last detection
    feed(node, empty, 74 * FRAME)                         # lost again: held off until 0.82 s
    feed(node, empty, 75 * FRAME)
    assert len(calls) == 6
    # image time going back (a bag replayed from its start) does not hold the search off
    feed(node, empty, 0.0)
    assert len(calls) == 7


def test_a_frame_without_a_ball_is_dropped_with_its_reason_on_sphere_dropped(node):
    node.dropped_pub = Recorder()
    cam = vision_camera.default()
    feed(node, np.full((cam.height, cam.width), 80, np.uint8), 0.0)
    assert node.position_pub.messages == [] and len(node.dropped_pub.messages) == 1
    assert node.dropped_pub.messages[0].data.startswith('no sphere')


def test_an_image_it_cannot_read_is_dropped_with_the_reason(node, monkeypatch):
    reasons = []
    monkeypatch.setattr(node, 'drop', reasons.append)
    colour = Image(height=2, width=2, step=6, encoding='rgb8', data=bytes(12))
    node.on_image(serialize_message(colour))
    node.on_image(serialize_message(Image(height=4, width=4, step=4, encoding='mono8',
                                          data=bytes(8))))
    assert node.detection_pub.messages == []
    assert 'rgb8' in reasons[0] and 'too short' in reasons[1]
