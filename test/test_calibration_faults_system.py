"""
System test: the sphere detector killed mid-session stops the session; its bag opens anywhere.

The whole calibration system runs as processes on simulated time (calibration.launch.yaml,
sim_time:=true) and ``calibrate --call`` asks for 40 poses at the demo's timing (10 frames, 0.3 s
settle), with the node's move and measure time-outs shortened to 3 s so that the silence limit is
short (10 frames at 120 Hz take 0.08 s; a move slower than 3 s would only skip its pose). Once two
rests are measured the test kills sphere_detector by its PID. The session must then stop on its
own, naming sphere/detection, with no result written and its bag kept; the launcher names the dead
node. The bag must open with rosbags' AnyReader (every message deserialized with the types the bag
itself carries) and with the mcap library's reader, and its contract topics carry standard message
types.

Time bounds. The session stops once detections have been silent for longer than a pose can last,
session_limits.pose_time_limit: 6.4 s here, on simulated time and on the wall clock alike (the
simulator runs ahead of the wall when nothing waits for it). The response states the silence it
saw, the shorter of the two, which must exceed that limit by no more than the node's 0.01 s timer
tick on simulated time, or on the wall clock the time between two of its timer callbacks (bounded
here by WALL_TICK_S, a guard on a loaded machine). The other wall-clock bounds only guard against a
hang: 120 s for the first two rests, 120 s from the kill to the client's exit.
"""
import os
import random
import re
import signal
import subprocess
import time

from mcap.reader import make_reader
import pytest
from robotenis_bringup import launch_file
from robotenis_bringup.launcher import Launcher
from robotenis_calibration import session_limits
from robotenis_calibration.session_runner import RunnerConfig
from rosbags.highlevel import AnyReader
import yaml

TOP = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLIENT = os.path.join(TOP, 'install', 'robotenis_calibration', 'lib', 'robotenis_calibration',
                      'calibrate')
SETTLE_S = 0.3
TIMEOUT_S = 3.0                     # move_timeout and measure_timeout of the calibration node
REST_WAIT_S = 120.0
STOP_WAIT_S = 120.0
TICK_S = 0.01                       # the calibration node's timer period
WALL_TICK_S = 0.5                   # guard: wall time between two of its callbacks
CONTRACT = {'/robot_description': 'std_msgs/msg/String',
            '/joint_states': 'sensor_msgs/msg/JointState',
            '/sphere/position': 'geometry_msgs/msg/PointStamped'}


def rests_in_log(path):
    """Return how many rests the calibration node's log reports as measured so far."""
    return len(re.findall(r'pose \d+: rest measured', path.read_text())) if path.exists() else 0


@pytest.fixture(scope='module')
def stopped_session(tmp_path_factory):
    """Run the session, kill the detector after two rests; (status, stderr, bag, results, log)."""
    if not os.path.exists(CLIENT):
        pytest.skip(f'{CLIENT} is not installed (./robotenis setup)')
    tmp = tmp_path_factory.mktemp('faults')
    env = dict(os.environ, ROS_DOMAIN_ID=str(random.randint(1, 200)),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    shipped = os.path.join(launch_file.share_directory('robotenis_bringup'), 'config',
                           'calibration.params.yaml')
    with open(shipped) as f:
        params = yaml.safe_load(f)
    params['/**/calibration']['ros__parameters'].update(move_timeout=TIMEOUT_S,
                                                        measure_timeout=TIMEOUT_S)
    (tmp / 'calibration.params.yaml').write_text(yaml.safe_dump(params))
    nodes = launch_file.load(launch_file.find('calibration.launch.yaml'),
                             {'sim_time': 'true', 'bags_dir': str(tmp / 'bags'),
                              'results_dir': str(tmp / 'results'),
                              'params_file': str(tmp / 'calibration.params.yaml')})
    out = open(tmp / 'launcher.txt', 'w')
    launcher = Launcher(nodes, os.path.join(TOP, 'install'), str(tmp / 'log'), out, env)
    bag = tmp / 'session'
    client = None
    try:
        launcher.start()
        client = subprocess.Popen([CLIENT, '--call', '--poses', '40', '--frames', '10',
                                   '--settle', str(SETTLE_S), '--bag', str(bag)], env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        markers = tmp / 'log' / 'calibration.log'
        deadline = time.monotonic() + REST_WAIT_S
        while rests_in_log(markers) < 2 and time.monotonic() < deadline:
            assert client.poll() is None, client.communicate()
            time.sleep(0.1)
        assert rests_in_log(markers) >= 2, 'no two rests measured: ' + markers.read_text()
        os.kill(launcher.pid('sphere_detector'), signal.SIGKILL)
        _, err = client.communicate(timeout=STOP_WAIT_S)
        launcher.check()
        return client.returncode, err, bag, tmp / 'results', (tmp / 'launcher.txt')
    finally:
        if client is not None and client.poll() is None:
            client.kill()
            client.communicate()
        launcher.stop()
        out.close()


def test_the_session_stops_naming_the_silent_detector(stopped_session):
    status, err, bag, results, _ = stopped_session
    limit = session_limits.pose_time_limit(RunnerConfig(settle_time=SETTLE_S,
                                                        move_timeout=TIMEOUT_S,
                                                        measure_timeout=TIMEOUT_S))
    assert status == 1, err
    found = re.search(r'no message on sphere/detection for ([0-9.]+) s \(([0-9.]+) s of robot '
                      r'time\), longer than a pose can last', err)
    assert found, err
    silence, robot = float(found.group(1)), float(found.group(2))
    # printed to 0.1 s: within half of that of (limit, limit + one tick]
    assert limit - 0.05 <= silence <= limit + max(TICK_S, WALL_TICK_S) + 0.05
    assert robot >= silence - 0.1
    assert 'no result written, the bag is kept' in err
    assert not results.exists() or not any(results.glob('*.yaml')), 'a result was written'
    assert bag.is_dir()


def test_the_launcher_names_the_killed_detector(stopped_session):
    _, _, _, _, launcher_out = stopped_session
    assert 'node sphere_detector died with exit code -9' in launcher_out.read_text()


def test_the_bag_opens_with_rosbags_and_with_mcap(stopped_session):
    _, _, bag, _, _ = stopped_session
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        counts, started = {}, 0
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
            started += connection.topic == '/calibration/rest' and msg.start
    assert {t: types[t] for t in CONTRACT} == CONTRACT
    assert counts['/robot_description'] == 1 and counts['/joint_states'] > 1000
    assert counts['/calibration/rest'] >= 4       # two rests measured, each opened and closed
    # the node takes the images only from a rest's start until it keeps images_per_pose (2) of
    # them: the two rests measured kept theirs, and no rest kept more
    assert 4 <= counts['/camera/image_raw/compressed'] <= 2 * started
    (path,) = bag.glob('*.mcap')
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
        seen = sum(1 for _ in make_reader(f).iter_messages())
    assert summary.statistics.message_count == sum(counts.values()) == seen
