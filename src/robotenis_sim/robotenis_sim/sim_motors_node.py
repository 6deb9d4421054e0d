"""
The `sim_motors` node: the simulated robot behind the drives and resolvers (robotenis_sim.motors).

Subscribes motor_velocity_cmd (JointState velocity, motor_1..3, rad/s at the joints) and
publishes joint_states at ``rate`` (position = resolver increment from home, rad; velocity = the
drives' speed estimate, rad/s). Ground truth, for scoring only, goes to sim/effector_position
(PointStamped, base frame, m) every ``truth_decimation`` steps (default 4: 250 Hz, faster than the
120 Hz camera that renders from it).

The true geometry and masses come from the truth file (``truth_path``; the default truth when
empty) or, if ``description_path`` is set, from a robot description with nominal masses.

Clock modes (robotenis_sim.lockstep): wall (default), a steady timer running the steps due; or
simulated (``publish_clock``): the node owns /clock and publishes the simulated time every
``clock_decimation`` steps, ``speed`` simulated seconds per wall second (0: as fast as possible),
with ``lockstep`` one step per command answering the last reading, and with ``camera_rate`` > 0
the visual lockstep that waits for each frame's answer: the tracking loop's cmd_vel_cartesian
(``visual_answer`` 'command'), or the detector's sphere/position ('detection'), and with
``visual_rest_speed`` > 0 only while every arm turns slower than that. A calibration session
waits for the detector at rest: it runs on the wall clock, and its accurate fit at rest takes
longer than a frame, so a simulator faster than real time would run ahead of it, make frames for
it to drop and simulated time for every node to spend (1.9 s of simulated time per rest instead
of 0.6 s), and the session's time-outs, in simulated time, would skip poses it had not measured
yet. Every node on /clock pays for each clock message (about 0.1 ms in rclpy): 250 Hz is enough
for the nodes' timers and costs a quarter of 1 kHz. The joint states and the commands, 1 kHz each
way in lockstep, are written and read as CDR bytes (robotenis_ros.cdr): the lockstep round trip
is what bounds a session's simulated time per wall second.
"""
import sys

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, TwistStamped
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from robotenis_control.dynamics import MassParameters
from robotenis_kinematics import description
from robotenis_kinematics.description import DescriptionError
from robotenis_ros import cdr
from robotenis_ros.convert import point_stamped, stamp_seconds
from robotenis_ros.names import BASE_FRAME, JOINTS
from robotenis_ros.node import declare_parameters, spin
from robotenis_sim import lockstep, motors, truth as sim_truth
from robotenis_sim.motors import true_masses
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState

PARAMETERS = {
    'truth_path': ('', "the simulator's truth file (empty: robotenis_sim's default truth)"),
    'description_path': ('', 'if set, the true geometry from this robot description, '
                             'nominal masses'),
    'rate': (1000.0, 'Hz: steps and joint readings'),
    'substeps': (1, 'RK4 steps per control period'),
    'resolver_noise': (motors.ResolverParameters.noise, 'rad: white noise of a reading'),
    'resolver_counts': (motors.ResolverParameters.counts_per_rev, 'counts per motor revolution'),
    'gear_ratio': (motors.ResolverParameters.gear_ratio, 'motor turns per joint turn'),
    'kv': (motors.DriveParameters.K_V, "N m s/rad: the drives' velocity gain (eq. 10)"),
    'torque_limit': (motors.DriveParameters.torque_limit, 'N m: peak joint torque'),
    'seed': (-1, 'random seed of the resolver noise (-1: random)'),
    'publish_clock': (False, 'own /clock: run on simulated time'),
    'speed': (1.0, 'simulated seconds per wall second on simulated time (0: as fast as possible)'),
    'lockstep': (False, 'one step per command answering the last reading'),
    'lockstep_timeout': (0.1, 'wall s to wait for that command before stepping on'),
    'truth_decimation': (4, 'steps per sim/effector_position sample'),
    'clock_decimation': (1, 'steps per /clock message'),
    'max_catch_up': (10, 'most steps run at once on the wall clock'),
    'camera_rate': (0.0, 'Hz: visual lockstep on the frames of this rate (0: off)'),
    'visual_delay': (1.0 / 120.0, 's: a frame must be answered within this simulated time'),
    'visual_timeout': (0.1, "wall s to wait for a frame's command"),
    'visual_answer': ('command', "what answers a frame in visual lockstep: 'command' "
                                 "(cmd_vel_cartesian) or 'detection' (sphere/position)"),
    'visual_rest_speed': (0.0, 'rad/s: in visual lockstep, wait for frames only while every arm '
                               'turns slower than this (0: always)'),
}
VISUAL_ANSWERS = {'command': (TwistStamped, 'cmd_vel_cartesian'),
                  'detection': (PointStamped, 'sphere/position')}


