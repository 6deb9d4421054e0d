"""The `pbvs_tracker` node: keep the ball centred, ``distance`` ahead of the camera (calibration paper, eqs. 23-25).

Subscribes /sphere/position (geometry_msgs/PointStamped: the ball centre s in the camera optical frame,
m, stamped at the exposure) and /joint_states (motor_1..3, position = resolver increment from home,
rad). Each detection, with the joint reading nearest its exposure, goes to a pbvs.Tracker (the
ball's Kalman filter on P_est + R s, e_r = -R (s - s_d) with s_d = (0, 0, distance), and
u_r = -K_p e_r + v_p of eq. 23 clipped to max_speed), and u_r is published on /cmd_vel_cartesian
(geometry_msgs/TwistStamped, base frame, m/s, stamped with the exposure). A detection waits for a
joint reading at or after its exposure: the executor may hand over the detection before the readings
queued ahead of it, and an older reading would misplace the ball by the robot's motion since then
(5 mm at 1 m/s and 5 ms), which the filter would take for a jump of the ball.

The motion controller turns u_r into joint speeds through the same description (u_q = J_R^-1 u_r,
eq. 25, by following the integrated position with its inverse kinematics); run it with the same
description_path. Parameters: description_path (robot description YAML), kp (1/s), distance (m),
max_speed (m/s), enabled (False: publish nothing, and forget the ball), feedforward (False: no v_p,
the pure proportional law), kalman_q (m^2/s^3, the ball's white acceleration) and camera_sigma (m,
one detection's noise along optical x, y, z; default pbvs.SIGMA_CAMERA). All can be set while
running; a change restarts the ball's filter (its velocity settles again within about 20 frames).
"""
import sys
from collections import deque

import numpy as np
from geometry_msgs.msg import PointStamped, TwistStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState

from robotenis_control import pbvs
from robotenis_kinematics import description
from robotenis_kinematics.description import DescriptionError
from robotenis_kinematics.ros import joint_vector, spin, stamp_seconds

READING_MATCH_S = 0.02   # a detection needs a joint reading this close to its exposure
HISTORY = 200            # joint readings kept (0.2 s at 1 kHz)
WAITING = 10             # detections kept while their joint reading is on its way (more: readings stopped)
STAMP_TOLERANCE = 1e-6   # s: stamps travel in whole nanoseconds


class PbvsTrackerNode(Node):
    def __init__(self):
        super().__init__('pbvs_tracker')
        self.declare_parameter('description_path', description.config_path('nominal.yaml'))
        self.declare_parameter('kp', pbvs.K_P)
        self.declare_parameter('distance', float(pbvs.S_DESIRED[2]))
        self.declare_parameter('max_speed', pbvs.MAX_SPEED)
        self.declare_parameter('enabled', True)
        self.declare_parameter('feedforward', True)
        self.declare_parameter('kalman_q', pbvs.KALMAN_Q)
        self.declare_parameter('camera_sigma', list(pbvs.SIGMA_CAMERA))
        self.desc = description.load(self.get_parameter('description_path').value)
        self.enabled, self.tracker = self.make_tracker({})
        self.add_on_set_parameters_callback(self.on_parameters)
        self.readings = deque(maxlen=HISTORY)        # (stamp s, Theta)
        self.waiting = deque(maxlen=WAITING)         # (t, s, stamp) of detections ahead of their reading
        self.pub = self.create_publisher(TwistStamped, '/cmd_vel_cartesian', 10)
        # a deep queue: readings come at 1 kHz and a busy moment must not lose the one a detection needs
        self.create_subscription(JointState, '/joint_states', self.on_joint_states, HISTORY)
        self.create_subscription(PointStamped, '/sphere/position', self.on_sphere, 10)

    def make_tracker(self, changes):
        """(enabled, a new pbvs.Tracker) from the parameters with ``changes`` applied; ValueError naming a bad one."""
        get = lambda name: changes.get(name, self.get_parameter(name).value)  # noqa: E731
        kp, distance, max_speed, q = (float(get(n)) for n in ('kp', 'distance', 'max_speed', 'kalman_q'))
        sigma = np.asarray(get('camera_sigma'), dtype=float)
        if not (kp > 0 and distance > 0 and max_speed > 0 and q > 0):
            raise ValueError(f"kp, distance, max_speed and kalman_q must be positive "
                             f"(got {kp}, {distance}, {max_speed}, {q})")
        if sigma.shape != (3,) or not np.all(sigma > 0):
            raise ValueError(f"camera_sigma: expected three positive standard deviations (m), got {sigma.tolist()}")
        return bool(get('enabled')), pbvs.Tracker(self.desc, kp, [0.0, 0.0, distance], max_speed, q, sigma,
                                                  feedforward=bool(get('feedforward')))

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
        self.waiting.clear()                         # held for the tracker just replaced (or switched off)
        return SetParametersResult(successful=True)

    def on_joint_states(self, msg):
        Theta = joint_vector(msg, 'position')
        if Theta is None:
            self.get_logger().error('joint_states without positions of motor_1..3', throttle_duration_sec=1.0)
            return
        self.readings.append((stamp_seconds(msg.header.stamp), Theta))
        while self.waiting and self.waiting[0][0] <= self.readings[-1][0] + STAMP_TOLERANCE:
            self.track(*self.waiting.popleft())

    def reading_at(self, t):
        """The joint reading nearest time t, or None if none is within READING_MATCH_S."""
        if not self.readings:
            return None
        stamp, Theta = min(self.readings, key=lambda r: abs(r[0] - t))
        return Theta if abs(stamp - t) <= READING_MATCH_S else None

    def on_sphere(self, msg):
        if not self.enabled:
            return
        frame = self.desc.camera_frame_id
        if msg.header.frame_id and msg.header.frame_id != frame:
            self.get_logger().error(f'/sphere/position in frame {msg.header.frame_id!r}, expected {frame!r}: ignored',
                                    throttle_duration_sec=1.0)
            return
        s = np.array([msg.point.x, msg.point.y, msg.point.z])
        if not np.all(np.isfinite(s)):
            self.get_logger().error(f'/sphere/position not finite: {s.tolist()}', throttle_duration_sec=1.0)
            return
        t = stamp_seconds(msg.header.stamp)
        if not self.readings or self.readings[-1][0] < t - STAMP_TOLERANCE:
            self.waiting.append((t, s, msg.header.stamp))
            return
        self.track(t, s, msg.header.stamp)

    def track(self, t, s, stamp):
        """Eq. 23 for the detection s exposed at t, published as u_r."""
        Theta = self.reading_at(t)
        if Theta is None:
            self.get_logger().warn('no joint reading near the detection: not tracking', throttle_duration_sec=1.0)
            return
        command = self.tracker.update(t, s, Theta)
        if command is None:
            return                                   # repeated or out of order
        out = TwistStamped()
        out.header.stamp, out.header.frame_id = stamp, 'base'
        out.twist.linear.x, out.twist.linear.y, out.twist.linear.z = (float(v) for v in command[0])
        self.pub.publish(out)


def main(args=None):
    return spin(PbvsTrackerNode, 'pbvs_tracker', (DescriptionError,), args)


if __name__ == '__main__':
    sys.exit(main())
