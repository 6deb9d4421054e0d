"""The `sim_motors` node: the simulated robot behind the drives and resolvers (robotenis_sim.motors).

Subscribes /motor_velocity_cmd (JointState velocity, motor_1..3, rad/s at the joints) and publishes
/joint_states at ``rate`` (position = resolver increment from home, rad; velocity = the drives' speed
estimate, rad/s). Ground truth, for scoring only, goes to /sim/effector_position (PointStamped,
base frame, m) every ``truth_decimation`` steps (default 4: 250 Hz, faster than the 120 Hz camera
that renders from it).

The true geometry and masses come from the truth file (``truth_path``; the default truth when empty)
or, if ``description_path`` is set, from a robot description with nominal masses.

Clock modes:
* wall (default): a steady timer; each callback runs the steps due since the start (at most
  ``max_catch_up``, so a stalled process does not burst), stamped with the node's clock.
* simulated (``publish_clock``): the node owns /clock and publishes the simulated time every
  ``clock_decimation`` steps, ``speed`` simulated seconds per wall second (0: as fast as possible).
  With ``lockstep`` every step waits (at most ``lockstep_timeout`` wall seconds) for the command
  answering the last reading, so a controller with use_sim_time and tick_on_joint_states runs
  exactly once per step at any speed. Every node on /clock pays for each clock message (about
  0.1 ms in rclpy): 250 Hz is enough for a 120 Hz camera and costs a quarter of 1 kHz.
* visual lockstep (``camera_rate`` > 0, with lockstep): the hand camera (tick_on_effector, same
  rate) exposes the first truth sample at or after each k / camera_rate. The simulator does not
  step past an exposure plus ``visual_delay`` until a /cmd_vel_cartesian stamped with it (or later)
  has arrived, waiting at most ``visual_timeout`` wall seconds: the visual loop (camera, detector,
  tracker) then acts within visual_delay of simulated time whatever the load, as a real camera
  pipeline acts within its frame. It waits only while the loop answers: after a frame without an
  answer (ball lost, tracker off) it lets frames go by unwaited until the next answer.
"""
import math
import sys
import time
from collections import deque

import numpy as np
from geometry_msgs.msg import PointStamped, TwistStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.time import Time
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState

from robotenis_control.dynamics import MassParameters
from robotenis_kinematics import description
from robotenis_kinematics.description import DescriptionError
from robotenis_kinematics.ros import JOINTS, spin, stamp_seconds
from robotenis_sim import camera_model, motors, truth as sim_truth
from robotenis_sim.motors import true_masses



