"""
`./robotenis replay BAG_DIR [--rate R] [--delay S] [--wait-for TOPIC]`: publish a recorded session.

Every topic of the bag whose message type is installed is published as the stored CDR bytes (so
the messages keep their header stamps) by a publisher of that type, at the recorded times divided
by ``rate``, after ``delay`` seconds for the subscribers to discover the publishers, and then,
for each ``--wait-for`` topic, until a subscriber has matched it (at most WAIT_FOR_TIMEOUT: on a
loaded machine discovery can take longer than any fixed delay, and what a reliable publisher
sends before the match is lost). QoS:
/robot_description latched (transient local, depth 1), images (sensor_msgs Image and
CompressedImage) the sensor-data profile, every other topic reliable with depth 100. A truncated
bag is replayed as far as it is whole (in file order). The topics are published under their names
relative to ``--namespace`` (default the root: the bag's own names). Progress goes to stderr;
Ctrl-C stops cleanly.
"""
import argparse
import importlib
import sys
import time

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from robotenis_calibration import bag_io

LATCHED = ('robot_description',)
IMAGE_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage')
ACK_TIMEOUT = Duration(seconds=5)   # for reliable subscribers to receive the last messages
WAIT_FOR_TIMEOUT = 60.0             # s: for a --wait-for topic's first subscriber


def message_class(type_name):
    """Import the Python class of a ROS type name ('pkg/msg/Type'); None if it is not installed."""
    package, kind, name = type_name.split('/')
    try:
        return getattr(importlib.import_module(f'{package}.{kind}'), name)
    except (ImportError, AttributeError):
        return None


def qos_for(topic, type_name):
    """Return the QoS profile of a replayed topic (see the module docstring)."""
    if topic.lstrip('/') in LATCHED:
        return QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    if type_name in IMAGE_TYPES:
        return qos_profile_sensor_data
    return QoSProfile(depth=100)


def create_publishers(node, topics):
    """Create {topic: publisher} for the topics of installed types; others are named on stderr."""
    publishers = {}
    for topic, type_name in sorted(topics.items()):
        cls = message_class(type_name)
        if cls is None:
            print(f'[replay] {topic}: type {type_name} is not installed, not replayed',
                  file=sys.stderr)
            continue
        # relative: the bag's topics are the calibration contract's, published in --namespace
        publishers[topic] = node.create_publisher(cls, topic.lstrip('/'),
                                                  qos_for(topic, type_name))
    return publishers


def wait(executor, until):
    """Spin the executor until the monotonic time ``until``."""
    while (left := until - time.monotonic()) > 0:
        executor.spin_once(timeout_sec=min(left, 0.1))


def wait_for_subscribers(executor, publishers, topics, until):
    """Spin until each of ``topics`` has a matched subscriber or ``until``; return the others."""
    missing = list(topics)
    while missing and time.monotonic() < until:
        executor.spin_once(timeout_sec=0.05)
        missing = [t for t in missing if publishers[t].get_subscription_count() == 0]
    return missing


def play(reader, publishers, executor, rate):
    """Publish the bag's messages at recorded times / rate; progress on stderr about every 1 s."""
    total = sum(reader.counts[t] for t in publishers)
    start, first, shown = time.monotonic(), None, 0.0
    for done, record in enumerate(reader.records(publishers), start=1):
        first = record.log_ns if first is None else first
        wait(executor, start + (record.log_ns - first) * 1e-9 / rate)
        publishers[record.topic].publish(record.data)
        if time.monotonic() - shown >= 1.0 or done == total:
            shown = time.monotonic()
            print(f'\r[replay] {(record.log_ns - first) * 1e-9:8.1f} s of the bag,'
                  f' {done} of {total} messages', end='', file=sys.stderr, flush=True)
    print(file=sys.stderr)


def main(argv=None):
    parser = argparse.ArgumentParser(prog='robotenis replay', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag_dir', help='a rosbag2 bag directory')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='speed factor (default 1: recorded timing)')
    parser.add_argument('--delay', type=float, default=1.0,
                        help='s to wait before the first message (default 1)')
    parser.add_argument('--namespace', default='', help='publish the topics in this namespace')
    parser.add_argument('--wait-for', action='append', default=[], metavar='TOPIC',
                        help="then wait until the bag's TOPIC has a subscriber (repeatable; at "
                             f'most {WAIT_FOR_TIMEOUT:.0f} s)')
    args = parser.parse_args(argv)
    if not args.rate > 0:
        parser.error(f'--rate must be positive, got {args.rate}')
    try:
        reader = bag_io.BagReader(args.bag_dir)
    except (OSError, ValueError) as e:
        print(f'robotenis replay: {e}', file=sys.stderr)
        return 1
    for note in reader.notes:
        print(f'[replay] {note}', file=sys.stderr)
    # Ctrl-C as Python's KeyboardInterrupt in this thread, not rclpy's handler: that one shuts
    # the context down from its own thread under a running publish or wait, and the clean-up
    # after it crashed (SIGSEGV) in 2 of 300 interrupts under load. SIGTERM is still rclpy's.
    rclpy.init(signal_handler_options=SignalHandlerOptions.SIGTERM)
    node = rclpy.create_node('replay', namespace=args.namespace)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        publishers = create_publishers(node, reader.topics)
        unknown = [t for t in args.wait_for if t not in publishers]
        if unknown:
            print(f"robotenis replay: --wait-for {', '.join(unknown)}: not replayed (the bag's "
                  f"topics of installed types: {', '.join(publishers)})", file=sys.stderr)
            return 2
        wait(executor, time.monotonic() + args.delay)
        missing = wait_for_subscribers(executor, publishers, args.wait_for,
                                       time.monotonic() + WAIT_FOR_TIMEOUT)
        if missing:
            print(f"robotenis replay: no subscriber on {', '.join(missing)} after "
                  f'{WAIT_FOR_TIMEOUT:.0f} s; nothing published', file=sys.stderr)
            return 1
        play(reader, publishers, executor, args.rate)
        for pub in publishers.values():
            if pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
                pub.wait_for_all_acked(ACK_TIMEOUT)
    except (KeyboardInterrupt, ExternalShutdownException):
        print('\n[replay] interrupted', file=sys.stderr)
    finally:
        reader.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
