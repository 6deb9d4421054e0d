"""
The `calibration` node as its own process: the Calibrate service's wiring, without a robot.

No simulator runs, so a session never gets past its first pose; what is checked is what does not
need one: a bad request is answered with what went wrong, a second request while a session runs is
refused with "busy", and Ctrl-C during a session leaves a whole, readable bag.
"""
import signal
import subprocess
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from robotenis_calibration import bag_io
from robotenis_interfaces.srv import Calibrate

GUESS = [0.73, -0.02, 1.37]   # m: where the session looks for the ball (no ball is needed here)


@pytest.fixture
def service(tmp_path, console_script, ros_env):
    log = open(tmp_path / 'node.log', 'w')
    args = ['--ros-args', '-p', f'bags_dir:={tmp_path}', '-p', 'num_poses:=30',
            '-p', f'sphere_guess:={GUESS}']
    proc = subprocess.Popen([console_script('calibration'), *args], env=ros_env, stdout=log,
                            stderr=subprocess.STDOUT)
    rclpy.init()
    node = rclpy.create_node('calibration_probe')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    client = node.create_client(Calibrate, 'calibrate')
    try:
        assert client.wait_for_service(timeout_sec=20.0), 'no /calibrate service'
        yield client, executor, proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        log.close()


def call(client, executor, timeout=30.0, **fields):
    future = client.call_async(Calibrate.Request(**fields))
    executor.spin_until_future_complete(future, timeout_sec=timeout)
    assert future.done(), 'no answer from /calibrate'
    return future.result()


def test_service_answers_refuses_when_busy_and_keeps_the_bag_whole_on_ctrl_c(service, tmp_path):
    client, executor, proc = service
    bad = call(client, executor, pose_selection='random')
    assert not bad.success and 'unknown pose selection' in bad.message
    bag = tmp_path / 'session'
    first = client.call_async(Calibrate.Request(bag_path=str(bag)))
    deadline = time.monotonic() + 30.0
    while not bag.exists() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    assert bag.exists(), 'the session did not start recording'
    busy = call(client, executor)
    assert not busy.success and busy.message.startswith('busy')
    assert not first.done()
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=15) == 0, (tmp_path / 'node.log').read_text()
    with bag_io.BagReader(bag) as reader:
        assert reader.notes == []          # footer and metadata written: not a truncated bag
        assert reader.counts['/robot_description'] == 1 and reader.counts['/goal'] == 1
