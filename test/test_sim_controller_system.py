"""
System test: sim_motors and motion_controller as separate processes move the robot to three goals.

Mode: simulated time in lockstep (the simulator owns /clock, waits for the command answering each
reading; the controller ticks on every reading), so the result does not depend on how loaded the
machine is. The simulator's true geometry and masses are the controller's (nominal description), so
what remains at rest is the resolution of the loop: the readings are quantised (one count q =
2 pi / (16384 * 10) rad) with 2e-5 rad noise, the controller holds the joints within a few counts,
and the effector within |J|_2 * 4 q of the goal (|J|_2 < 1.3 m/rad at these goals: 0.2 mm).
The pair runs in the root namespace and in a namespace of its own (two robots on one graph): the
nodes' names are relative, so only /clock stays global.
"""
import os
import random
import signal
import subprocess
import time

from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from robotenis_kinematics import delta, description
from robotenis_ros.convert import point_stamped
from robotenis_ros.names import BASE_FRAME
from robotenis_sim import motors

TOP = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GOALS = np.array([[-0.2, 0.2, 0.75], [0.15, 0.1, 0.9], [0.0, -0.25, 0.8]])
SIM_SECONDS_PER_GOAL = 0.8      # 0.3 m at 2 m/s and 4 g takes 0.33 s; the rest is settling


def executable(pkg, name):
    path = os.path.join(TOP, 'install', pkg, 'lib', pkg, name)
    if not os.path.exists(path):
        pytest.skip(f'{path} is not installed (./robotenis setup)')
    return path


def stop(procs, timeout=10.0):
    """SIGINT, then wait; SIGKILL what is still running. Returns the exit codes."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    deadline = time.monotonic() + timeout
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    return [p.returncode for p in procs]


@pytest.fixture(params=['', 'robot1'])
def system(tmp_path, request):
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(1, 200)),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    os.environ.update({k: env[k] for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE')})
    nominal = description.config_path('nominal.yaml')
    ns = ['-r', f'__ns:=/{request.param}'] if request.param else []
    commands = [
        [executable('robotenis_sim', 'sim_motors'), '--ros-args', *ns,
         '-p', f'description_path:={nominal}', '-p', 'publish_clock:=true', '-p', 'lockstep:=true',
         '-p', 'speed:=0.0', '-p', 'seed:=3'],
        [executable('robotenis_control', 'motion_controller'), '--ros-args', *ns,
         '-p', f'description_path:={nominal}', '-p', 'use_sim_time:=true',
         '-p', 'tick_on_joint_states:=true'],
    ]
    logs = [open(tmp_path / f'node{k}.log', 'w') for k in range(2)]
    procs = [subprocess.Popen(c, env=env, stdout=log, stderr=subprocess.STDOUT)
             for c, log in zip(commands, logs)]
    rclpy.init()
    node = Node('system_test_probe')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        yield node, executor, procs, '/' + request.param if request.param else ''
    finally:
        codes = stop(procs)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        for log in logs:
            log.close()
        assert codes == [0, 0], \
            f'nodes did not stop cleanly: exit codes {codes}; logs in {tmp_path}'


def test_three_goals_reached_within_the_loop_resolution(system):
    node, executor, procs, ns = system
    truth = []
    node.create_subscription(
        PointStamped, f'{ns}/sim/effector_position',
        lambda m: truth.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                                m.point.x, m.point.y, m.point.z)), 10)
    goal_pub = node.create_publisher(PointStamped, f'{ns}/goal', 10)

    def spin_until(predicate, wall_timeout):
        deadline = time.monotonic() + wall_timeout
        while time.monotonic() < deadline and not predicate():
            executor.spin_once(timeout_sec=0.01)
            assert all(p.poll() is None for p in procs), 'a node died'
        return predicate()

    assert spin_until(lambda: len(truth) > 10 and node.count_subscribers(f'{ns}/goal') > 0,
                      20.0), 'no simulator output'
    desc = description.nominal()
    q = motors.ResolverParameters().resolution
    for goal in GOALS:
        goal_pub.publish(point_stamped(goal, TimeMsg(), BASE_FRAME))
        start = truth[-1][0]
        assert spin_until(lambda: truth[-1][0] > start + SIM_SECONDS_PER_GOAL, 15.0), \
            'simulated time stalled'
        P = np.array(truth[-1][1:])
        bound = np.linalg.norm(delta.jacobian(desc, goal), 2) * 4 * q
        assert np.linalg.norm(P - goal) < bound, (goal, P, np.linalg.norm(P - goal), bound)
