"""
Calibration bags as another driver would record them: a simulated static session, without ROS.

The robot, camera and truth are the static session's (robotenis_sim.static_session): the
declared description is the nominal one, the truth the simulator's default plus any undeclared
effects, the poses the paper's (random, 5-10 cm from a singularity) among those where the camera
sees the ball.
The bag is written with the rosbags library alone (rosbag2 version 9, MCAP), not with the
calibration package's writer, so that the calibration reads a bag it did not write. What this
module adds to the static session is the time series a recorder stores:

* /robot_description (std_msgs/String): the declared description, once at the start;
  /camera/camera_info once (the simulator's default camera).
* /joint_states at ``joint_rate``: after ``IDLE`` s at home, the readings move to each rest along
  a quintic profile (every joint monotone, as the static session assumes for backlash) and stay;
  each sample is the reading plus the resolver's white noise, quantised to one count
  (robotenis_sim.motors.ResolverParameters).
* /sphere/position at ``camera_rate`` from the arrival to the end of each rest: the true centre, a
  vibration of the ball holder decaying during the settle time, and per-frame noise: Table 3's
  standard deviation of a 500-frame average times sqrt(500) (robotenis_kinematics.synthetic).
* /calibration/rest markers (optional) around the ``frames_per_pose`` frames after the settle
  time; the robot leaves ``TAIL`` s after the end marker.
* images (optional): ``images_per_pose`` frames of each rest, mono8 640x480 with 2 DN of sensor
  noise, raw (sensor_msgs/Image on /camera/image_raw) or PNG (sensor_msgs/CompressedImage on
  /camera/image_raw/compressed).

Corruption, all optional: NaN and infinite values, false detections 1-5 mm off in a random
direction, dropped messages, missing topics; ``truncate`` cuts the MCAP file as a dying recorder
would.
"""
from dataclasses import dataclass, field
import functools
import os
from pathlib import Path

import cv2
import numpy as np
from robotenis_kinematics import description, synthetic, workspace
from robotenis_sim import motors, static_session
from robotenis_sim import truth as sim_truth
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg, get_typestore, Stores

# m, one frame, optical axes
FRAME_SIGMA = np.asarray(synthetic.NoiseModel().sigma_camera) * np.sqrt(500)
RESOLVER = motors.ResolverParameters()
START_NS = 1_700_000_000 * 10 ** 9    # the session's first stamp, ns
IDLE = 0.5                             # s at home before the first motion
TAIL = 0.1                             # s still after the end marker, before the next motion
# s: a move takes 0.3 s plus 1 s per rad of the largest joint motion
MOVE_TIME = (0.3, 1.0)
# ball holder after arrival: amplitude m, decay time s, frequency Hz
VIBRATION = (2e-4, 0.05, 12.0)
OVERSHOOT_TIME = 0.1                   # s after arrival for an overshoot's way back
FALSE_OFFSET = (1e-3, 5e-3)            # m: how far off a false detection is
LATENCY_NS = 300_000                   # recording time after the stamp, ns
CAMERA = static_session.DEFAULT_CAMERA
PNG_FORMAT = 'mono8; png compressed mono8'   # CompressedImage.format of a PNG of a mono8 image
TOPICS = {
    '/robot_description': 'std_msgs/msg/String',
    '/camera/camera_info': 'sensor_msgs/msg/CameraInfo',
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/sphere/position': 'geometry_msgs/msg/PointStamped',
    '/calibration/rest': 'robotenis_interfaces/msg/RestMarker',
    '/camera/image_raw': 'sensor_msgs/msg/Image',
    '/camera/image_raw/compressed': 'sensor_msgs/msg/CompressedImage',
}


