"""
The `calibration` node: the Calibrate service that runs a session and calibrates from its bag.

A request plans the poses (robotenis_calibration.poses) around the parameter ``sphere_guess`` (the
user's rough ball position: required, it is the robot's), then the session runner commands each
one on goal, waits for rest and settling, and counts detections (the first pose the one whose ball
should be nearest the optical axis; with ``replan``, the default, the poses after the first rest
are planned again around the ball it saw, and again after six), while every
message of the session is recorded to a rosbag2 bag (MCAP, robotenis_calibration.bag_io): the
declared description, joint states, sphere positions and detections, the detector's reasons for
the frames it dropped (sphere/dropped: they also name why a pose was skipped), camera info,
goals, rest markers, progress, and of the camera images only the first ``images_per_pose`` frames
of each rest, as lossless PNG (sensor_msgs/CompressedImage on ``image_topic``/compressed):
enough to check or re-run the detector on every pose, at a small share of the bag (all frames raw
would be 300 kB each at 120 Hz). The images are subscribed only from a rest's start until its
frames are kept: taking a 640x480 frame costs about 1.1 ms, at 100 Hz a tenth of a core, and a
session keeps 2 of about 110 per pose (a new subscription matches the camera's publisher within
about 10 ms here).
The subscribed topics are recorded as the bytes that arrived (as ``ros2 bag record`` does;
rclpy's own serialization of a JointState has trailing bytes that rosbags' reader refuses).
The bag names the topics as the calibration contract does (/joint_states, /sphere/position,
/robot_description, ...) whatever the node's namespace. When the session is
over the bag is calibrated exactly as `./robotenis calibrate BAG --out RESULT.yaml` would do it
(robotenis_calibration.pipeline). A request that cannot give the rests the identification needs
is refused before anything moves, and a session whose joint states or detections stop for longer
than a pose can last is stopped, naming the silent input, with its bag kept and no result
(robotenis_calibration.session_limits). A second request while a session runs is refused with
"busy"; progress goes to calibration/progress. On shutdown a bag being recorded is closed, so it
stays whole. Parameters: the table PARAMETERS.

The node runs on the EventsExecutor (robotenis_ros.node.spin): it takes every joint state, 1 kHz
of simulated time, as bytes, recorded as they are and their positions read from them
(robotenis_ros.cdr.JointStateReader). The service is a robotenis_ros.node.DeferredService: a
request starts the session, and the timer that drives it answers when it is over.
"""
import array
import math
import os
import time
from types import SimpleNamespace

from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import deserialize_message, serialize_message
from robotenis_calibration import bag_io, pipeline, poses, protocol, result, session_limits
from robotenis_calibration.session_runner import DONE, MEASURING, RunnerConfig, SessionRunner
from robotenis_interfaces.msg import CalibrationProgress, RestMarker, SphereDetection
from robotenis_interfaces.srv import Calibrate
from robotenis_kinematics import description
from robotenis_ros import cdr
from robotenis_ros.convert import image_array, point_stamped, stamp_seconds, xyz
from robotenis_ros.names import BASE_FRAME, JOINTS
from robotenis_ros.node import declare_parameters, DeferredService, LATCHED, spin
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, JointState
from std_msgs.msg import String

RECORDED = {  # topic (relative) -> (message class, ROS type name)
    'joint_states': (JointState, 'sensor_msgs/msg/JointState'),
    'sphere/position': (PointStamped, 'geometry_msgs/msg/PointStamped'),
    'sphere/detection': (SphereDetection, 'robotenis_interfaces/msg/SphereDetection'),
    'camera/camera_info': (CameraInfo, 'sensor_msgs/msg/CameraInfo'),
    'sphere/dropped': (String, 'std_msgs/msg/String'),
}
PUBLISHED = {
    'goal': 'geometry_msgs/msg/PointStamped',
    'calibration/rest': 'robotenis_interfaces/msg/RestMarker',
    'calibration/progress': 'robotenis_interfaces/msg/CalibrationProgress',
    'robot_description': 'std_msgs/msg/String',
}
UNSET = [math.nan] * 3
# Messages kept for the node while it is busy: a second of joint states at 1 kHz. Replanning
# after the first rests holds it 0.7 s of simulated time, and with a queue of 50 the joint states
# of that move were lost (the moves' reversals give the backlash sides).
QUEUE = 1000
PARAMETERS = {
    'description_path': (description.config_path('nominal.yaml'),
                         'the robot description the session starts from'),
    'sphere_guess': (UNSET, "m, base frame: the ball's rough position (a few cm); required"),
    'replan': (True, 'plan the poses again around the ball the first rest saw, and the first six'),
    'max_range': (poses.IMAGE_MAX_RANGE, 'm: the farthest the ball is planned from the camera (a '
                                         "rest's depth error grows as its square: see poses)"),
    'bags_dir': ('bags', 'folder of the recorded sessions'),
    'results_dir': ('bags', 'folder of the calibration results'),
    'num_poses': (300, 'poses of a session (a request may ask for others)'),
    'frames_per_pose': (500, 'detections averaged per rest'),
    'settle_time': (4.0, "s waited at rest before measuring (the paper's 4 s)"),
    'holdout_fraction': (pipeline.Settings.holdout_fraction,
                         'share of the rests held out to test the calibration'),
    'image_topic': ('camera/image_raw', 'the images whose first frames of each rest are kept'),
    'images_per_pose': (2, 'images kept per rest, as PNG'),
    'move_timeout': (RunnerConfig.move_timeout, 's to come to rest at a pose, else it is skipped'),
    'measure_timeout': (RunnerConfig.measure_timeout,
                        "s a rest may take beyond its frames' own time (at the detections' "
                        'rate) before the pose is skipped'),
}


