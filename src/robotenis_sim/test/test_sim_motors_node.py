"""sim_motors' visual lockstep via its callbacks: the simulator waits for each frame's command."""
import time

from geometry_msgs.msg import TwistStamped
import pytest
import rclpy
from robotenis_ros.cdr import JointStateWriter
from robotenis_ros.names import JOINTS
from robotenis_sim.sim_motors_node import SimMotorsNode

DELAY, TIMEOUT = 1.0 / 120.0, 0.05


@pytest.fixture
def node():
    rclpy.init(args=['--ros-args', '-p', 'publish_clock:=true', '-p', 'lockstep:=true',
                     '-p', 'speed:=0.0', '-p', 'camera_rate:=120.0',
                     '-p', f'visual_delay:={DELAY}', '-p', f'visual_timeout:={TIMEOUT}',
                     '-p', 'seed:=1'])
    n = SimMotorsNode()
    try:
        yield n
    finally:
        n.destroy_node()
        rclpy.try_shutdown()


def controller_answers(node, steps):
    """Answer the last reading ``steps`` times as the controller does; return the sim time."""
    command = JointStateWriter(JOINTS, ('velocity',))
    for _ in range(steps):
        node.on_command(command(*node.last_stamp, velocity=(0.0, 0.0, 0.0)))
    return node.sim.t


def visual_answer(node, t):
    msg = TwistStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(t), int(round((t % 1) * 1e9))
    node.on_visual_command(msg)


def test_the_simulator_waits_for_each_frames_command_while_the_loop_answers(node):
    # nothing has answered yet: frames go by unwaited
    assert controller_answers(node, 50) == pytest.approx(0.050)
    visual_answer(node, node.schedule.exposures[-1])      # the loop answers its latest frame
    while not node.schedule.exposures:
        controller_answers(node, 1)
    t_frame = node.schedule.exposures[0]                  # the next frame, not answered yet
    t = controller_answers(node, 50)
    assert t < t_frame + DELAY <= t + node.sim.dt + 1e-9  # stopped at the step before its deadline
    # its command comes: the simulator goes on
    visual_answer(node, t_frame)
    assert controller_answers(node, 1) > t


def test_an_unanswered_frame_is_given_up_after_the_timeout_and_then_not_waited_for(node):
    controller_answers(node, 50)
    visual_answer(node, node.schedule.exposures[-1])
    t = controller_answers(node, 50)                      # waiting for the next frame's command
    time.sleep(1.5 * TIMEOUT)
    node.on_timer()                                       # the timer notices the timeout
    assert node.sim.t > t and not node.schedule.visual_answers
    # no more waiting
    assert controller_answers(node, 50) == pytest.approx(t + node.sim.dt + 0.050)