@dataclass(frozen=True)
class BagSpec:
    """What to simulate. ``effects``: undeclared effects of the truth, as in scenarios.EFFECTS."""

    poses: int = 50
    seed: int = 0
    effects: dict = field(default_factory=dict)
    joint_rate: float = 250.0           # Hz
    camera_rate: float = 120.0          # Hz
    frames_per_pose: int = 40
    settle: float = 0.5                 # s from arrival to the start marker
    # s still at each rest, arrival to departure; None: settle, frames_per_pose frames and TAIL,
    # as this project's calibration node records a rest
    rest_time: float = None
    move_time: tuple = MOVE_TIME        # s: a move takes a + b * (largest joint motion, rad)
    vibration: tuple = VIBRATION        # the ball holder's shake after arrival
    rest_floor: tuple = (0.0, 0.0, 0.0)  # m, optical axes: each rest's own error, not averaged out
    overshoot: float = 0.0              # rad past a rest and back (readings), less than any
    #                                     backlash gap: the contact side stays the approach's;
    overshoot_fraction: float = 0.5     # of the joints' moves, drawn at random
    stamp_jitter: float = 0.0           # s: standard deviation of the header stamps' jitter
    joints: tuple = ('motor_1', 'motor_2', 'motor_3')   # the joint names the driver publishes
    markers: bool = True
    nan_fraction: float = 0.0           # of sphere positions and joint states
    false_fraction: float = 0.0         # of sphere positions
    drop_fraction: float = 0.0          # of sphere positions and joint states
    omit: tuple = ()                    # topics not written
    images_per_pose: int = 0
    compressed_images: bool = True
    storage: str = 'mcap'               # or 'sqlite3', rosbag2's other storage
    targets: tuple = None               # commanded positions (m, base frame) instead of random
    #                                     boundary poses: a planner's; those the camera cannot see
    #                                     are skipped


@dataclass
class SimulatedBag:
    """
    The bag written and what it should give.

    Per rest: the noise-free readings (K, 3, rad), the sphere centre the camera measures on average
    (K, 3, optical frame, m: its undeclared errors included, noise and floor left out), the
    measuring window between the markers (K, 2, s) and the true effector position (K, 3, base
    frame, m: for scoring).
    """

    path: str
    declared: object
    Theta: np.ndarray
    sphere: np.ndarray
    windows: np.ndarray
    counts: dict
    P: np.ndarray = None


def plan(spec, batch=4000):
    """
    Return the declared description, readings, measured sphere centres, true effector positions.

    Each (K, 3): the readings at the rests (rad), the sphere centres the camera measures on
    average (optical frame, m) and the effector's true positions (base frame, m).
    """
    declared = description.nominal()
    truth = sim_truth.with_effects(sim_truth.load(), **spec.effects)
    rng = np.random.default_rng(spec.seed)
    if spec.targets is not None:
        P = _seen(truth, declared, np.asarray(spec.targets, dtype=float).reshape(-1, 3))
    else:
        P = np.empty((0, 3))
        while len(P) < spec.poses:
            P = np.concatenate([P, _seen(truth, declared,
                                         workspace.boundary_poses(declared, batch, rng))])
    Theta, P_true = static_session.rest_positions(truth, declared, P[:spec.poses])
    return (declared, Theta,
            truth.camera_reading(static_session.sphere_in_camera(truth, P_true)), P_true)


def _seen(truth, declared, candidates):
    """Return the commanded positions at which the camera sees the whole ball."""
    P_true = static_session.rest_positions(truth, declared, candidates)[1]
    return candidates[static_session.visible(static_session.sphere_in_camera(truth, P_true),
                                             truth.geometry.sphere_radius)]


def schedule(Theta, spec):
    """
    Return the times (s from the start) of each rest (K, 5).

    The times are: move start, arrival, start and end of the measurement, departure. Camera frames
    are at multiples of 1 / camera_rate; the measurement starts at the first frame after the settle
    time and ends half a period after its last frame (with ``rest_time``: at the departure).
    """
    period = 1.0 / spec.camera_rate
    rows, t, previous = [], IDLE, np.zeros(3)
    for reading in Theta:
        arrive = t + spec.move_time[0] + spec.move_time[1] * np.max(np.abs(reading - previous))
        first = np.ceil((arrive + spec.settle) / period) * period
        if spec.rest_time is None:
            end = first + (spec.frames_per_pose - 0.5) * period
            leave = end + TAIL
        else:
            end = leave = arrive + spec.rest_time
        rows.append((t, arrive, first, end, leave))
        t, previous = leave, reading
    return np.array(rows)


