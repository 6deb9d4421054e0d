"""
The `hand_camera` node: the camera on the effector, seeing the ball (robotenis_sim.camera_model).

Renders at ``rate`` (120 Hz, the paper's 8.34 ms) the ball as the camera sees it from the TRUE
effector position (the latest sim/effector_position of sim_motors) and the truth file's camera
mounting, where the truth's camera reads it (its undeclared errors: rendered_centre), and publishes
camera/image_raw (sensor_msgs/Image, mono8) and camera/camera_info with
sensor-data QoS, frame_id the robot description's optical frame. Each image is stamped with the
effector sample it was rendered from (a faster camera than that topic repeats a stamp: run
sim_motors with truth_decimation <= 8 for a fresh sample per frame). The ball is the truth's fixed
calibration ball, or (``ball: chaotic``) a Lorenz path at up to ``ball_max_speed`` m/s
(robotenis_sim.ball) in the box of half sizes ``ball_half_size`` about ``ball_centre`` (default:
about the calibration ball); its true position goes to sim/ball_position (PointStamped, base frame)
for scoring. Timers follow the node's clock, so use_sim_time runs it on /clock. With
``tick_on_effector`` there is no timer: the frames are the first effector samples at or after each
k / rate (camera_model.FrameClock), the same whatever the load; sim_motors' visual lockstep expects
them.

Parameters: the table PARAMETERS.
"""
import sys

from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from robotenis_kinematics.description import DescriptionError
from robotenis_ros.convert import (camera_info_message, image_message, point_stamped,
                                   stamp_seconds, xyz)
from robotenis_ros.names import BASE_FRAME
from robotenis_ros.node import declare_parameters, spin
from robotenis_sim import ball as sim_ball, camera_model, truth as sim_truth
from robotenis_vision import camera as vision_camera
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

CHAOTIC_HALF_SIZE = (0.12, 0.12, 0.08)   # m: the box of the chaotic path around the ball
PARAMETERS = {
    'truth_path': ('', "the simulator's truth file (empty: robotenis_sim's default truth)"),
    'rate': (120.0, "Hz: frames (the paper's 8.34 ms)"),
    'camera_info_path': ('', "ROS camera_info YAML (empty: the vision package's "
                             'hand_camera.yaml)'),
    'ball': ('fixed', "'fixed': the truth's calibration ball; 'chaotic': a Lorenz path"),
    'ball_max_speed': (1.5, 'm/s: top speed of the chaotic path'),
    'ball_centre': ([0.0, 0.0, 0.0], "m, base frame: centre of the chaotic path's box "
                                     "(default: the truth's calibration ball)"),
    'ball_half_size': (list(CHAOTIC_HALF_SIZE), "m: half sizes of the chaotic path's box"),
    'ball_path_duration': (120.0, "ChaoticBall's duration: how much of the attractor the path "
                                  'covers'),
    'seed': (-1, 'random seed of the noise (-1: random); the chaotic path uses max(seed, 0)'),
    'noise': (2.0, 'grey levels: sensor noise'),
    'blur': (0.8, 'px: Gaussian blur of the lens'),
    'tick_on_effector': (False, 'expose on the simulator samples (visual lockstep), no timer'),
    'effector_queue': (10, 'effector samples kept while busy: a sample lost is a frame not made '
                           '(a simulator up to 0.1 s ahead at rest: 25; a visual loop wants the '
                           'newest)'),
}


def rendered_centre(truth, P, B):
    """
    Return where the ball is drawn (optical frame, m) for effector P and ball B (base frame).

    Where the truth's camera reads it (truth.camera_reading: a depth scale, a lens residue the
    declared camera lacks), so that a detector that measures the image exactly reads what the
    truth says the camera reads, and the scorers compare with the same.
    """
    return truth.camera_reading(camera_model.sphere_in_optical(
        P, B, truth.camera_rotation, truth.camera_translation))


