"""
Benchmark: what the nodes' messages cost on their way: a camera frame, and the lockstep round trip.

Issue 15 part 4 (wall time): in a live session the hand camera publishes about 100 frames per
second of robot time, the sphere detector takes every one, and the calibration node used to take
every one too, to keep 2 per rest. Each way is measured over real DDS (rclpy, Fast DDS): this
process publishes FRAMES frames at RATE Hz, a subscriber runs in a second process (as the nodes
do), and each side reports its CPU time per frame (user + system, all threads: the middleware's
too). The baseline is what the nodes did before (robotenis_ros.convert's former construction of
the message, rclpy's deserialization), run in the same invocation:

* camera, build and publish: ``array.array('B', pixels.tobytes())`` (before) against
  ``convert.image_message`` (the array's own buffer);
* detector, take and read: a subscription of sensor_msgs/Image, ``convert.image_array`` (before)
  against a raw subscription and ``robotenis_ros.cdr.image`` (a view of the bytes);
* a subscriber that only takes the bytes (raw), as the calibration node did for every frame.

The lockstep round trip: in a session the simulator publishes a sensor_msgs/JointState every 1 ms
step and waits for the controller's JointState command stamped with it. This process plays the
simulator, a second process the controller (both on the EventsExecutor, as the nodes), for TRIPS
round trips: wall time and each side's CPU per round trip, with rclpy's messages both ways (the
nodes before) against CDR bytes written and read by robotenis_ros.cdr (now).

    ./robotenis bench transport
"""
import array
import os
import subprocess
import sys
import time

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.qos import qos_profile_sensor_data
from rclpy.task import Future
from robotenis_ros import cdr, convert
from robotenis_ros.names import JOINTS
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import Header

FRAMES, RATE = 600, 100.0
TOPIC = 'bench_transport/image_raw'
TRIPS = 4000
READINGS, COMMANDS = 'bench_transport/joint_states', 'bench_transport/motor_velocity_cmd'
WAYS = {'message': 'sensor_msgs/Image, convert.image_array (before)',
        'raw': 'raw bytes, cdr.image (now)',
        'bytes': 'raw bytes only (the calibration node, before: every frame)'}


def subscriber(way, seconds):
    """Take images for ``seconds``; print the frames taken and the CPU (s) spent on them."""
    rclpy.init()
    node = rclpy.create_node('bench_transport_sub')
    taken = []
    read = {'message': convert.image_array, 'raw': lambda data: cdr.image(data).pixels,
            'bytes': len}[way]
    node.create_subscription(Image, TOPIC, lambda m: taken.append(read(m)),
                             qos_profile_sensor_data, raw=way != 'message')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    deadline, cpu = time.monotonic() + seconds, None
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if taken and cpu is None:
            cpu, first = time.process_time(), len(taken)
    print(len(taken) - first, time.process_time() - cpu, flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def before(pixels, header):
    """Build the camera's message as it was built before: the pixels by way of a bytes object."""
    msg = Image(header=header, height=pixels.shape[0], width=pixels.shape[1],
                encoding='mono8', step=pixels.shape[1])
    msg.data = array.array('B', np.ascontiguousarray(pixels).tobytes())
    return msg


def publish(node, build, frames, subscribers=1):
    """Publish ``frames`` frames at RATE; return the CPU (s) a frame took to build and publish."""
    pub = node.create_publisher(Image, TOPIC, qos_profile_sensor_data)
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() < subscribers and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)                     # discovery done before timing
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (8, 480, 640), dtype=np.uint8)
    cpu = 0.0
    for k in range(frames):
        t = time.process_time()
        pub.publish(build(images[k % len(images)], Header(frame_id='camera_optical')))
        cpu += time.process_time() - t
        time.sleep(1.0 / RATE)
    node.destroy_publisher(pub)
    return cpu / frames


def run(node, way, build):
    """One subscriber process of ``way``; return (publisher's, subscriber's) CPU per frame."""
    seconds = FRAMES / RATE + 6.0
    proc = subprocess.Popen([sys.executable, __file__, '--subscriber', way, str(seconds)],
                            stdout=subprocess.PIPE, text=True, env=os.environ)
    pub_cpu = publish(node, build, FRAMES)
    out, _ = proc.communicate(timeout=seconds + 30)
    taken, cpu = out.split()
    return pub_cpu, float(cpu) / max(int(taken), 1), int(taken)


def joint_state(sec, nanosec, **arrays):
    """Build a JointState of the motors as the nodes built them before (an rclpy message)."""
    msg = JointState(name=list(JOINTS), **{k: [float(v) for v in a] for k, a in arrays.items()})
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    return msg