class SimMotorsNode(Node):

    def __init__(self):
        super().__init__('sim_motors')
        p = declare_parameters(self, PARAMETERS)
        geometry, mass, joint_effects = self.load_truth(p['truth_path'], p['description_path'])
        rate = float(p['rate'])
        if not rate > 0:
            raise ValueError(f'rate must be positive, got {rate}')
        seed = int(p['seed'])
        resolver = motors.ResolverParameters(int(p['resolver_counts']), float(p['gear_ratio']),
                                             float(p['resolver_noise']))
        self.sim = motors.SimulatedMotors(
            geometry, mass, motors.DriveParameters(float(p['kv']), float(p['torque_limit'])),
            resolver, dt=1.0 / rate, substeps=int(p['substeps']),
            rng=np.random.default_rng(None if seed < 0 else seed), joint_effects=joint_effects)
        self.publish_clock = p['publish_clock']
        self.schedule = lockstep.StepSchedule(lockstep.ScheduleParameters(
            dt=self.sim.dt, simulated=self.publish_clock, speed=float(p['speed']),
            lockstep=p['lockstep'], lockstep_timeout=float(p['lockstep_timeout']),
            max_catch_up=int(p['max_catch_up']), camera_rate=float(p['camera_rate']),
            visual_delay=float(p['visual_delay']), visual_timeout=float(p['visual_timeout'])))
        self.truth_decimation = max(1, int(p['truth_decimation']))
        self.clock_decimation = max(1, int(p['clock_decimation']))
        self.joint_pub = self.create_publisher(JointState, 'joint_states', 10)
        # the truth is for scorers, which may be starved of CPU for a while (a pytest probe on two
        # cores beside five nodes once missed 0.6 s): keep 4 s of samples for them
        self.truth_pub = self.create_publisher(PointStamped, 'sim/effector_position', 1000)
        self.clock_pub = (self.create_publisher(ClockMsg, '/clock', 10) if self.publish_clock
                          else None)
        self.readings = cdr.JointStateWriter(JOINTS)
        self.commands = cdr.JointStateReader(JOINTS)
        self.create_subscription(JointState, 'motor_velocity_cmd', self.on_command, 10, raw=True)
        if p['visual_answer'] not in VISUAL_ANSWERS:
            raise ValueError(f"visual_answer must be one of {', '.join(VISUAL_ANSWERS)}, "
                             f"got {p['visual_answer']!r}")
        self.rest_speed = float(p['visual_rest_speed'])
        if self.schedule.frames is not None:
            answer_type, topic = VISUAL_ANSWERS[p['visual_answer']]
            self.create_subscription(answer_type, topic, self.on_visual_command, 10)
        self.steps = 0
        self.last_stamp = None
        self.publish_reading(self.sim.read())
        speed = float(p['speed'])
        period = 1.0 / rate if not self.publish_clock or speed <= 0 else 1.0 / (rate * speed)
        # in lockstep the commands step the simulation; the timer only watches for a missing one
        period = float(p['lockstep_timeout']) / 4 if p['lockstep'] else min(period, 1e-3)
        self.create_timer(period, self.on_timer, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def load_truth(self, truth_path, description_path):
        """Return (geometry, masses, joint effects hook) of the simulated robot."""
        if description_path:
            self.get_logger().info(f'true geometry from the robot description {description_path}, '
                                   'nominal masses')
            return description.load(description_path), MassParameters(), None
        truth = sim_truth.load(truth_path or None)
        joint = set(truth.effects) & set(sim_truth.JOINT_EFFECTS)
        if joint:
            self.get_logger().info('undeclared joint effects simulated: '
                                   f"{', '.join(sorted(joint))}")
        return (truth.geometry, true_masses(truth),
                sim_truth.JointReadings(truth) if joint else None)

    def stamp(self):
        """Return the time of the reading (sec, nanosec): simulated, or the node's clock."""
        if self.publish_clock:
            return divmod(int(round(self.sim.t * 1e9)), 1_000_000_000)
        return self.get_clock().now().seconds_nanoseconds()

    def on_command(self, data):
        command = self.commands.read(data)
        if command is None or command[3] is None:
            self.get_logger().error('motor_velocity_cmd without velocities of motor_1..3',
                                    throttle_duration_sec=1.0)
            return
        sec, nanosec, _, velocity = command
        try:
            self.sim.set_command(velocity)
        except ValueError as e:
            self.get_logger().error(str(e), throttle_duration_sec=1.0)
            return
        if self.schedule.p.lockstep and (sec, nanosec) == self.last_stamp:
            self.schedule.answer()
            self.on_timer()             # step at once: lockstep runs as fast as the two nodes can

    def on_visual_command(self, msg):
        if self.schedule.visual_answer(stamp_seconds(msg.header.stamp)):
            self.on_timer()             # the step that waited for this answer

    def on_timer(self):
        still = self.rest_speed <= 0 or max(map(abs, self.sim.dalpha)) < self.rest_speed
        n, notes = self.schedule.due(self.sim.t, self.steps, still)
        for note in notes:
            self.get_logger().warn(note, throttle_duration_sec=1.0)
        for _ in range(n):
            self.sim.step()
            self.steps += 1
            reading = self.sim.read()   # every step: the speed estimate differentiates readings
        if n:
            self.publish_reading(reading)

    def publish_reading(self, reading):
        sec, nanosec = self.last_stamp = self.stamp()
        if self.clock_pub is not None and self.steps % self.clock_decimation == 0:
            self.clock_pub.publish(ClockMsg(clock=Time(sec=sec, nanosec=nanosec)))
        Theta, dTheta = reading
        self.schedule.published()
        self.joint_pub.publish(self.readings(sec, nanosec, position=Theta, velocity=dTheta))
        if self.steps % self.truth_decimation == 0:
            stamp = Time(sec=sec, nanosec=nanosec)
            self.schedule.sampled(stamp_seconds(stamp))
            self.truth_pub.publish(point_stamped(self.sim.effector()[0], stamp, BASE_FRAME))


def main(args=None):
    return spin(SimMotorsNode, 'sim_motors', (DescriptionError, ValueError), args, events=True)


if __name__ == '__main__':
    sys.exit(main())
