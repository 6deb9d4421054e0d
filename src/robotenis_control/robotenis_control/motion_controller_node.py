"""
The `motion_controller` node: Cartesian goals and velocities to drive velocity commands (eq. 11).

Subscribes joint_states (motor_1..3, position = resolver increment from home, rad; velocity rad/s),
goal (PointStamped, base frame, m: chained rest-to-rest 4-5-6-7 segments), cmd_vel_cartesian
(TwistStamped, linear m/s: replaces the plan while commands keep coming) and robot_description
(std_msgs/String, latched, e.g. from calibration). Publishes motor_velocity_cmd (JointState,
velocity field, motor_1..3) every tick and controller/state (PointStamped: the effector position
from the forward kinematics of the description in use) every ``state_decimation`` ticks.

Ticks come from a timer at ``rate`` (wall clock, or /clock with use_sim_time), or, with
``tick_on_joint_states``, from every joint reading (lockstep with a simulator; the command then
carries the reading's stamp, and the node's time, for goals and velocity commands too, is the
last reading's stamp: it needs no /clock). The joint states and the commands are read and written
as CDR bytes (robotenis_ros.cdr): at 1 kHz in lockstep, rclpy's messages took each side about 1.8x
the CPU and the round trip twice the wall time (``./robotenis bench transport``). The description
is reloaded by the ~/reload_description service (std_srvs/Trigger: reads description_path again)
or by setting description_path.
"""
import sys

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, TwistStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from robotenis_control import controller as ctl
from robotenis_kinematics import description
from robotenis_kinematics.description import DescriptionError
from robotenis_ros import cdr
from robotenis_ros.convert import point_stamped, xyz
from robotenis_ros.names import BASE_FRAME, JOINTS
from robotenis_ros.node import declare_parameters, LATCHED, spin
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

GAIN_PARAMETERS = ('kp', 'kd', 'kv')
AT_START_ONLY = ('rate', 'state_decimation', 'tick_on_joint_states')   # they shape the node itself
STALE_READING_S = 0.05   # no joint reading for this long: command zero speed (the drives brake)
PARAMETERS = {
    'description_path': (description.config_path('nominal.yaml'), 'the robot description YAML'),
    'kp': (ctl.Gains.kp, '1/s: gain on the joint position error (eq. 11)'),
    'kd': (ctl.Gains.kd, 'gain on the joint velocity error (eq. 11)'),
    'kv': (ctl.Gains.kv, "N m s/rad: the controller's value of the drives' K_V (eq. 10)"),
    'max_speed': (2.0, 'm/s: top speed of the planned segments and of velocity commands'),
    'max_acceleration': (4 * 9.81, 'm/s^2: top acceleration of the planned segments'),
    'rate': (1000.0, 'Hz: control ticks (without tick_on_joint_states)'),
    'velocity_timeout': (0.1, 's a velocity command holds before the position is held'),
    'state_decimation': (10, 'ticks per controller/state message'),
    'tick_on_joint_states': (False, 'tick on every joint reading (lockstep with a simulator)'),
}


