"""
From a recorded calibration session (any rosbag2 bag) to a Session.

A Session holds one averaged measurement per rest.

Topics (a missing one is a ValueError naming it); times are the messages' header stamps:

* /robot_description (std_msgs/String): the declared robot description YAML (the first one is
  used);
* /joint_states (sensor_msgs/JointState): positions of motor_1..3, names in any order: resolver
  increments from home, rad;
* /sphere/position (geometry_msgs/PointStamped): the sphere centre in the camera optical frame, m;
* /calibration/rest (robotenis_interfaces/RestMarker), optional: start and end of each measurement.

Rests. With markers, a rest is the time between a pose's start and end markers (the session waited
for the robot to settle before the start marker). Without them, rests are found from the joint
states: the robot is still where, on every joint, the mean reading over half a window (m samples,
``window`` / 2) and the mean over the next half window differ by at most

    delta = k sqrt(2 / m) sigma + q,

k standard deviations of that difference under noise alone (sigma: the readings' noise, from the
median absolute difference of consecutive readings, i.e. mostly from the rests) plus one count q of
the resolvers (the smallest step between two readings), which a reading sitting on a count boundary
may flip without moving: a speed threshold of delta / (m dt). A still period is a rest if it lasts
at least ``min_duration``; its first ``settle`` seconds are skipped (vibrations of the robot and of
the ball's holder that the joints do not show).

Averaging, per rest and over the same window for both sensors: non-finite samples are dropped, then
``robust_mean`` rejects outliers (false detections): a median/MAD start, then a chi-square gate at
level ``alpha`` against the spread, iterated with the mean and covariance of the other samples kept
(leave one out: the gate is exact for Gaussian samples, however few). The covariance of the mean is
S / n * (n - 1) / (n - p - 2), S the covariance of one sample: its inverse is then an unbiased
estimate of the mean's precision (the mean of an inverse Wishart), so chi-square statistics keep
their expectation even with few frames per rest. Readings use per-joint variances (p = 1) with a
floor of q^2 / 12 per sample (a joint whose readings never change still has the quantisation
spread). Samples are taken as independent: camera frames are; resolver noise at rest is white in
the simulator. A rest with fewer than ``min_samples`` good camera frames or readings is skipped
with a note.
"""
from dataclasses import dataclass

import numpy as np
from robotenis_calibration import bag_io
from robotenis_calibration.session import Session
from robotenis_kinematics import description
from robotenis_ros.convert import joint_vector
from robotenis_ros.names import JOINTS
from scipy import stats

REQUIRED = {
    '/robot_description': 'std_msgs/msg/String',
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/sphere/position': 'geometry_msgs/msg/PointStamped',
}
MARKERS = ('/calibration/rest', 'robotenis_interfaces/msg/RestMarker')
MAX_PASSES = 50       # of the outlier gate; it settles in a few
START_ALPHA = 1e-6    # the first, robust gate (median and MAD) only takes out gross outliers
# m: floor on a frame's standard deviation, far below any detector's; keeps the gate defined
SPHERE_FLOOR = 1e-9


@dataclass(frozen=True)
class RestParameters:
    """How rests are found (without markers) and averaged; see the module docstring."""

    window: float = 0.2         # s: two half windows whose mean readings are compared
    k: float = 5.0              # noise standard deviations of that difference allowed at rest
    min_duration: float = 0.5   # s: a shorter still period is not a rest
    settle: float = 0.5         # s skipped at the start of a rest found from the joint states
    min_samples: int = 20       # good camera frames (and readings) a rest needs
    alpha: float = 1e-3         # outlier gate: a good sample is rejected with this probability


@dataclass
class Recording:
    """
    The time series of a bag.

    Stamps in s, readings (n, 3) rad, sphere centres (m, 3) m, markers
    [(stamp, pose index, start)].
    """

    description: object
    t_joint: np.ndarray
    Theta: np.ndarray
    t_sphere: np.ndarray
    sphere: np.ndarray
    markers: list


