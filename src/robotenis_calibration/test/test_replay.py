"""
`replay` as its own process publishes a bag's messages, with their stamps and their timing.

A probe node in this process subscribes before the replay starts (the replay waits ``--delay`` for
discovery); the reliable /sphere/position must arrive complete and in order, the latched
/robot_description once, and the images (sensor-data QoS, best effort) at all.
"""
import signal
import subprocess
import time

from geometry_msgs.msg import PointStamped
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile
from robotenis_calibration import bag_io
from robotenis_sim import session_bag as bag_sim
from sensor_msgs.msg import CompressedImage
from std_msgs.msg import String

RATE = 4.0


@pytest.fixture
def probe(ros_env):
    rclpy.init()
    node = rclpy.create_node('replay_probe')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        yield node, executor, ros_env
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


def spin_while(executor, proc, timeout):
    deadline = time.monotonic() + timeout
    while proc.poll() is None and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    for _ in range(50):       # what is still in flight after the replay exits
        executor.spin_once(timeout_sec=0.01)


def test_replay_publishes_the_bag(tmp_path, probe, console_script):
    node, executor, env = probe
    bag = bag_sim.write(tmp_path / 'bag', bag_sim.BagSpec(poses=10, images_per_pose=1))
    with bag_io.BagReader(bag.path) as reader:
        stamps = [s for _, _, s, _ in reader.messages(['/sphere/position'])]
        records = list(reader.records(['/sphere/position']))
    span = (records[-1].log_ns - records[0].log_ns) * 1e-9
    got, descriptions, images = [], [], []
    node.create_subscription(PointStamped, '/sphere/position',
                             lambda m: got.append((m.header.stamp.sec * 10 ** 9
                                                   + m.header.stamp.nanosec, time.monotonic())),
                             QoSProfile(depth=len(stamps)))
    node.create_subscription(String, '/robot_description', lambda m: descriptions.append(m.data),
                             QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    node.create_subscription(CompressedImage, '/camera/image_raw/compressed', images.append,
                             qos_profile_sensor_data)
    log = open(tmp_path / 'replay.log', 'w')
    # waits for the probe's subscription: a fixed delay lost the first messages once in CI
    proc = subprocess.Popen([console_script('replay'), bag.path, '--rate', str(RATE),
                             '--delay', '0.5', '--wait-for', '/sphere/position'], env=env,
                            stdout=log, stderr=subprocess.STDOUT)
    spin_while(executor, proc, 60.0)
    log.close()
    assert proc.returncode == 0, (tmp_path / 'replay.log').read_text()
    assert [s for s, _ in got] == stamps
    assert len(descriptions) == 1 and descriptions[0].startswith('legs:')
    assert images and images[0].format == bag_io.PNG_FORMAT
    # the original timing: never faster than the recording divided by the rate
    assert got[-1][1] - got[0][1] > span / RATE * 0.99


def test_replay_stops_cleanly_on_ctrl_c(tmp_path, probe, console_script):
    _, _, env = probe
    bag = bag_sim.write(tmp_path / 'bag', bag_sim.BagSpec(poses=10))
    log_path = tmp_path / 'replay.log'
    with open(log_path, 'w') as log:
        proc = subprocess.Popen([console_script('replay'), bag.path, '--delay', '0.5'],
                                env=env, stdout=log, stderr=subprocess.STDOUT)
    # interrupted while it publishes (a fixed sleep hit the imports on a loaded machine)
    deadline = time.monotonic() + 60.0
    while 'of the bag' not in log_path.read_text() and time.monotonic() < deadline:
        assert proc.poll() is None, log_path.read_text()
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    out = log_path.read_text()
    assert proc.returncode == 0, out
    assert 'interrupted' in out and 'Traceback' not in out


def test_waiting_for_a_topic_the_bag_does_not_replay_is_refused_at_once(tmp_path, probe,
                                                                        console_script):
    _, _, env = probe
    bag = bag_sim.write(tmp_path / 'bag', bag_sim.BagSpec(poses=2))
    done = subprocess.run([console_script('replay'), bag.path, '--wait-for', '/no/such/topic'],
                          env=env, capture_output=True, text=True, timeout=30)
    assert done.returncode == 2
    assert '/no/such/topic: not replayed' in done.stderr and '/sphere/position' in done.stderr
