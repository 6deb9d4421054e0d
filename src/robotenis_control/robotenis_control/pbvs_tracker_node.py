"""
The `pbvs_tracker` node: keep the ball centred, ``distance`` ahead of the camera (eqs. 23-25).

Subscribes sphere/position (geometry_msgs/PointStamped: the ball centre s in the camera optical
frame, m, stamped at the exposure) and joint_states (motor_1..3, position = resolver increment
from home, rad). Each detection, with the joint reading of its exposure (pbvs.ReadingMatcher),
goes to a pbvs.Tracker (the ball's Kalman filter on P_est + R s, e_r = -R (s - s_d) with
s_d = (0, 0, distance), and u_r = -K_p e_r + v_p of eq. 23 clipped to max_speed), and u_r is
published on cmd_vel_cartesian (geometry_msgs/TwistStamped, base frame, m/s, stamped with the
exposure).

The motion controller turns u_r into joint speeds through the same description (u_q = J_R^-1 u_r,
eq. 25, by following the integrated position with its inverse kinematics); run it with the same
description_path. Parameters: the table PARAMETERS. All can be set while running; a change
restarts the ball's filter (its velocity settles again within about 20 frames).
"""
import sys

from geometry_msgs.msg import PointStamped, TwistStamped
import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from robotenis_control import pbvs
from robotenis_kinematics import description
from robotenis_kinematics.description import DescriptionError
from robotenis_ros.convert import joint_vector, stamp_seconds, twist_stamped, xyz
from robotenis_ros.names import BASE_FRAME
from robotenis_ros.node import declare_parameters, spin
from sensor_msgs.msg import JointState

# joint readings kept (2 s at 1 kHz): a frame the loop leaves unanswered lets the simulator run
# on unlocked, its readings ahead of the detections; a detection older than every reading kept
# is not paired, not answered, and the loop stays unlocked (a CI run: 'no joint reading near
# the detection' and the ball not acquired in 5 s of simulated time, with 200 kept)
HISTORY = 2000
PARAMETERS = {
    'description_path': (description.config_path('nominal.yaml'), 'the robot description YAML'),
    'kp': (pbvs.K_P, '1/s: K_p of eq. 23'),
    'distance': (float(pbvs.S_DESIRED[2]), 'm: the ball is kept this far ahead, centred'),
    'max_speed': (pbvs.MAX_SPEED, 'm/s: u_r is clipped to this'),
    'enabled': (True, 'false: publish nothing, and forget the ball'),
    'feedforward': (True, 'false: no v_p, the pure proportional law'),
    'kalman_q': (pbvs.KALMAN_Q, "m^2/s^3: the ball's white acceleration"),
    'camera_sigma': (list(pbvs.SIGMA_CAMERA), "m: one detection's noise along optical x, y, z"),
}


class PbvsTrackerNode(Node):

    def __init__(self):
        super().__init__('pbvs_tracker')
        p = declare_parameters(self, PARAMETERS)
        self.desc = description.load(p['description_path'])
        self.enabled, self.tracker = self.make_tracker({})
        self.add_on_set_parameters_callback(self.on_parameters)
        self.matcher = pbvs.ReadingMatcher(history=HISTORY)
        self.pub = self.create_publisher(TwistStamped, 'cmd_vel_cartesian', 10)
        # a deep queue: readings come at 1 kHz and a busy moment must not lose the one a
        # detection needs
        self.create_subscription(JointState, 'joint_states', self.on_joint_states, HISTORY)
        self.create_subscription(PointStamped, 'sphere/position', self.on_sphere, 10)

    def make_tracker(self, changes):
        """Return (enabled, a new pbvs.Tracker) after ``changes``; ValueError names a bad one."""
        def get(name):
            return changes.get(name, self.get_parameter(name).value)
        kp, distance, max_speed, q = (float(get(n))
                                      for n in ('kp', 'distance', 'max_speed', 'kalman_q'))
        sigma = np.asarray(get('camera_sigma'), dtype=float)
        if not (kp > 0 and distance > 0 and max_speed > 0 and q > 0):
            raise ValueError('kp, distance, max_speed and kalman_q must be positive '
                             f'(got {kp}, {distance}, {max_speed}, {q})')
        if sigma.shape != (3,) or not np.all(sigma > 0):
            raise ValueError('camera_sigma: expected three positive standard deviations (m), '
                             f'got {sigma.tolist()}')
        return bool(get('enabled')), pbvs.Tracker(self.desc, kp, [0.0, 0.0, distance], max_speed,
                                                  q, sigma, feedforward=bool(get('feedforward')))

    def on_parameters(self, params):
        changes = {p.name: p.value for p in params}
        previous = self.desc
        try:
            if 'description_path' in changes:
                self.desc = description.load(changes['description_path'])
            self.enabled, self.tracker = self.make_tracker(changes)
        except (DescriptionError, ValueError, TypeError) as e:
            self.desc = previous
            return SetParametersResult(successful=False, reason=str(e))
        self.matcher.clear()                 # held for the tracker just replaced (or switched off)
        return SetParametersResult(successful=True)

    def on_joint_states(self, msg):
        Theta = joint_vector(msg, 'position')
        if Theta is None:
            self.get_logger().error('joint_states without positions of motor_1..3',
                                    throttle_duration_sec=1.0)
            return
        for pair in self.matcher.reading(stamp_seconds(msg.header.stamp), Theta):
            self.track(*pair)

    def on_sphere(self, msg):
        if not self.enabled:
            return
        frame = self.desc.camera_frame_id
        if msg.header.frame_id and msg.header.frame_id != frame:
            self.get_logger().error(f'sphere/position in frame {msg.header.frame_id!r}, '
                                    f'expected {frame!r}: ignored', throttle_duration_sec=1.0)
            return
        s = xyz(msg.point)
        if not np.all(np.isfinite(s)):
            self.get_logger().error(f'sphere/position not finite: {s.tolist()}',
                                    throttle_duration_sec=1.0)
            return
        for pair in self.matcher.detection(stamp_seconds(msg.header.stamp), s, msg.header.stamp):
            self.track(*pair)

    def track(self, t, s, stamp, Theta):
        """Eq. 23 for the detection s exposed at t, seen from the joint reading Theta."""
        if Theta is None:
            self.get_logger().warn('no joint reading near the detection: not tracking',
                                   throttle_duration_sec=1.0)
            return
        command = self.tracker.update(t, s, Theta)
        if command is not None:                      # None: repeated or out of order
            self.pub.publish(twist_stamped(command[0], stamp, BASE_FRAME))


def main(args=None):
    return spin(PbvsTrackerNode, 'pbvs_tracker', (DescriptionError,), args, events=True)


if __name__ == '__main__':
    sys.exit(main())