def check_topics(reader):
    """Raise ValueError naming a required topic that is missing, of another type, or empty."""
    why = f' ({"; ".join(reader.notes)})' if reader.notes else ''
    for topic, type_name in REQUIRED.items():
        if topic not in reader.topics:
            have = ', '.join(sorted(reader.topics)) or 'none'
            raise ValueError(f'{reader.path}: the bag has no {topic} topic ({type_name});'
                             f' its topics: {have}{why}')
        if reader.topics[topic] != type_name:
            raise ValueError(f'{topic}: expected {type_name}, the bag has {reader.topics[topic]}')
        if reader.counts[topic] == 0:
            raise ValueError(f'{topic}: no messages in the bag {reader.path}{why}')


def read(reader, notes, progress=None):
    """Read the Recording of an open BagReader (time order), counting odd messages in ``notes``."""
    check_topics(reader)
    topics = list(REQUIRED) + ([MARKERS[0]] if reader.topics.get(MARKERS[0]) == MARKERS[1] else [])
    text, joints, spheres, markers, unnamed = None, [], [], [], 0
    report = ((lambda done, total: progress(f'read {done} of {total} messages')) if progress
              else None)
    for topic, _, stamp, msg in reader.messages(topics, report, steps=10):
        t = stamp * 1e-9
        if topic == '/joint_states':
            position = joint_vector(msg, 'position')
            if position is None:
                unnamed += 1
            else:
                joints.append([t, *position])
        elif topic == '/sphere/position':
            spheres.append((t, msg.point.x, msg.point.y, msg.point.z))
        elif topic == MARKERS[0]:
            markers.append((t, int(msg.pose_index), bool(msg.start)))
        elif text is None:          # /robot_description: the first one
            text = msg.data
    if unnamed:
        notes.append(f'{unnamed} /joint_states messages without positions of'
                     f' {", ".join(JOINTS)} ignored')
    try:
        declared = description.loads(text)
    except ValueError as e:
        raise ValueError(f'/robot_description: {e}') from e
    J = _sorted(np.array(joints, dtype=float).reshape(-1, 4))
    finite = np.all(np.isfinite(J), axis=1)
    if not finite.any():
        raise ValueError(f'/joint_states: no message has finite positions of {", ".join(JOINTS)}')
    if not finite.all():
        notes.append(f'{int((~finite).sum())} /joint_states readings with NaN or infinite values'
                     ' dropped')
    J = J[finite]
    S = _sorted(np.array(spheres, dtype=float).reshape(-1, 4))
    return Recording(declared, J[:, 0], J[:, 1:], S[:, 0], S[:, 1:], sorted(markers))


def _sorted(rows):
    return rows[np.argsort(rows[:, 0], kind='stable')]


def marked_windows(markers, notes):
    """(start, end, label) of each pose between its start and end markers, in time order."""
    open_, windows = {}, []
    for t, index, start in markers:
        if start:
            open_[index] = t
        elif index in open_:
            windows.append((open_.pop(index), t, f'pose {index}'))
    for index in sorted(open_):
        notes.append(f'pose {index}: rest without an end marker (bag cut short?), skipped')
    return sorted(windows)


def resolver_noise(Theta):
    """
    Return the noise standard deviation (3,) and count size q (3,) of the readings.

    See the module docstring; steps below the readings' float resolution are rounding, not counts.
    """
    d = np.diff(Theta, axis=0)
    sigma = 1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0) / np.sqrt(2)
    resolution = 4 * np.finfo(float).eps * np.max(np.abs(Theta), axis=0)
    q = np.array([np.min(np.abs(col[np.abs(col) > r]), initial=np.inf)
                  for col, r in zip(d.T, resolution)])
    return sigma, np.where(np.isfinite(q), q, 0.0)