def frames(t0, t1, spec):
    """Return the frame times of the camera clock in [t0, t1] (s)."""
    period = 1.0 / spec.camera_rate
    return np.arange(np.ceil(t0 / period - 1e-6), np.floor(t1 / period + 1e-6) + 1) * period


def readings(t, Theta, times, overshoot=0.0):
    """
    Return noise-free readings at t, (n, 3): moves 10 s^3 - 15 s^4 + 6 s^5 between rests.

    With ``overshoot`` (K, 3) rad, each joint passes rest k by that much and comes back the same
    way in OVERSHOOT_TIME after arriving, as a controller does.
    """
    starts = np.concatenate([[-np.inf], times[:, 0]])
    # 0: idle at home; k: moving to or at rest k
    k = np.searchsorted(starts, t, side='right') - 1
    frm = np.vstack([np.zeros((2, 3)), Theta])[k]          # where the move to rest k started
    to = np.vstack([np.zeros((1, 3)), Theta])[k]
    start = np.concatenate([[0.0], times[:, 0]])[k]
    duration = np.concatenate([[1.0], times[:, 1] - times[:, 0]])[k]
    past = np.vstack([np.zeros((1, 3)), np.broadcast_to(overshoot, Theta.shape)])[k]
    past = past * np.sign(to - frm)
    s = np.clip((t - start) / duration, 0.0, 1.0)[:, None]
    back = np.clip((t - start - duration) / OVERSHOOT_TIME, 0.0, 1.0)[:, None]
    return frm + (to + past - frm) * _smooth(s) - past * _smooth(back)


def overshoots(spec, K):
    """Return how far each joint passes each rest (K, 3), rad: ``overshoot`` in a random share."""
    chosen = np.random.default_rng([spec.seed, 7]).random((K, 3)) < spec.overshoot_fraction
    return spec.overshoot * chosen


def _smooth(s):
    return s ** 3 * (10 - 15 * s + 6 * s ** 2)


@functools.lru_cache(maxsize=1)
def typestore():
    """Build the ROS 2 Jazzy typestore with robotenis_interfaces/RestMarker (installed .msg)."""
    from ament_index_python.packages import get_package_share_directory
    store = get_typestore(Stores.ROS2_JAZZY)
    name = 'robotenis_interfaces/msg/RestMarker'
    path = os.path.join(get_package_share_directory('robotenis_interfaces'), 'msg',
                        'RestMarker.msg')
    with open(path) as f:
        store.register(get_types_from_msg(f.read(), name))
    return store


def png(pixels):
    """Encode a mono8 image as lossless PNG bytes."""
    ok, data = cv2.imencode('.png', pixels)
    assert ok, 'OpenCV could not encode a mono8 image as PNG'
    return data.tobytes()


class _Messages:
    """Builds the rosbags message objects of the simulated topics."""

    def __init__(self, frame_id):
        self.types = typestore().types
        self.frame_id = frame_id

    def header(self, t, frame_id=''):
        ns = START_NS + int(round(t * 1e9))
        return self.types['std_msgs/msg/Header'](
            stamp=self.types['builtin_interfaces/msg/Time'](sec=ns // 10 ** 9,
                                                            nanosec=ns % 10 ** 9),
            frame_id=frame_id)

    def joint_state(self, t, position, names):
        return self.types['sensor_msgs/msg/JointState'](
            header=self.header(t), name=list(names),
            position=np.asarray(position, dtype=float), velocity=np.zeros(0), effort=np.zeros(0))

    def point(self, t, p):
        Point = self.types['geometry_msgs/msg/Point']
        return self.types['geometry_msgs/msg/PointStamped'](header=self.header(t, self.frame_id),
                                                            point=Point(x=p[0], y=p[1], z=p[2]))

    def marker(self, t, index, start):
        return self.types['robotenis_interfaces/msg/RestMarker'](header=self.header(t),
                                                                 pose_index=index, start=start)

    def camera_info(self, t):
        c = CAMERA
        K = np.array([c['fx'], 0, c['cx'], 0, c['fy'], c['cy'], 0, 0, 1], dtype=float)
        roi = self.types['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0,
                                                             width=0, do_rectify=False)
        return self.types['sensor_msgs/msg/CameraInfo'](
            header=self.header(t, self.frame_id), height=c['height'], width=c['width'],
            distortion_model='plumb_bob', d=np.zeros(5), k=K, r=np.eye(3).ravel(),
            p=np.insert(K.reshape(3, 3), 3, 0, axis=1).ravel(), binning_x=0, binning_y=0, roi=roi)

    def image(self, t, pixels, compressed):
        if compressed:
            return self.types['sensor_msgs/msg/CompressedImage'](
                header=self.header(t, self.frame_id), format=PNG_FORMAT,
                data=np.frombuffer(png(pixels), dtype=np.uint8))
        h, w = pixels.shape
        return self.types['sensor_msgs/msg/Image'](
            header=self.header(t, self.frame_id), height=h, width=w, encoding='mono8',
            is_bigendian=0, step=w, data=pixels.ravel())


