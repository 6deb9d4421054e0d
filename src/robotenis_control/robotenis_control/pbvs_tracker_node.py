"""The `pbvs_tracker` node: keep the ball centred, ``distance`` ahead of the camera (calibration paper, eqs. 23-25).

Subscribes /sphere/position (geometry_msgs/PointStamped: the ball centre s in the camera optical frame,
m, stamped at the exposure) and /joint_states (motor_1..3, position = resolver increment from home,
rad). For each detection:

- the ball's base-frame position P_est + R s, with P_est the forward kinematics of the description on
  the joint reading nearest the exposure and R the description's camera rotation, goes into the ball's
  Kalman filter (pbvs.BallKalman), which gives its velocity v_p;
- e_r = -R (s - s_d), s_d = (0, 0, distance), and u_r = -K_p e_r + v_p (eq. 23), clipped to max_speed,
  is published on /cmd_vel_cartesian (geometry_msgs/TwistStamped, base frame, m/s).

The motion controller turns u_r into joint speeds through the same description (u_q = J_R^-1 u_r,
eq. 25, by following the integrated position with its inverse kinematics); run it with the same
description_path. Parameters: description_path (robot description YAML), kp (1/s), distance (m),
max_speed (m/s), enabled (False: publish nothing, and forget the ball), kalman_q (m^2/s^3, the ball's
white acceleration) and camera_sigma (m, one detection's noise along optical x, y, z; the default is
the calibration paper's Table 2 for single frames at 200 mm, scaled to 600 mm). All can be set while
running; a new description_path is loaded at once.
"""
import sys
from collections import deque

import numpy as np
from geometry_msgs.msg import PointStamped, TwistStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.time import Time
from sensor_msgs.msg import JointState

from robotenis_control import pbvs
from robotenis_kinematics import delta, description
from robotenis_kinematics.description import DescriptionError
from robotenis_kinematics.ros import joint_vector, spin
from robotenis_kinematics.synthetic import NoiseModel

READING_MATCH_S = 0.02   # a detection needs a joint reading this close to its exposure
LOST_S = 0.5             # no detection for this long: the ball's filter starts again
HISTORY = 200            # joint readings kept (0.2 s at 1 kHz)


def stamp_seconds(stamp):
    return Time.from_msg(stamp).nanoseconds * 1e-9


def clip_speed(u, max_speed):
    """u scaled down to max_speed if it is faster (m/s)."""
    speed = float(np.linalg.norm(u))
    return u * (max_speed / speed) if speed > max_speed else u