def bag_topic(name):
    """Return the contract's name of a topic in the bag: the node's relative name from the root."""
    return '/' + name.lstrip('/')


class CalibrationNode(Node):

    def __init__(self):
        super().__init__('calibration')
        self.image_topic = declare_parameters(self, PARAMETERS)['image_topic']
        self.busy = False
        self.runner = None
        self.writer = None
        self.session = None             # the request being served: see start_session
        self.images_kept = {}           # pose index -> images recorded during its rest
        self.joints = cdr.JointStateReader(JOINTS)
        self.goal_pub = self.create_publisher(PointStamped, 'goal', 10)
        self.progress_pub = self.create_publisher(CalibrationProgress, 'calibration/progress', 10)
        self.rest_pub = self.create_publisher(RestMarker, 'calibration/rest', 10)
        self.description_pub = self.create_publisher(String, 'robot_description', LATCHED)
        fed = {'joint_states': self.on_joint_states, 'sphere/detection': self.on_detection,
               'sphere/dropped': self.on_dropped}
        for topic, (cls, _) in RECORDED.items():
            qos = qos_profile_sensor_data if topic.startswith('camera') else QUEUE
            callback = fed.get(topic, lambda data, t=topic: self.record(t, data, self.stamp_ns()))
            self.create_subscription(cls, topic, callback, qos, raw=True)
        self.image_subscription = None  # while a rest keeps images: see watch_images
        # The service is answered when the session is over, minutes later: meanwhile the timer
        # and the subscriptions run, and a second request is answered "busy".
        self.service = DeferredService(self, Calibrate, 'calibrate', self.on_calibrate)
        self.create_timer(0.01, self.on_timer)

    def stamp_ns(self):
        return self.get_clock().now().nanoseconds

    def now(self):
        return self.stamp_ns() * 1e-9

    def record(self, topic, msg, stamp_ns=None):
        """Write a message (or its serialized bytes) to the bag being recorded, if any."""
        if self.writer is not None:
            data = msg if isinstance(msg, bytes) else serialize_message(msg)
            self.writer.write(bag_topic(topic), self.stamp_ns() if stamp_ns is None else stamp_ns,
                              data)

    def on_joint_states(self, data):
        """Record a joint state as it arrived; feed its positions to the runner."""
        stamp_ns = self.stamp_ns()
        self.record('joint_states', data, stamp_ns)
        if self.runner is not None:
            reading = self.joints.read(data)
            if reading is not None and reading[2] is not None:
                self.runner.joint_state(stamp_ns * 1e-9, reading[2])

    def on_detection(self, data):
        """Record a sphere detection as it arrived; feed it to the runner."""
        stamp_ns = self.stamp_ns()
        self.record('sphere/detection', data, stamp_ns)
        if self.runner is not None:
            msg = deserialize_message(data, SphereDetection)
            self.runner.detection(stamp_ns * 1e-9, xyz(msg.position),
                                  np.reshape(msg.covariance, (3, 3)),
                                  stamp_seconds(msg.header.stamp))

    def on_dropped(self, data):
        """Record the detector's reason to drop a frame; tell the runner (its skip messages)."""
        stamp_ns = self.stamp_ns()
        self.record('sphere/dropped', data, stamp_ns)
        if self.runner is not None:
            self.runner.dropped(stamp_ns * 1e-9, deserialize_message(data, String).data)

    def watch_images(self, on):
        """Subscribe to the camera images (``on``) or stop taking them."""
        if on and self.image_subscription is None:
            self.image_subscription = self.create_subscription(
                Image, self.image_topic, self.on_image, qos_profile_sensor_data, raw=True)
        elif not on and self.image_subscription is not None:
            self.destroy_subscription(self.image_subscription)
            self.image_subscription = None

    def on_image(self, data):
        """Record the first images_per_pose mono8 frames of each rest as PNG."""
        if self.runner is None or self.writer is None or self.runner.state != MEASURING:
            return
        index = self.runner.index
        wanted = self.get_parameter('images_per_pose').value
        if self.images_kept.get(index, 0) >= wanted:
            return
        msg = deserialize_message(data, Image)
        try:
            pixels = image_array(msg)
        except ValueError as e:
            self.get_logger().warn(f'{self.image_topic}: not recorded ({e})',
                                   throttle_duration_sec=60.0)
            return
        self.record(self.image_topic + '/compressed',
                    CompressedImage(header=msg.header, format=bag_io.PNG_FORMAT,
                                    data=array.array('B', bag_io.png(pixels))))
        self.images_kept[index] = self.images_kept.get(index, 0) + 1
        if self.images_kept[index] >= wanted:
            self.watch_images(False)

    def on_timer(self):
        if self.runner is None:
            return
        self.runner.tick(self.now())
        self.run_actions()

    def run_actions(self):
        """Execute what the runner asks for; finish the session when it is done."""
        done = False
        for kind, value in self.runner.take_actions():
            if kind == 'done':
                done = True
            else:
                self.execute(kind, value)
        if done:
            self.finish_session()

    def execute(self, kind, value):
        stamp = self.get_clock().now().to_msg()
        if kind == 'goal':
            goal = point_stamped(value, stamp, BASE_FRAME)
            self.goal_pub.publish(goal)
            self.record('goal', goal)
        elif kind in ('rest_start', 'rest_end'):
            marker = RestMarker(pose_index=int(value), start=(kind == 'rest_start'))
            self.watch_images(kind == 'rest_start'
                              and self.get_parameter('images_per_pose').value > 0)
            marker.header.stamp = stamp
            self.rest_pub.publish(marker)
            self.record('calibration/rest', marker)
            if kind == 'rest_end':
                self.log_pose(int(value))
        elif kind == 'progress':
            stage, index, count = value
            self.publish_progress(stage, index, count, self.runner.fraction)

    def log_pose(self, index):
        """Log how the pose ``index`` ended: its rest measured, or skipped with the reason."""
        if self.runner.rests and self.runner.rests[-1].index == index:
            self.get_logger().info(f'pose {index + 1}: rest measured')
        elif self.runner.skipped and self.runner.skipped[-1][0] == index:
            self.get_logger().warn(f'pose {index + 1} skipped: {self.runner.skipped[-1][1]}')

    def publish_progress(self, stage, index, count, fraction, message=''):
        msg = CalibrationProgress(stage=stage, pose_index=int(index), pose_count=int(count),
                                  fraction=float(fraction), message=message)
        msg.header.stamp = self.get_clock().now().to_msg()
        self.progress_pub.publish(msg)
        self.record('calibration/progress', msg)

    def open_bag(self, path, declared_text):
        self.writer = bag_io.BagWriter(path)
        for topic, (_, type_name) in RECORDED.items():
            self.writer.add_topic(bag_topic(topic), type_name)
        for topic, type_name in PUBLISHED.items():
            self.writer.add_topic(bag_topic(topic), type_name)
        self.writer.add_topic(bag_topic(self.image_topic + '/compressed'),
                              'sensor_msgs/msg/CompressedImage')
        self.images_kept = {}
        text = String(data=declared_text)
        self.description_pub.publish(text)
        self.record('robot_description', text)

    def param(self, name, requested):
        return requested if requested else self.get_parameter(name).value

    def on_calibrate(self, request, answer):
        """Start a session for the request; it is answered when the session is over."""
        if self.busy:
            answer(Calibrate.Response(success=False, message='busy: a calibration session is '
                                                             'already running'))
            return
        self.busy = True
        try:
            self.start_session(request, answer)
        except (pipeline.CalibrationError, ValueError, OSError) as e:
            self.end_session(answer, self.failed(Calibrate.Response(), e))

    def failed(self, response, error):
        response.success, response.message = False, f'calibration failed: {error}'
        self.get_logger().error(response.message)
        return response

    def end_session(self, answer, response):
        self.watch_images(False)
        self.close_bag()
        self.runner, self.session = None, None
        self.busy = False
        answer(response)

    def close_bag(self):
        """Finish the bag being recorded, if any."""
        if self.writer is not None:
            self.writer.close()
            self.writer = None

    def start_session(self, request, answer):
        """Plan the poses, open the bag and start the runner; the timer then drives the session."""
        guess = np.asarray(self.get_parameter('sphere_guess').value, dtype=float)
        if guess.shape != (3,) or not np.all(np.isfinite(guess)):
            raise ValueError("the parameter sphere_guess (the ball's rough position, base frame, "
                             f'm) is not set: got {guess.tolist()}; give it in the launch '
                             'configuration (robotenis_bringup/config/calibration.params.yaml)')
        declared = description.load(self.get_parameter('description_path').value)
        n = self.param('num_poses', request.num_poses)
        config = RunnerConfig(
            frames_per_pose=self.param('frames_per_pose', request.frames_per_pose),
            settle_time=request.settle_time if request.settle_time > 0
            else self.get_parameter('settle_time').value,
            move_timeout=self.get_parameter('move_timeout').value,
            measure_timeout=self.get_parameter('measure_timeout').value)
        refused = session_limits.refusal(n, config.frames_per_pose)
        if refused is not None:
            raise ValueError(f'request refused, nothing was moved: {refused}')
        rng = np.random.default_rng(request.seed)
        max_range = self.get_parameter('max_range').value
        selection = request.pose_selection or poses.SESSION_SELECTION
        planned = poses.central_first(declared, guess, poses.select(
            selection, declared, guess, n, rng, max_range))
        stamp = time.strftime('%Y%m%d-%H%M%S')
        bag = request.bag_path or os.path.join(self.get_parameter('bags_dir').value,
                                               f'session-{stamp}')
        result_path = os.path.join(self.get_parameter('results_dir').value,
                                   f'calibration-{stamp}.yaml')
        self.open_bag(bag, description.dumps(declared))
        self.get_logger().info(f'session: {len(planned)} poses'
                               f' ({selection}), '
                               f'{config.frames_per_pose} frames each, recording {bag}')

        def replan(rests, n):
            refined = poses.refined_guess(declared, [np.mean(r.Theta, axis=0) for r in rests],
                                          [np.mean(r.sphere, axis=0) for r in rests])
            moved = np.linalg.norm(refined - guess)
            try:
                again = poses.select(selection, declared, refined, n, rng, max_range)
            except ValueError as e:
                self.get_logger().warn(f'ball guess refined from {len(rests)} rests, but {e}:'
                                       ' the plan is kept')
                return None
            self.get_logger().info(f'ball guess refined from {len(rests)} rests'
                                   f' (moved {moved * 1e3:.0f} mm): '
                                   f'the last {n} poses planned again')
            return again

        self.session = SimpleNamespace(request=request, answer=answer, planned=planned, bag=bag,
                                       result_path=result_path)
        on_replan = replan if self.get_parameter('replan').value else None
        # The wall clock too: on simulated time a detector's silence must also be the wall's.
        self.runner = SessionRunner(planned, config, on_replan, clock=time.monotonic)
        self.runner.start(self.now())
        if not self.runner.started:
            self.get_logger().info('waiting for the clock to run (no /clock message yet)')
        self.run_actions()                  # the first goal, now or once the clock runs

    def finish_session(self):
        """Close the bag, calibrate from it and answer the request (the runner is done)."""
        session, response = self.session, Calibrate.Response()
        try:
            self.calibrate_session(session, response)
        except (pipeline.CalibrationError, ValueError, OSError) as e:
            self.failed(response, e)
        self.end_session(session.answer, response)

    def calibrate_session(self, session, response):
        planned, bag, result_path = session.planned, session.bag, session.result_path
        skipped = list(self.runner.skipped)
        self.close_bag()
        response.bag_path = bag
        if self.runner.failure is not None:
            response.success = False
            response.message = (f'session stopped at pose {self.runner.index + 1} of '
                                f'{len(self.runner.poses)}: {self.runner.failure}; no result '
                                f'written, the bag is kept: {bag}')
            self.get_logger().error(response.message)
            return
        settings = pipeline.Settings(self.get_parameter('holdout_fraction').value,
                                     session.request.seed)
        outcome = pipeline.calibrate_bag(
            bag, result_path, settings,
            progress=lambda text: self.publish_progress('identifying', len(planned) - 1,
                                                        len(planned), 1.0, text))
        d = outcome.diagnosis
        response.success = True
        response.message = (f'{len(planned) - len(skipped)} of {len(planned)} poses measured; '
                            f'effects found: {result.effects_text(d)}')
        if 'next_session' in outcome.description.report:
            response.message += '; ' + protocol.next_session_text(
                outcome.description.report['next_session'])
        response.result_path = result_path
        response.rms_before_mm = d.errors_mm['nominal']
        response.rms_plain_mm = d.errors_mm['plain']
        response.rms_after_mm = d.errors_mm['final']
        response.effects = list(d.effects)
        self.publish_progress(DONE, len(planned) - 1, len(planned), 1.0, response.message)


def main(args=None):
    return spin(CalibrationNode, 'calibration', (ValueError, description.DescriptionError), args,
                finish=CalibrationNode.close_bag, events=True)