def render(sphere, radius, rng):
    """Render a hand camera mono8 frame: ball (shaded disc) on a dark background, 2 DN of noise."""
    x, y, z = sphere
    u, v = CAMERA['fx'] * x / z + CAMERA['cx'], CAMERA['fy'] * y / z + CAMERA['cy']
    r = CAMERA['fx'] * radius / z
    vv, uu = np.mgrid[0:CAMERA['height'], 0:CAMERA['width']]
    rho2 = ((uu - u) ** 2 + (vv - v) ** 2) / r ** 2
    image = (40.0 + 150.0 * np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0))
             + rng.normal(scale=2.0, size=rho2.shape))
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def corrupt(values, spec, rng, false_offsets=True):
    """Corrupt in place: NaN/inf, false detections (sphere positions); return the kept mask."""
    n = len(values)
    bad = rng.random(n) < spec.nan_fraction
    values[bad] = np.where(rng.random((int(bad.sum()), 1)) < 0.5, np.nan, np.inf)
    if false_offsets:
        false = (rng.random(n) < spec.false_fraction) & ~bad
        direction = rng.normal(size=(int(false.sum()), 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        values[false] += direction * rng.uniform(*FALSE_OFFSET, size=(len(direction), 1))
    return rng.random(n) >= spec.drop_fraction


def image_topic(spec):
    """Return where the simulated images go: PNG on .../compressed, raw otherwise."""
    return '/camera/image_raw/compressed' if spec.compressed_images else '/camera/image_raw'


def _joint_states(t0, t1, Theta, times, overshoot, spec, msgs, rngs):
    """
    Return (time, topic, message) of joint states in [t0, t1): quantised noisy readings, corrupted.

    ``overshoot``: each joint's past each rest (K, 3, ``overshoots``); ``rngs``: generators of the
    noise and of the corruption (separate, so that a corrupted bag has the noise of the clean one).
    """
    rng, bad_rng = rngs
    t = np.arange(np.ceil(t0 * spec.joint_rate), np.ceil(t1 * spec.joint_rate)) / spec.joint_rate
    raw = (readings(t, Theta, times, overshoot)
           + rng.normal(scale=RESOLVER.noise, size=(len(t), 3)))
    Th = np.round(raw / RESOLVER.resolution) * RESOLVER.resolution
    keep = corrupt(Th, spec, bad_rng, false_offsets=False)
    stamps = jittered(t, spec, bad_rng)
    return [(ti, '/joint_states', msgs.joint_state(ti, p, spec.joints))
            for ti, p, ok in zip(stamps, Th, keep) if ok]


def jittered(t, spec, rng):
    """Return the header stamps of samples taken at t, with the driver's jitter."""
    if not spec.stamp_jitter:
        return t
    return t + rng.normal(scale=spec.stamp_jitter, size=len(t))


def _rest(k, times, sphere, spec, msgs, rngs, radius):
    """Return (time, topic, message) of rest k's camera frames, markers and images."""
    rng, bad_rng = rngs
    tf = frames(times[k, 1], times[k, 3], spec)
    a, tau, f = spec.vibration
    axis = rng.normal(size=3)
    shake = a * np.exp(-(tf - times[k, 1]) / tau) * np.sin(2 * np.pi * f * (tf - times[k, 1]))
    own = rng.normal(size=3) * np.asarray(spec.rest_floor) if np.any(spec.rest_floor) else 0.0
    p = (sphere[k] + own + shake[:, None] * axis / np.linalg.norm(axis)
         + rng.normal(size=(len(tf), 3)) * FRAME_SIGMA)
    keep = corrupt(p, spec, bad_rng)
    out = [(ti, '/sphere/position', msgs.point(ti, pi))
           for ti, pi, ok in zip(jittered(tf, spec, bad_rng), p, keep) if ok]
    if spec.markers:
        out += [(times[k, 2], '/calibration/rest', msgs.marker(times[k, 2], k, True)),
                (times[k, 3], '/calibration/rest', msgs.marker(times[k, 3], k, False))]
    if spec.images_per_pose:
        measured = frames(times[k, 2], times[k, 3], spec)
        picked = np.linspace(0, len(measured) - 1, spec.images_per_pose).round().astype(int)
        for ti in measured[picked]:
            out.append((ti, image_topic(spec),
                        msgs.image(ti, render(sphere[k], radius, rng), spec.compressed_images)))
    return out


def _segments(declared, Theta, sphere, times, spec, msgs, rngs):
    """Yield lists of (time, topic, message): the idle start, then each move with its rest."""
    robot_description = msgs.types['std_msgs/msg/String'](data=description.dumps(declared))
    overshoot = overshoots(spec, len(Theta))
    yield [(0.0, '/robot_description', robot_description),
           (0.0, '/camera/camera_info', msgs.camera_info(0.0))] + \
        _joint_states(0.0, times[0, 0], Theta, times, overshoot, spec, msgs, rngs)
    for k in range(len(Theta)):
        yield _joint_states(times[k, 0], times[k, 4], Theta, times, overshoot, spec, msgs,
                            rngs) + \
            _rest(k, times, sphere, spec, msgs, rngs, declared.sphere_radius)


def write(path, spec=BagSpec(), progress=None):
    """
    Simulate a session and record it to the new bag directory ``path``; return a SimulatedBag.

    ``progress(k, K)`` is called after each rest.
    """
    declared, Theta, sphere, P_true = plan(spec)
    rngs = (np.random.default_rng(spec.seed + 1), np.random.default_rng(spec.seed + 2))
    times = schedule(Theta, spec)
    topics = [t for t in TOPICS
              if t not in spec.omit and (t != '/calibration/rest' or spec.markers)
              and (not t.startswith('/camera/image')
                   or (spec.images_per_pose and t == image_topic(spec)))]
    counts = dict.fromkeys(topics, 0)
    store = typestore()
    bag = Writer(Path(path), version=9, storage_plugin=StoragePlugin[spec.storage.upper()])
    bag.open()
    try:
        connections = {t: bag.add_connection(t, TOPICS[t], typestore=store) for t in topics}
        segments = _segments(declared, Theta, sphere, times, spec,
                             _Messages(declared.camera_frame_id), rngs)
        for k, segment in enumerate(segments):
            for t, topic, msg in sorted(segment, key=lambda item: item[0]):
                if topic in counts:
                    bag.write(connections[topic], START_NS + int(round(t * 1e9)) + LATENCY_NS,
                              store.serialize_cdr(msg, TOPICS[topic]))
                    counts[topic] += 1
            if progress:
                progress(k, len(Theta))
    finally:
        bag.close()
    return SimulatedBag(str(path), declared, Theta, sphere, times[:, 2:4] + START_NS * 1e-9,
                        counts, P_true)


def truncate(bag_dir, keep_fraction, drop_metadata=False):
    """
    Cut the bag's MCAP file to ``keep_fraction`` of its size, as when the recording process dies.

    With ``drop_metadata``, metadata.yaml is removed too.
    """
    bag = Path(bag_dir)
    (mcap,) = bag.glob('*.mcap')
    with open(mcap, 'r+b') as f:
        f.truncate(int(mcap.stat().st_size * keep_fraction))
    if drop_metadata:
        (bag / 'metadata.yaml').unlink()
