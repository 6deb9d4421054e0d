"""The `sphere_detector` node: the sphere's centre from the hand camera's images.

Subscribes /camera/image_raw (sensor_msgs/Image, mono8) and /camera/camera_info (sensor-data QoS);
publishes /sphere/position (geometry_msgs/PointStamped, optical frame, m, stamp of the image) and
/sphere/detection (robotenis_interfaces/SphereDetection: covariance, frames, edge points, fit RMS,
method). With ``frames`` > 1 it publishes the average of every ``frames`` detections (outliers
rejected, robotenis_vision.averaging), stamped with the last image. A frame it cannot trust is
dropped with the reason in a rate-limited log line.

Parameters: method ('conic', 'paper', 'tangent', 'baseline'), radius (m; 0: from the robot
description), description_path (default: the nominal description), frames (1), max_fit_rms_px
(outline points farther than this from the fitted outline, RMS, make the frame untrusted),
use_prior (true: the previous frame's detection, if it is the last frame's, seeds the next one:
about half the time at rest; the detector searches the whole image when it does not fit).
"""
import sys

import numpy as np
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from robotenis_interfaces.msg import SphereDetection
from robotenis_kinematics import description
from robotenis_kinematics.ros import spin
from robotenis_vision import averaging, camera as camera_model, detector

ENCODINGS = ('mono8', '8UC1')


def image_array(msg):
    """The image of a mono8 sensor_msgs/Image as a (height, width) uint8 array; ValueError otherwise."""
    if msg.encoding not in ENCODINGS:
        raise ValueError(f"image encoding {msg.encoding!r} is not mono8")
    if msg.step < msg.width or len(msg.data) < msg.step * msg.height:
        raise ValueError(f'image data too short for {msg.width}x{msg.height} (step {msg.step}, {len(msg.data)} bytes)')
    rows = np.frombuffer(bytes(msg.data), dtype=np.uint8, count=msg.step * msg.height).reshape(msg.height, msg.step)
    return rows[:, :msg.width]


def detection_message(det, header, frames):
    out = SphereDetection()
    out.header = header
    out.position.x, out.position.y, out.position.z = (float(v) for v in det.position)
    out.covariance = [float(v) for v in np.asarray(det.covariance).ravel()]
    out.frames = int(frames)
    out.edge_points = int(len(det.edge_points))
    out.fit_rms_px = float(det.fit_rms_px) if np.isfinite(det.fit_rms_px) else 0.0
    out.method = det.method
    return out


class SphereDetectorNode(Node):
    def __init__(self):
        super().__init__('sphere_detector')
        self.declare_parameter('method', 'conic')
        self.declare_parameter('radius', 0.0)
        self.declare_parameter('description_path', description.config_path('nominal.yaml'))
        self.declare_parameter('frames', 1)
        self.declare_parameter('max_fit_rms_px', 0.5)
        self.declare_parameter('use_prior', True)
        p = lambda name: self.get_parameter(name).value  # noqa: E731 - short accessor
        self.method = p('method')
        if self.method not in detector.METHODS:
            raise ValueError(f"method must be one of {', '.join(detector.METHODS)}, got {self.method!r}")
        self.radius = float(p('radius')) or description.load(p('description_path')).sphere_radius
        self.frames = max(1, int(p('frames')))
        self.max_rms = float(p('max_fit_rms_px'))
        self.use_prior = bool(p('use_prior'))
        self.prior = None
        self.camera = None
        self.camera_key = None
        self.batch = []
        self.position_pub = self.create_publisher(PointStamped, '/sphere/position', 10)
        self.detection_pub = self.create_publisher(SphereDetection, '/sphere/detection', 10)
        self.create_subscription(CameraInfo, '/camera/camera_info', self.on_camera_info, qos_profile_sensor_data)
        self.create_subscription(Image, '/camera/image_raw', self.on_image, qos_profile_sensor_data)
        self.get_logger().info(f'sphere radius {self.radius * 1e3:.2f} mm, method {self.method}, '
                               f'{self.frames} frame(s) per measurement')

    def drop(self, reason):
        self.get_logger().warn(f'frame dropped: {reason}', throttle_duration_sec=2.0)

    def on_camera_info(self, msg):
        key = (tuple(msg.k), tuple(msg.d), msg.width, msg.height, msg.distortion_model)
        if key == self.camera_key:
            return
        try:
            self.camera = camera_model.from_camera_info(msg)
            self.camera_key = key
        except camera_model.CameraError as e:
            self.get_logger().error(f'camera_info unusable: {e}', throttle_duration_sec=5.0)

    def on_image(self, msg):
        if self.camera is None:
            self.drop('no camera_info received yet')
            return
        prior, self.prior = self.prior, None
        try:
            det = detector.detect(image_array(msg), self.camera, self.radius, self.method, prior)
        except (ValueError, detector.DetectionError) as e:
            self.drop(str(e))
            return
        if np.isfinite(det.fit_rms_px) and det.fit_rms_px > self.max_rms:
            self.drop(f'outline fit RMS {det.fit_rms_px:.2f} px > {self.max_rms} px')
            return
        if self.use_prior and det.method != 'baseline':
            self.prior = det
        if self.frames == 1:
            self.publish(det, msg.header, 1)
            return
        self.batch.append(det)
        if len(self.batch) == self.frames:
            avg = averaging.average([d.position for d in self.batch], [d.covariance for d in self.batch])
            det.position, det.covariance = avg.position, avg.covariance
            self.batch = []
            self.publish(det, msg.header, avg.frames)

    def publish(self, det, header, frames):
        header.frame_id = header.frame_id or 'camera_optical'
        point = PointStamped()
        point.header = header
        point.point.x, point.point.y, point.point.z = (float(v) for v in det.position)
        self.position_pub.publish(point)
        self.detection_pub.publish(detection_message(det, header, frames))


def main(args=None):
    return spin(SphereDetectorNode, 'sphere_detector', (ValueError, description.DescriptionError), args)


if __name__ == '__main__':
    sys.exit(main())