class HandCameraNode(Node):

    def __init__(self):
        super().__init__('hand_camera')
        path = declare_parameters(self, {'truth_path': PARAMETERS['truth_path']})['truth_path']
        self.truth = sim_truth.load(path or None)
        p = declare_parameters(self, PARAMETERS,
                               ball_centre=[float(v) for v in self.truth.sphere_position])
        self.camera = vision_camera.load(p['camera_info_path'] or vision_camera.default_path())
        self.ball = self.make_ball(p)
        seed = int(p['seed'])
        self.rng = np.random.default_rng(None if seed < 0 else seed)
        self.noise, self.blur = float(p['noise']), float(p['blur'])
        rate = float(p['rate'])
        if not rate > 0 or self.noise < 0 or self.blur < 0:
            raise ValueError(f'rate must be positive and noise, blur not negative '
                             f'(got {rate}, {self.noise}, {self.blur})')
        self.frame_id = self.truth.geometry.camera_frame_id
        self.effector = None            # (P, stamp) of the latest true effector sample
        self.image_pub = self.create_publisher(Image, 'camera/image_raw', qos_profile_sensor_data)
        self.info_pub = self.create_publisher(CameraInfo, 'camera/camera_info',
                                              qos_profile_sensor_data)
        # the truth is for scorers, which may be starved of CPU for a while: keep 8 s of frames
        self.ball_pub = self.create_publisher(PointStamped, 'sim/ball_position', 1000)
        self.create_subscription(PointStamped, 'sim/effector_position', self.on_effector,
                                 max(1, int(p['effector_queue'])))
        self.frames = camera_model.FrameClock(rate) if p['tick_on_effector'] else None
        if self.frames is None:
            self.create_timer(1.0 / rate, self.render_frame)

    def make_ball(self, p):
        if p['ball'] == 'fixed':
            return sim_ball.FixedBall(tuple(self.truth.sphere_position))
        if p['ball'] != 'chaotic':
            raise ValueError(f"ball must be 'fixed' or 'chaotic', got {p['ball']!r}")
        centre, half_size = (np.asarray(p[n], dtype=float)
                             for n in ('ball_centre', 'ball_half_size'))
        max_speed, duration = float(p['ball_max_speed']), float(p['ball_path_duration'])
        if not (max_speed > 0 and duration > 0 and centre.shape == half_size.shape == (3,)
                and np.all(half_size > 0)):
            raise ValueError('chaotic ball: need ball_max_speed > 0, ball_path_duration > 0, a '
                             'ball_centre and three positive ball_half_size (got '
                             f'{max_speed}, {duration}, {centre.tolist()}, {half_size.tolist()})')
        return sim_ball.ChaoticBall(centre, half_size, max_speed, seed=max(int(p['seed']), 0),
                                    duration=duration)

    def on_effector(self, msg):
        self.effector = (xyz(msg.point), msg.header.stamp)
        if self.frames is not None and self.frames.due(stamp_seconds(msg.header.stamp)):
            self.render_frame()

    def render_frame(self):
        """Render the ball from the latest effector sample, stamped with it; publish the truth."""
        if self.effector is None:
            self.get_logger().warn('no sim/effector_position yet: not rendering',
                                   throttle_duration_sec=5.0)
            return
        P, stamp = self.effector
        B = self.ball.at(stamp_seconds(stamp))
        C = rendered_centre(self.truth, P, B)
        image = camera_model.render(self.camera, C, self.truth.geometry.sphere_radius, self.rng,
                                    blur_sigma=self.blur, noise_sigma=self.noise)
        header = Header(stamp=stamp, frame_id=self.frame_id)
        self.image_pub.publish(image_message(image, header))
        self.info_pub.publish(camera_info_message(self.camera.camera_info_fields(), header))
        self.ball_pub.publish(point_stamped(B, stamp, BASE_FRAME))


def main(args=None):
    return spin(HandCameraNode, 'hand_camera',
                (DescriptionError, vision_camera.CameraError, ValueError), args, events=True)


if __name__ == '__main__':
    sys.exit(main())