def still_periods(t, Theta, params=RestParameters()):
    """(start, end) times of the periods where all joints stay still for at least min_duration."""
    dt = np.median(np.diff(t)) if len(t) > 1 else np.inf
    m = max(2, int(round(params.window / 2 / dt))) if np.isfinite(dt) and dt > 0 else 2
    if len(t) < 2 * m + 1:
        return []
    c = np.vstack([np.zeros((1, 3)), np.cumsum(Theta - Theta[0], axis=0)])
    i = np.arange(m, len(t) - m + 1)
    difference = (c[i + m] - 2 * c[i] + c[i - m]) / m
    sigma, q = resolver_noise(Theta)
    rounding = 8 * np.finfo(float).eps * np.max(np.abs(c), axis=0) / m   # of the cumulative sums
    threshold = params.k * np.sqrt(2.0 / m) * sigma + q + rounding
    still = np.all(np.abs(difference) <= threshold, axis=1)
    edges = np.diff(np.concatenate([[0], still.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    periods = [(t[i[a]], t[i[b - 1]]) for a, b in zip(starts, ends)]
    return [(a, b) for a, b in periods if b - a >= params.min_duration]


def found_windows(rec, params):
    """(start, end, label) of the rests found from the joint states, after the settle margin."""
    t_first = rec.t_joint[0]
    return [(a + params.settle, b, f'rest at {a - t_first:.1f} s')
            for a, b in still_periods(rec.t_joint, rec.Theta, params) if b > a + params.settle]


def robust_mean(x, floor, alpha):
    """
    Return the mean (p,), covariance of one sample (p, p) and mask of samples kept, outliers out.

    Start from the median and the MAD (scaled to a standard deviation), gated at the chi2(p)
    quantile 1 - START_ALPHA (gross outliers only); then, until the kept set does not change, test
    every sample against the mean and covariance of the other kept samples (``loo_gate``: exact for
    Gaussian samples, so a good sample is rejected with probability alpha whatever their number).
    The covariance is divided by the share of a Gaussian's variance such a gate keeps
    (P(chi2(p+2) <= g) / P(chi2(p) <= g)); ``floor`` (p,) bounds each variance from below.
    """
    p = x.shape[1]
    gate = stats.chi2.ppf(1 - alpha, p)
    consistency = stats.chi2.cdf(gate, p + 2) / (1 - alpha)
    center = np.median(x, axis=0)
    cov = np.diag(np.maximum((1.4826 * np.median(np.abs(x - center), axis=0)) ** 2, floor))
    d = x - center
    keep = np.einsum('ni,ij,nj->n', d, np.linalg.inv(cov), d) <= stats.chi2.ppf(1 - START_ALPHA, p)
    for _ in range(MAX_PASSES):
        if keep.sum() < p + 3:
            break
        center = x[keep].mean(axis=0)
        cov = np.cov(x[keep], rowvar=False).reshape(p, p) / consistency
        cov += np.diag(np.maximum(floor - np.diag(cov), 0.0))
        new = loo_gate(x, keep, center, cov, alpha)
        if np.array_equal(new, keep) or new.sum() < p + 3:
            break
        keep = new
    return center, cov, keep


def loo_gate(x, keep, center, cov, alpha):
    """
    Return the mask of samples within the level-alpha gate of the other kept samples.

    For a Gaussian sample x tested against the mean and unbiased covariance of m others,
    D^2 m / (m + 1) (m - p) / (p (m - 1)) follows F(p, m - p) (Hotelling). A kept sample's D^2
    follows from its distance d^2 to the estimate that includes it (n = m + 1 samples):
    D^2 = (n - 2) n^2 d^2 / ((n - 1) ((n - 1)^2 - n d^2)).
    """
    n, p = int(keep.sum()), x.shape[1]
    d = x - center
    d2 = np.einsum('ni,ij,nj->n', d, np.linalg.inv(cov), d)
    inside = np.minimum(d2, (n - 1) ** 2 / n * (1 - 1e-12))     # d^2 of a kept sample is below
    D2 = np.where(keep, (n - 2) * n ** 2 * inside / ((n - 1) * ((n - 1) ** 2 - n * inside)), d2)
    m = np.where(keep, n - 1, n)
    gate = p * (m - 1) / (m - p) * (m + 1) / m * stats.f.ppf(1 - alpha, p, m - p)
    return D2 <= gate


def unbiased_precision_factor(n, p):
    """(n - 1) / (n - p - 2): scales a sample covariance so that its inverse is unbiased."""
    return (n - 1) / (n - p - 2)


# rad: a joint this far from its rest value was moving toward it (5 counts and the noise)
MOVED = 2e-4


def approach_direction(t_joint, Theta, t0, rest, previous):
    """
    Return the sign of each joint's motion into the rest that starts at t0.

    With mean readings ``rest`` (3,): from the last reading before t0 farther than MOVED from it; a
    joint that did not move keeps ``previous``. The joint states show the motion through every pose
    visited, measured or not.
    """
    before = Theta[:np.searchsorted(t_joint, t0)]
    out = np.array(previous, dtype=float)
    for j in range(3):
        away = np.flatnonzero(np.abs(before[:, j] - rest[j]) > MOVED)
        if len(away):
            out[j] = np.sign(rest[j] - before[away[-1], j])
    return out


def average(rec, windows, params, notes):
    """Average the rests in ``windows`` into a Session (module docstring); skips go to notes."""
    _, q = resolver_noise(rec.Theta)
    rows, rejected, total, direction = [], 0, 0, np.ones(3)
    for t0, t1, label in windows:
        s0, s1 = np.searchsorted(rec.t_sphere, t0), np.searchsorted(rec.t_sphere, t1, side='right')
        j0, j1 = np.searchsorted(rec.t_joint, t0), np.searchsorted(rec.t_joint, t1, side='right')
        sphere = rec.sphere[s0:s1]
        Theta = rec.Theta[j0:j1]
        sphere = sphere[np.all(np.isfinite(sphere), axis=1)]
        if min(len(sphere), len(Theta)) < params.min_samples:
            notes.append(f'{label}: only {len(sphere)} camera frames and {len(Theta)} readings '
                         f'(at least {params.min_samples} needed), skipped')
            continue
        s, S, keep = robust_mean(sphere, np.full(3, SPHERE_FLOOR ** 2), params.alpha)
        th, T, keep_T = robust_mean(Theta, q ** 2 / 12, params.alpha)
        n, n_T = int(keep.sum()), int(keep_T.sum())
        if min(n, n_T) < params.min_samples:
            notes.append(f'{label}: only {n} camera frames and {n_T} readings agree with the rest '
                         f'(at least {params.min_samples} needed), skipped')
            continue
        rejected, total = rejected + len(sphere) - n, total + len(sphere)
        direction = approach_direction(rec.t_joint, rec.Theta, t0, th, direction)
        rows.append((th, np.sqrt(np.diag(T) / n_T * unbiased_precision_factor(n_T, 1)), s,
                     S / n * unbiased_precision_factor(n, 3), 0.5 * (t0 + t1), n, direction))
    notes.append(f'{rejected} of {total} finite camera frames in the rests rejected as outliers')
    if not rows:
        return Session(rec.description, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)),
                       np.zeros((0, 3, 3)), np.zeros(0), np.zeros(0, dtype=int), np.zeros((0, 3)))
    Theta, sigma, sphere, cov, stamps, samples, direction = (np.array(v) for v in zip(*rows))
    return Session(rec.description, Theta, sigma, sphere, cov, stamps, samples, direction)


def load_session(bag_dir, params=RestParameters(), progress=None):
    """(Session, notes) of a recorded session; ValueError naming a missing topic or bad content."""
    notes = []
    with bag_io.BagReader(bag_dir) as reader:
        rec = read(reader, notes, progress)
        notes[:0] = reader.notes
    bad = int((~np.all(np.isfinite(rec.sphere), axis=1)).sum())
    if bad:
        notes.append(f'{bad} /sphere/position messages with NaN or infinite values dropped')
    if rec.markers:
        windows = marked_windows(rec.markers, notes)
        notes.append(f'{len(windows)} rests between /calibration/rest markers')
    else:
        windows = found_windows(rec, params)
        notes.append(f'no /calibration/rest markers: {len(windows)} rests found from the joint'
                     f' states (still for at least {params.min_duration} s; the first'
                     f' {params.settle} s of each skipped)')
    return average(rec, windows, params, notes), notes