class SimMotorsNode(Node):
    def __init__(self):
        super().__init__('sim_motors')
        for name, default in (('truth_path', ''), ('description_path', ''), ('rate', 1000.0), ('substeps', 1),
                              ('resolver_noise', motors.ResolverParameters.noise),
                              ('resolver_counts', motors.ResolverParameters.counts_per_rev),
                              ('gear_ratio', motors.ResolverParameters.gear_ratio),
                              ('kv', motors.DriveParameters.K_V), ('torque_limit', motors.DriveParameters.torque_limit),
                              ('seed', -1), ('publish_clock', False), ('speed', 1.0), ('lockstep', False),
                              ('lockstep_timeout', 0.1), ('truth_decimation', 4), ('clock_decimation', 1),
                              ('max_catch_up', 10), ('camera_rate', 0.0), ('visual_delay', 1.0 / 120.0),
                              ('visual_timeout', 0.1)):
            self.declare_parameter(name, default)
        p = lambda name: self.get_parameter(name).value  # noqa: E731 - short accessor
        geometry, mass, joint_effects = self.load_truth(p('truth_path'), p('description_path'))
        rate = float(p('rate'))
        if not rate > 0:
            raise ValueError(f"rate must be positive, got {rate}")
        seed = int(p('seed'))
        self.sim = motors.SimulatedMotors(
            geometry, mass, motors.DriveParameters(float(p('kv')), float(p('torque_limit'))),
            motors.ResolverParameters(int(p('resolver_counts')), float(p('gear_ratio')), float(p('resolver_noise'))),
            dt=1.0 / rate, substeps=int(p('substeps')), rng=np.random.default_rng(None if seed < 0 else seed),
            joint_effects=joint_effects)
        self.publish_clock, self.speed, self.lockstep = p('publish_clock'), float(p('speed')), p('lockstep')
        self.lockstep_timeout, self.max_catch_up = float(p('lockstep_timeout')), int(p('max_catch_up'))
        self.truth_decimation = max(1, int(p('truth_decimation')))
        self.clock_decimation = max(1, int(p('clock_decimation')))
        self.joint_pub = self.create_publisher(JointState, '/joint_states', 10)
        self.truth_pub = self.create_publisher(PointStamped, '/sim/effector_position', 10)
        self.clock_pub = self.create_publisher(ClockMsg, '/clock', 10) if self.publish_clock else None
        self.create_subscription(JointState, '/motor_velocity_cmd', self.on_command, 10)
        self.frames = None
        if self.lockstep and float(p('camera_rate')) > 0:
            self.frames = camera_model.FrameClock(float(p('camera_rate')))
            self.visual_delay, self.visual_timeout = float(p('visual_delay')), float(p('visual_timeout'))
            self.exposures = deque()         # stamps (s) of frames whose command has not arrived
            self.visual_answers = False      # the visual loop answered its last frame
            self.visual_since = None         # wall time the wait for a frame's command began
            self.create_subscription(TwistStamped, '/cmd_vel_cartesian', self.on_visual_command, 10)
        self.steps = 0
        self.answered = True         # lockstep: the command for the last reading has arrived
        self.last_stamp = None
        self.waiting_since = None
        self.wall_start = time.monotonic()
        self.publish_reading(self.sim.read())
        period = 1.0 / rate if not self.publish_clock or self.speed <= 0 else 1.0 / (rate * self.speed)
        # in lockstep the commands step the simulation; the timer only watches for a missing one
        period = self.lockstep_timeout / 4 if self.lockstep else min(period, 1e-3)
        self.create_timer(period, self.on_timer, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def load_truth(self, truth_path, description_path):
        """(geometry, masses, joint effects hook) of the simulated robot."""
        if description_path:
            self.get_logger().info(f'true geometry from the robot description {description_path}, nominal masses')
            return description.load(description_path), MassParameters(), None
        truth = sim_truth.load(truth_path or None)
        joint = set(truth.effects) & {'joint_scale', 'backlash', 'gravity_compliance'}
        if joint:
            self.get_logger().info(f"undeclared joint effects simulated: {', '.join(sorted(joint))}")
        return truth.geometry, true_masses(truth), sim_truth.JointReadings(truth) if joint else None

    def stamp(self):
        if self.publish_clock:
            return Time(nanoseconds=int(round(self.sim.t * 1e9))).to_msg()
        return self.get_clock().now().to_msg()

    def on_command(self, msg):
        index = {name: i for i, name in enumerate(msg.name)}
        if len(msg.velocity) != len(msg.name) or any(j not in index for j in JOINTS):
            self.get_logger().error('motor_velocity_cmd without velocities of motor_1..3', throttle_duration_sec=1.0)
            return
        try:
            self.sim.set_command([msg.velocity[index[j]] for j in JOINTS])
        except ValueError as e:
            self.get_logger().error(str(e), throttle_duration_sec=1.0)
            return
        if self.lockstep and msg.header.stamp == self.last_stamp:
            self.answered = True
            self.on_timer()             # step at once: lockstep runs as fast as the two nodes can

    def on_visual_command(self, msg):
        t = stamp_seconds(msg.header.stamp)
        while self.exposures and self.exposures[0] <= t + camera_model.FrameClock.TOLERANCE:
            self.exposures.popleft()
        self.visual_answers = True
        if self.visual_since is not None:
            self.on_timer()             # the step that waited for this command

    def waiting_for_camera(self):
        """Visual lockstep: True while the next step would pass a frame's deadline before its command."""
        while self.exposures and self.sim.t + self.sim.dt >= self.exposures[0] + self.visual_delay - 1e-9:
            if self.visual_answers:
                now = time.monotonic()
                self.visual_since = self.visual_since or now
                if now - self.visual_since < self.visual_timeout:
                    return True
                self.get_logger().info('visual lockstep: a frame went unanswered, not waiting until the next answer',
                                       throttle_duration_sec=5.0)
            self.exposures.popleft()
            self.visual_answers = False
            self.visual_since = None
        self.visual_since = None
        return False

    def due_steps(self):
        """Steps to run now: as many as the wall clock (times speed) asks, at most max_catch_up."""
        if self.publish_clock and self.speed <= 0:
            return self.max_catch_up
        speed = self.speed if self.publish_clock else 1.0
        target = math.floor((time.monotonic() - self.wall_start) * speed / self.sim.dt)
        return max(0, min(target - self.steps, self.max_catch_up))

    def on_timer(self):
        n = self.due_steps()
        if n and self.lockstep:
            n = 1                       # one step per answered reading
            if not self.answered:
                now = time.monotonic()
                self.waiting_since = self.waiting_since or now
                if now - self.waiting_since < self.lockstep_timeout:
                    return
                self.get_logger().warn('lockstep: no command for the last reading, stepping on', throttle_duration_sec=1.0)
            self.waiting_since = None
            if self.frames is not None and self.waiting_for_camera():
                return
        for _ in range(n):
            self.sim.step()
            self.steps += 1
            reading = self.sim.read()   # every step: the speed estimate differentiates consecutive readings
        if n:
            self.publish_reading(reading)

    def publish_reading(self, reading):
        stamp = self.stamp()
        if self.clock_pub is not None and self.steps % self.clock_decimation == 0:
            self.clock_pub.publish(ClockMsg(clock=stamp))
        Theta, dTheta = reading
        msg = JointState(name=list(JOINTS), position=[float(v) for v in Theta], velocity=[float(v) for v in dTheta])
        msg.header.stamp = stamp
        self.last_stamp, self.answered = stamp, False
        self.joint_pub.publish(msg)
        if self.steps % self.truth_decimation == 0:
            t = stamp_seconds(stamp)
            if self.frames is not None and self.frames.due(t):
                self.exposures.append(t)
            P, _ = self.sim.effector()
            truth = PointStamped()
            truth.header.stamp, truth.header.frame_id = stamp, 'base'
            truth.point.x, truth.point.y, truth.point.z = (float(v) for v in P)
            self.truth_pub.publish(truth)


def main(args=None):
    return spin(SimMotorsNode, 'sim_motors', (DescriptionError, ValueError), args)


if __name__ == '__main__':
    sys.exit(main())