def lockstep_side(node, way, publish_topic, take_topic, answer):
    """Wire one side of the round trip: ``answer(sec, nanosec, values)`` on each message taken."""
    if way == 'cdr':
        fields = ('position', 'velocity') if publish_topic == READINGS else ('velocity',)
        write, reader = cdr.JointStateWriter(JOINTS, fields), cdr.JointStateReader(JOINTS)
        read = reader.read
    else:
        def write(sec, nanosec, **arrays):
            return joint_state(sec, nanosec, **arrays)

        def read(msg):
            return (msg.header.stamp.sec, msg.header.stamp.nanosec,
                    convert.joint_vector(msg, 'position'), convert.joint_vector(msg, 'velocity'))
    pub = node.create_publisher(JointState, publish_topic, 10)
    node.create_subscription(JointState, take_topic, lambda m: answer(pub, write, read(m)), 10,
                             raw=way == 'cdr')
    return pub, write


def controller(way, seconds):
    """Answer TRIPS readings with commands stamped with them (within ``seconds``); print CPU."""
    rclpy.init()
    node = rclpy.create_node('bench_transport_controller')
    taken = []

    def answer(pub, write, reading):
        taken.append(reading[0])
        pub.publish(write(reading[0], reading[1], velocity=reading[3]))
    lockstep_side(node, way, COMMANDS, READINGS, answer)
    executor = EventsExecutor()
    executor.add_node(node)
    deadline, cpu = time.monotonic() + seconds, None
    while time.monotonic() < deadline and len(taken) < TRIPS:
        executor.spin_until_future_complete(Future(), timeout_sec=0.05)
        if taken and cpu is None:
            cpu, first = time.process_time(), len(taken)
    print(len(taken) - first, time.process_time() - cpu, flush=True)
    rclpy.try_shutdown()


def lockstep(way):
    """Return (wall, simulator's CPU, controller's CPU) per round trip, in s."""
    seconds = 30.0
    proc = subprocess.Popen([sys.executable, __file__, '--controller', way, str(seconds)],
                            stdout=subprocess.PIPE, text=True, env=os.environ)
    node = rclpy.create_node('bench_transport_simulator')
    done, count = Future(), [0]

    def answer(pub, write, command):
        count[0] += 1
        if count[0] < TRIPS:
            pub.publish(write(count[0], 0, position=(0.1, 0.2, 0.3), velocity=(1.0, 2.0, 3.0)))
        else:
            done.set_result(True)
    pub, write = lockstep_side(node, way, READINGS, COMMANDS, answer)
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    time.sleep(1.0)                     # discovery done before timing
    wall, cpu = time.monotonic(), time.process_time()
    pub.publish(write(0, 0, position=(0.1, 0.2, 0.3), velocity=(1.0, 2.0, 3.0)))
    executor.spin_until_future_complete(done, timeout_sec=seconds - 5.0)
    wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    executor.remove_node(node)
    node.destroy_node()
    proc.wait(timeout=seconds + 30)
    taken, controller_cpu = proc.stdout.read().split()
    return wall / count[0], cpu / count[0], float(controller_cpu) / max(int(taken), 1)


def main():
    rclpy.init()
    print(f'the lockstep round trip (JointState each way), {TRIPS} trips; per trip (us):')
    for way, label in (('message', "rclpy's messages (before)"), ('cdr', 'CDR bytes (now)')):
        wall, sim_cpu, ctl_cpu = lockstep(way)
        print(f'  {label:26s} wall {wall * 1e6:5.0f} | CPU: simulator {sim_cpu * 1e6:4.0f}, '
              f'controller {ctl_cpu * 1e6:4.0f}')
    node = rclpy.create_node('bench_transport_pub')
    print(f'a 640x480 mono8 frame over DDS, {FRAMES} frames at {RATE:.0f} Hz; CPU per frame (ms), '
          'publisher in this process, subscriber in another')
    rows = [('message', before), ('message', convert.image_message),
            ('raw', convert.image_message), ('bytes', convert.image_message)]
    for way, build in rows:
        pub_cpu, sub_cpu, taken = run(node, way, build)
        label = 'before' if build is before else 'now'
        print(f'  camera: build + publish ({label}) {pub_cpu * 1e3:5.2f} | subscriber: '
              f'{WAYS[way]}: {sub_cpu * 1e3:5.2f} ({taken} frames taken)')
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    if len(sys.argv) > 1 and sys.argv[1] == '--subscriber':
        subscriber(sys.argv[2], float(sys.argv[3]))
    elif len(sys.argv) > 1 and sys.argv[1] == '--controller':
        controller(sys.argv[2], float(sys.argv[3]))
    else:
        main()
