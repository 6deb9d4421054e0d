"""The `motion_controller` node: Cartesian goals and velocities to drive velocity commands (eq. 11).

Subscribes /joint_states (motor_1..3, position = resolver increment from home, rad; velocity rad/s),
/goal (PointStamped, base frame, m: chained rest-to-rest 4-5-6-7 segments), /cmd_vel_cartesian
(TwistStamped, linear m/s: replaces the plan while commands keep coming) and /robot_description
(std_msgs/String, latched, e.g. from calibration). Publishes /motor_velocity_cmd (JointState, velocity
field, motor_1..3) every tick and /controller/state (PointStamped: the effector position from the
forward kinematics of the description in use) every ``state_decimation`` ticks.

Ticks come from a timer at ``rate`` (wall clock, or /clock with use_sim_time), or, with
``tick_on_joint_states``, from every joint reading (lockstep with a simulator; the command then
carries the reading's stamp). The description is reloaded by the ~/reload_description service
(std_srvs/Trigger: reads description_path again) or by setting description_path.
"""
import sys

import numpy as np
from geometry_msgs.msg import PointStamped, TwistStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rcl_interfaces.msg import SetParametersResult
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from robotenis_control import controller as ctl
from robotenis_kinematics import description
from robotenis_kinematics.description import DescriptionError
from robotenis_kinematics.ros import JOINTS, joint_vector, spin, stamp_seconds

GAIN_PARAMETERS = ('kp', 'kd', 'kv')
STALE_READING_S = 0.05   # no joint reading for this long: command zero speed (the drives then brake)


class MotionControllerNode(Node):
    def __init__(self):
        super().__init__('motion_controller')
        self.declare_parameter('description_path', description.config_path('nominal.yaml'))
        self.declare_parameter('kp', ctl.Gains.kp)
        self.declare_parameter('kd', ctl.Gains.kd)
        self.declare_parameter('kv', ctl.Gains.kv)
        self.declare_parameter('max_speed', 2.0)
        self.declare_parameter('max_acceleration', 4 * 9.81)
        self.declare_parameter('rate', 1000.0)
        self.declare_parameter('velocity_timeout', 0.1)
        self.declare_parameter('state_decimation', 10)
        self.declare_parameter('tick_on_joint_states', False)
        p = self.get_parameter
        self.controller = ctl.MotionController(
            description.load(p('description_path').value), gains=self.read_gains({}),
            max_speed=p('max_speed').value, max_acceleration=p('max_acceleration').value,
            velocity_timeout=p('velocity_timeout').value)
        self.add_on_set_parameters_callback(self.on_parameters)
        self.reading = None          # (Theta, dTheta, receive time)
        self.ticks = 0
        self.cmd_pub = self.create_publisher(JointState, '/motor_velocity_cmd', 10)
        self.state_pub = self.create_publisher(PointStamped, '/controller/state', 10)
        self.create_subscription(JointState, '/joint_states', self.on_joint_states, 10)
        self.create_subscription(PointStamped, '/goal', self.on_goal, 10)
        self.create_subscription(TwistStamped, '/cmd_vel_cartesian', self.on_velocity, 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(String, '/robot_description', self.on_description_text, latched)
        self.create_service(Trigger, '~/reload_description', self.on_reload)
        self.tick_on_joint_states = p('tick_on_joint_states').value
        self.state_decimation = max(1, int(p('state_decimation').value))
        if not self.tick_on_joint_states:
            self.create_timer(1.0 / p('rate').value, self.on_timer)

    def now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def read_gains(self, changes):
        values = {k: changes.get(k, self.get_parameter(k).value) for k in GAIN_PARAMETERS}
        return ctl.Gains(**{k: float(v) for k, v in values.items()})

    def on_parameters(self, params):
        """Apply description_path, gains and limits while running; refuse values that do not work."""
        changes = {q.name: q.value for q in params}
        try:
            if 'description_path' in changes:
                desc = description.load(changes['description_path'])
            gains = self.read_gains(changes)
            for key in ('max_speed', 'max_acceleration'):
                if key in changes and not float(changes[key]) > 0:
                    raise ValueError(f"{key} must be positive")
        except (DescriptionError, ValueError, TypeError) as e:
            return SetParametersResult(successful=False, reason=str(e))
        if 'description_path' in changes:
            self.controller.set_description(desc)
            self.get_logger().info(f"robot description from {changes['description_path']}")
        self.controller.gains = gains
        self.controller.max_speed = float(changes.get('max_speed', self.controller.max_speed))
        self.controller.max_acceleration = float(changes.get('max_acceleration', self.controller.max_acceleration))
        return SetParametersResult(successful=True)

    def on_reload(self, request, response):
        path = self.get_parameter('description_path').value
        try:
            self.controller.set_description(description.load(path))
        except DescriptionError as e:
            response.success, response.message = False, str(e)
        else:
            response.success, response.message = True, f'reloaded {path}'
        return response

    def on_description_text(self, msg):
        try:
            self.controller.set_description(description.loads(msg.data))
        except DescriptionError as e:
            self.get_logger().error(f'/robot_description ignored: {e}')
        else:
            self.get_logger().info('robot description from /robot_description')

    def on_joint_states(self, msg):
        Theta = joint_vector(msg, 'position')
        if Theta is None:
            self.get_logger().error('joint_states without positions of motor_1..3', throttle_duration_sec=1.0)
            return
        dTheta = joint_vector(msg, 'velocity')
        if self.tick_on_joint_states:
            # lockstep: the reading's stamp is the time, so /clock arriving late cannot skew it
            self.reading = (Theta, dTheta, stamp_seconds(msg.header.stamp))
            self.tick(msg.header.stamp)
        else:
            self.reading = (Theta, dTheta, self.now())

    def on_goal(self, msg):
        try:
            self.controller.add_goal([msg.point.x, msg.point.y, msg.point.z], self.now())
        except ctl.GoalError as e:
            self.get_logger().error(f'goal refused: {e}')

    def on_velocity(self, msg):
        if self.reading is None:
            return
        try:
            self.controller.set_velocity([msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z], self.now())
        except ctl.GoalError as e:
            self.get_logger().error(f'velocity command refused: {e}')

    def on_timer(self):
        self.tick(self.get_clock().now().to_msg())

    def tick(self, stamp):
        if self.reading is None:
            return
        Theta, dTheta, received = self.reading
        t = received if self.tick_on_joint_states else self.now()
        cmd = JointState(name=list(JOINTS))
        cmd.header.stamp = stamp
        if t - received > STALE_READING_S:
            self.get_logger().warn('no joint reading for 50 ms: commanding zero speed', throttle_duration_sec=1.0)
            cmd.velocity = [0.0, 0.0, 0.0]
            self.cmd_pub.publish(cmd)
            return
        ref, P_est = self.controller.update(t, Theta, dTheta)
        cmd.velocity = [float(v) for v in ref]
        self.cmd_pub.publish(cmd)
        self.ticks += 1
        if self.ticks % self.state_decimation == 0:
            state = PointStamped()
            state.header.stamp, state.header.frame_id = stamp, 'base'
            state.point.x, state.point.y, state.point.z = (float(v) for v in P_est)
            self.state_pub.publish(state)


def main(args=None):
    return spin(MotionControllerNode, 'motion_controller', (DescriptionError,), args)


if __name__ == '__main__':
    sys.exit(main())
