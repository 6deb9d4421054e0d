"""The `hand_camera` node: the camera on the effector, looking at the ball (robotenis_sim.camera_model).

Renders at ``rate`` (120 Hz, the paper's 8.34 ms) the ball as the camera sees it from the TRUE
effector position (the latest /sim/effector_position of sim_motors) and the truth file's camera
mounting, and publishes /camera/image_raw (sensor_msgs/Image, mono8) and /camera/camera_info with
sensor-data QoS, frame_id the robot description's optical frame. Each image is stamped with the
effector sample it was rendered from (a faster camera than that topic repeats a stamp: run
sim_motors with truth_decimation <= 8 for a fresh sample per frame). The ball is the truth's fixed
calibration ball, or (``ball: chaotic``) a Lorenz path at up to ``ball_max_speed`` m/s
(robotenis_sim.ball) in the box of half sizes ``ball_half_size`` about ``ball_centre`` (default:
about the calibration ball); its true position goes to /sim/ball_position (PointStamped, base frame)
for scoring. Timers follow the node's clock, so use_sim_time runs it on /clock. With
``tick_on_effector`` there is no timer: the frames are the first effector samples at or after each
k / rate (camera_model.FrameClock), the same whatever the load; sim_motors' visual lockstep expects them.

Parameters: truth_path, rate, camera_info_path (ROS camera_info YAML; default the vision package's
hand_camera.yaml), ball ('fixed' or 'chaotic'), ball_max_speed (m/s), ball_centre and
ball_half_size (m, base frame), ball_path_duration (ChaoticBall's duration: how much of the
attractor the path covers; a path of the tracking study takes its value and seed), seed (-1: random;
the chaotic path's seed is max(seed, 0)), noise (grey levels), blur (px).
"""
import sys

import numpy as np
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from robotenis_kinematics.description import DescriptionError
from robotenis_kinematics.ros import spin, stamp_seconds
from robotenis_sim import ball as sim_ball, camera_model, truth as sim_truth
from robotenis_vision import camera as vision_camera

CHAOTIC_HALF_SIZE = (0.12, 0.12, 0.08)   # m: the box of the chaotic path around the calibration ball


def image_message(image, header):
    msg = Image()
    msg.header = header
    msg.height, msg.width = image.shape
    msg.encoding, msg.is_bigendian, msg.step = 'mono8', 0, image.shape[1]
    msg.data = image.tobytes()
    return msg


def camera_info_message(camera, header):
    msg = CameraInfo()
    msg.header = header
    for key, value in camera.camera_info_fields().items():
        setattr(msg, key, value)
    return msg


class HandCameraNode(Node):
    def __init__(self):
        super().__init__('hand_camera')
        for name, default in (('truth_path', ''), ('rate', 120.0), ('camera_info_path', ''), ('ball', 'fixed'),
                              ('ball_max_speed', 1.5), ('seed', -1), ('noise', 2.0), ('blur', 0.8),
                              ('tick_on_effector', False)):
            self.declare_parameter(name, default)
        p = lambda name: self.get_parameter(name).value  # noqa: E731 - short accessor
        self.truth = sim_truth.load(p('truth_path') or None)
        for name, default in (('ball_centre', [float(v) for v in self.truth.sphere_position]),
                              ('ball_half_size', list(CHAOTIC_HALF_SIZE)), ('ball_path_duration', 120.0)):
            self.declare_parameter(name, default)
        self.camera = vision_camera.load(p('camera_info_path') or vision_camera.default_path())
        self.ball = self.make_ball(p('ball'), float(p('ball_max_speed')), int(p('seed')))
        seed = int(p('seed'))
        self.rng = np.random.default_rng(None if seed < 0 else seed)
        self.noise, self.blur = float(p('noise')), float(p('blur'))
        rate = float(p('rate'))
        if not rate > 0 or self.noise < 0 or self.blur < 0:
            raise ValueError(f'rate must be positive and noise, blur not negative (got {rate}, {self.noise}, {self.blur})')
        self.frame_id = self.truth.geometry.camera_frame_id
        self.effector = None            # (P, stamp) of the latest true effector sample
        self.image_pub = self.create_publisher(Image, '/camera/image_raw', qos_profile_sensor_data)
        self.info_pub = self.create_publisher(CameraInfo, '/camera/camera_info', qos_profile_sensor_data)
        self.ball_pub = self.create_publisher(PointStamped, '/sim/ball_position', 10)
        self.create_subscription(PointStamped, '/sim/effector_position', self.on_effector, 10)
        self.frames = camera_model.FrameClock(rate) if p('tick_on_effector') else None
        if self.frames is None:
            self.create_timer(1.0 / rate, self.render_frame)

    def make_ball(self, kind, max_speed, seed):
        if kind == 'fixed':
            return sim_ball.FixedBall(tuple(self.truth.sphere_position))
        if kind != 'chaotic':
            raise ValueError(f"ball must be 'fixed' or 'chaotic', got {kind!r}")
        centre, half_size, duration = (np.asarray(self.get_parameter(n).value, dtype=float)
                                       for n in ('ball_centre', 'ball_half_size', 'ball_path_duration'))
        if not (max_speed > 0 and duration > 0 and centre.shape == half_size.shape == (3,) and np.all(half_size > 0)):
            raise ValueError(f'chaotic ball: need ball_max_speed > 0, ball_path_duration > 0, a ball_centre and '
                             f'three positive ball_half_size (got {max_speed}, {duration}, {centre.tolist()}, '
                             f'{half_size.tolist()})')
        return sim_ball.ChaoticBall(centre, half_size, max_speed, seed=max(seed, 0), duration=float(duration))

    def on_effector(self, msg):
        self.effector = (np.array([msg.point.x, msg.point.y, msg.point.z]), msg.header.stamp)
        if self.frames is not None and self.frames.due(stamp_seconds(msg.header.stamp)):
            self.render_frame()

    def render_frame(self):
        """Render the ball from the latest effector sample, stamped with it, and publish the frame and the truth."""
        if self.effector is None:
            self.get_logger().warn('no /sim/effector_position yet: not rendering', throttle_duration_sec=5.0)
            return
        P, stamp = self.effector
        t = stamp_seconds(stamp)
        B = self.ball.at(t)
        C = camera_model.sphere_in_optical(P, B, self.truth.camera_rotation, self.truth.camera_translation)
        image = camera_model.render(self.camera, C, self.truth.geometry.sphere_radius, self.rng,
                                    blur_sigma=self.blur, noise_sigma=self.noise)
        header = Image().header
        header.stamp, header.frame_id = stamp, self.frame_id
        self.image_pub.publish(image_message(image, header))
        self.info_pub.publish(camera_info_message(self.camera, header))
        truth = PointStamped()
        truth.header.stamp, truth.header.frame_id = stamp, 'base'
        truth.point.x, truth.point.y, truth.point.z = (float(v) for v in B)
        self.ball_pub.publish(truth)


def main(args=None):
    return spin(HandCameraNode, 'hand_camera', (DescriptionError, vision_camera.CameraError, ValueError), args)


if __name__ == '__main__':
    sys.exit(main())