class MotionControllerNode(Node):

    def __init__(self):
        super().__init__('motion_controller')
        p = declare_parameters(self, PARAMETERS)
        self.controller = ctl.MotionController(
            description.load(p['description_path']), gains=self.read_gains({}),
            max_speed=p['max_speed'], max_acceleration=p['max_acceleration'],
            velocity_timeout=p['velocity_timeout'])
        self.add_on_set_parameters_callback(self.on_parameters)
        self.reading = None          # (Theta, dTheta, receive time)
        self.ticks = 0
        self.readings = cdr.JointStateReader(JOINTS)
        self.commands = cdr.JointStateWriter(JOINTS, fields=('velocity',))
        self.cmd_pub = self.create_publisher(JointState, 'motor_velocity_cmd', 10)
        self.state_pub = self.create_publisher(PointStamped, 'controller/state', 10)
        self.create_subscription(JointState, 'joint_states', self.on_joint_states, 10, raw=True)
        self.create_subscription(PointStamped, 'goal', self.on_goal, 10)
        self.create_subscription(TwistStamped, 'cmd_vel_cartesian', self.on_velocity, 10)
        self.create_subscription(String, 'robot_description', self.on_description_text, LATCHED)
        self.create_service(Trigger, '~/reload_description', self.on_reload)
        self.tick_on_joint_states = p['tick_on_joint_states']
        self.state_decimation = max(1, int(p['state_decimation']))
        if not self.tick_on_joint_states:
            self.create_timer(1.0 / p['rate'], self.on_timer)

    def now(self):
        if self.tick_on_joint_states and self.reading is not None:
            return self.reading[2]
        return self.get_clock().now().nanoseconds * 1e-9

    def read_gains(self, changes):
        values = {k: changes.get(k, self.get_parameter(k).value) for k in GAIN_PARAMETERS}
        return ctl.Gains(**{k: float(v) for k, v in values.items()})

    def on_parameters(self, params):
        """Apply description_path, gains, limits and timeout while running; refuse the others."""
        changes = {q.name: q.value for q in params}
        fixed = sorted(set(changes) & set(AT_START_ONLY))
        if fixed:
            return SetParametersResult(successful=False,
                                       reason=f'{", ".join(fixed)}: set at start only')
        try:
            if 'description_path' in changes:
                desc = description.load(changes['description_path'])
            gains = self.read_gains(changes)
            for key in ('max_speed', 'max_acceleration', 'velocity_timeout'):
                if key in changes and not float(changes[key]) > 0:
                    raise ValueError(f'{key} must be positive')
        except (DescriptionError, ValueError, TypeError) as e:
            return SetParametersResult(successful=False, reason=str(e))
        if 'description_path' in changes:
            self.controller.set_description(desc)
            self.get_logger().info(f"robot description from {changes['description_path']}")
        self.controller.gains = gains
        self.controller.max_speed = float(changes.get('max_speed', self.controller.max_speed))
        self.controller.max_acceleration = float(changes.get('max_acceleration',
                                                             self.controller.max_acceleration))
        self.controller.velocity_timeout = float(changes.get('velocity_timeout',
                                                             self.controller.velocity_timeout))
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

    def on_joint_states(self, data):
        reading = self.readings.read(data)
        if reading is None or reading[2] is None:
            self.get_logger().error('joint_states without positions of motor_1..3',
                                    throttle_duration_sec=1.0)
            return
        sec, nanosec, Theta, dTheta = reading
        if self.tick_on_joint_states:
            # lockstep: the reading's stamp is the time, so /clock arriving late cannot skew it
            self.reading = (Theta, dTheta, sec + nanosec * 1e-9)
            self.tick((sec, nanosec))
        else:
            self.reading = (Theta, dTheta, self.now())

    def on_goal(self, msg):
        try:
            self.controller.add_goal(xyz(msg.point), self.now())
        except ctl.GoalError as e:
            self.get_logger().error(f'goal refused: {e}')

    def on_velocity(self, msg):
        if self.reading is None:
            return
        try:
            self.controller.set_velocity(xyz(msg.twist.linear), self.now())
        except ctl.GoalError as e:
            self.get_logger().error(f'velocity command refused: {e}')

    def on_timer(self):
        self.tick(self.get_clock().now().seconds_nanoseconds())

    def tick(self, stamp):
        """Command the drives for the last reading; ``stamp``: the command's (sec, nanosec)."""
        if self.reading is None:
            return
        Theta, dTheta, received = self.reading
        t = received if self.tick_on_joint_states else self.now()
        if t - received > STALE_READING_S:
            self.get_logger().warn(f'no joint reading for {STALE_READING_S * 1e3:.0f} ms: '
                                   'commanding zero speed',
                                   throttle_duration_sec=1.0)
            self.cmd_pub.publish(self.commands(*stamp, velocity=(0.0, 0.0, 0.0)))
            return
        ref, P_est = self.controller.update(t, Theta, dTheta)
        self.cmd_pub.publish(self.commands(*stamp, velocity=ref))
        self.ticks += 1
        if self.ticks % self.state_decimation == 0:
            self.state_pub.publish(point_stamped(P_est, Time(sec=stamp[0], nanosec=stamp[1]),
                                                 BASE_FRAME))


def main(args=None):
    return spin(MotionControllerNode, 'motion_controller', (DescriptionError,), args,
                events=True)


if __name__ == '__main__':
    sys.exit(main())
