"""
The `calibration` node as its own process: the Calibrate service's wiring, without a robot.

No simulator runs, so a session never gets past its first pose; what is checked is what does not
need one: a bad request is answered with what went wrong, a second request while a session runs is
refused with "busy", and Ctrl-C during a session leaves a whole, readable bag; a request that
cannot give enough rests is refused before anything is recorded, and ``calibrate --call`` exits
non-zero when the node is stopped or killed under it.

Time bounds: the client waits at most service_client.SERVICE_WAIT (10 s) for the service, and the
node starts in 1-3 s here. A node stopped with SIGTERM leaves the graph at once, so the client must
be gone within its GONE_GRACE (1 s) plus 4 s for discovery and start-up; a node killed outright
leaves it when its DDS participant's lease expires (Fast DDS's default, 20 s), so within 30 s.
"""
import os
import signal
import subprocess
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from robotenis_calibration import bag_io, service_client
from robotenis_interfaces.srv import Calibrate

GUESS = [0.73, -0.02, 1.37]   # m: where the session looks for the ball (no ball is needed here)


@pytest.fixture
def node_process(tmp_path, console_script, ros_env):
    """Start the calibration node as its own process, recording to tmp_path/bags; kill it after."""
    log = open(tmp_path / 'node.log', 'w')
    args = ['--ros-args', '-p', f'bags_dir:={tmp_path / "bags"}', '-p', 'num_poses:=30',
            '-p', f'results_dir:={tmp_path / "results"}', '-p', f'sphere_guess:={GUESS}']
    proc = subprocess.Popen([console_script('calibration'), *args], env=ros_env, stdout=log,
                            stderr=subprocess.STDOUT)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        log.close()


@pytest.fixture
def service(node_process):
    proc = node_process
    rclpy.init()
    node = rclpy.create_node('calibration_probe')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    client = node.create_client(Calibrate, 'calibrate')
    try:
        assert client.wait_for_service(timeout_sec=20.0), 'no /calibrate service'
        yield client, executor, proc
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


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


def run_client(console_script, env, *args):
    """Start ``calibrate --call ARGS`` as its own process, its stderr in a pipe."""
    return subprocess.Popen([console_script('calibrate'), '--call', *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(client, timeout):
    """Return the client's (exit status, stderr, seconds waited); kill it past ``timeout``."""
    t0 = time.monotonic()
    try:
        _, err = client.communicate(timeout=timeout)
    finally:
        if client.poll() is None:
            client.kill()
            client.communicate()
    return client.returncode, err, time.monotonic() - t0


def test_a_request_that_cannot_give_enough_rests_is_refused_at_once(node_process, tmp_path,
                                                                    console_script, ros_env):
    client = run_client(console_script, ros_env, '--poses', '12', '--frames', '10')
    status, err, _ = finish(client, service_client.SERVICE_WAIT + 10.0)
    reason = ('robotenis calibrate: calibration failed: request refused, nothing was moved: '
              '12 poses give at most 12 rests (one per pose, none where the ball is out of view): '
              'the identification needs at least 20')
    assert status == 1 and reason in err.splitlines(), err
    assert not (tmp_path / 'bags').exists(), 'a refused request recorded a bag'


@pytest.mark.parametrize('sig, bound', [(signal.SIGTERM, 5.0), (signal.SIGKILL, 30.0)])
def test_the_client_exits_non_zero_when_the_node_goes_away(node_process, tmp_path,
                                                           console_script, ros_env, sig, bound):
    bag = tmp_path / 'session'
    client = run_client(console_script, ros_env, '--bag', str(bag))
    try:
        deadline = time.monotonic() + service_client.SERVICE_WAIT + 10.0
        while not bag.exists() and time.monotonic() < deadline and client.poll() is None:
            time.sleep(0.05)
        assert bag.exists(), 'the session did not start recording'
        time.sleep(1.0)                # the first pose commanded: the session awaits its rest
        os.kill(node_process.pid, sig)
        status, err, waited = finish(client, bound)
    finally:
        if client.poll() is None:
            client.kill()
            client.communicate()
    assert status == 1 and 'service went away before answering' in err, err
    assert waited < bound
    node_process.wait(timeout=10)
    with bag_io.BagReader(bag) as reader:
        if sig == signal.SIGTERM:          # stopped: the bag was closed, whole
            assert reader.notes == [] and reader.counts['/robot_description'] == 1