class PbvsTrackerNode(Node):
    def __init__(self):
        super().__init__('pbvs_tracker')
        self.declare_parameter('description_path', description.config_path('nominal.yaml'))
        self.declare_parameter('kp', pbvs.K_P)
        self.declare_parameter('distance', float(pbvs.S_DESIRED[2]))
        self.declare_parameter('max_speed', 2.5)
        self.declare_parameter('enabled', True)
        self.declare_parameter('kalman_q', pbvs.BallKalman().q)
        self.declare_parameter('camera_sigma', [0.042e-3, 0.114e-3, 0.83e-3])
        self.desc = description.load(self.get_parameter('description_path').value)
        self.settings = self.check({})
        self.add_on_set_parameters_callback(self.on_parameters)
        self.readings = deque(maxlen=HISTORY)        # (stamp s, Theta)
        self.kalman, self.last_stamp = None, None
        self.pub = self.create_publisher(TwistStamped, '/cmd_vel_cartesian', 10)
        self.create_subscription(JointState, '/joint_states', self.on_joint_states, 10)
        self.create_subscription(PointStamped, '/sphere/position', self.on_sphere, 10)

    def check(self, changes):
        """The numeric settings with ``changes`` applied; ValueError naming a bad one."""
        get = lambda name: changes.get(name, self.get_parameter(name).value)  # noqa: E731
        kp, distance, max_speed, q = (float(get(n)) for n in ('kp', 'distance', 'max_speed', 'kalman_q'))
        sigma = np.asarray(get('camera_sigma'), dtype=float)
        if not (kp > 0 and distance > 0 and max_speed > 0 and q > 0):
            raise ValueError(f"kp, distance, max_speed and kalman_q must be positive "
                             f"(got {kp}, {distance}, {max_speed}, {q})")
        if sigma.shape != (3,) or not np.all(sigma > 0):
            raise ValueError(f"camera_sigma: expected three positive standard deviations (m), got {sigma.tolist()}")
        return {'kp': kp, 's_d': np.array([0.0, 0.0, distance]), 'max_speed': max_speed, 'q': q,
                'cov': NoiseModel(sigma_camera=tuple(sigma)).cov_Pi(self.desc.camera_rotation),
                'enabled': bool(get('enabled'))}

    def on_parameters(self, params):
        changes = {p.name: p.value for p in params}
        previous = self.desc
        try:
            if 'description_path' in changes:
                self.desc = description.load(changes['description_path'])
            settings = self.check(changes)
        except (DescriptionError, ValueError, TypeError) as e:
            self.desc = previous
            return SetParametersResult(successful=False, reason=str(e))
        if settings['q'] != self.settings['q'] or self.desc is not previous or not settings['enabled']:
            self.kalman = None        # a new model or a pause: the ball's estimate starts again
        self.settings = settings
        return SetParametersResult(successful=True)

    def on_joint_states(self, msg):
        Theta = joint_vector(msg, 'position')
        if Theta is None:
            self.get_logger().error('joint_states without positions of motor_1..3', throttle_duration_sec=1.0)
            return
        self.readings.append((stamp_seconds(msg.header.stamp), Theta))

    def reading_at(self, t):
        """The joint reading nearest time t, or None if none is within READING_MATCH_S."""
        if not self.readings:
            return None
        stamp, Theta = min(self.readings, key=lambda r: abs(r[0] - t))
        return Theta if abs(stamp - t) <= READING_MATCH_S else None

    def on_sphere(self, msg):
        if not self.settings['enabled']:
            return
        frame = self.desc.camera_frame_id
        if msg.header.frame_id and msg.header.frame_id != frame:
            self.get_logger().error(f'/sphere/position in frame {msg.header.frame_id!r}, expected {frame!r}: ignored',
                                    throttle_duration_sec=1.0)
            return
        t = stamp_seconds(msg.header.stamp)
        Theta = self.reading_at(t)
        if Theta is None:
            self.get_logger().warn('no joint reading near the detection: not tracking', throttle_duration_sec=1.0)
            return
        s = np.array([msg.point.x, msg.point.y, msg.point.z])
        if not np.all(np.isfinite(s)):
            self.get_logger().error(f'/sphere/position not finite: {s.tolist()}', throttle_duration_sec=1.0)
            return
        if self.last_stamp is not None and t <= self.last_stamp:
            return                                   # repeated or out of order
        v_p = self.ball_velocity(t, s, Theta)
        u_r = clip_speed(pbvs.cartesian_command(pbvs.relative_error(s, self.desc.camera_rotation, self.settings['s_d']),
                                                v_p, self.settings['kp']), self.settings['max_speed'])
        out = TwistStamped()
        out.header.stamp, out.header.frame_id = msg.header.stamp, 'base'
        out.twist.linear.x, out.twist.linear.y, out.twist.linear.z = (float(v) for v in u_r)
        self.pub.publish(out)

    def ball_velocity(self, t, s, Theta):
        """v_p after fusing the ball's base-frame position P_est + R s measured at time t."""
        if self.kalman is None or t - self.last_stamp > LOST_S:
            self.kalman = pbvs.BallKalman(self.settings['q'])
        elif self.kalman.x is not None:
            self.kalman.predict(t - self.last_stamp)
        P_est = delta.forward(self.desc, self.desc.theta0 + Theta)
        self.kalman.update(P_est + self.desc.camera_rotation @ s, self.settings['cov'])
        self.last_stamp = t
        return self.kalman.velocity


def main(args=None):
    return spin(PbvsTrackerNode, 'pbvs_tracker', (DescriptionError,), args)


if __name__ == '__main__':
    sys.exit(main())
