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
``window`` / 2, at least two) and the mean over the next half window differ by at most

    delta = k sqrt(2 / m) sigma + q,

k standard deviations of that difference under noise alone (sigma: the readings' noise, from the
median absolute difference of consecutive readings, i.e. mostly from the rests) plus one count q of
the resolvers (the smallest step between two readings), which a reading sitting on a count boundary
may flip without moving: a speed threshold of delta / (m dt). A still period is a rest if it lasts
at least ``min_duration`` (default: one window). Its first seconds are skipped while the camera's
signal still moves (vibrations of the robot and of the ball's holder that the joints do not show):
the settle margin is found from the data (``settle_time``: pooled over the rests, the first time
after the joints stop from which the frames scatter as the frames' noise alone about their rest's
final position), or given (``settle``); it never leaves a rest fewer than ``min_samples``
frames.

Averaging, per rest and over the same window for both sensors. The frames' noise is learned from
all the rests at once (``FrameNoise``): along each optical axis a variance c_a (z / z_ref)^g_a
(a detector's depth noise grows with the range), fitted by maximum likelihood to the rests' sample
variances, and one correlation matrix; the readings' noise per joint likewise, at least the
quantisation's q^2 / 12. So a rest needs no minimum number of frames for its covariance: two frames
and two readings (``min_samples``) make a rest, its mean's covariance is the noise model's over the
number of samples kept. Non-finite samples are dropped; outliers (false detections) are rejected
by an exact chi-square gate at level ``alpha``: each sample against the mean of the others kept,
with the noise model's covariance, from a median start. What each rest gets wrong beyond its
frames' spread (a detector's error at that pose) is the floor the identification learns
(robotenis_kinematics.variance).
"""
from collections import Counter
from dataclasses import dataclass
import functools

import numpy as np
from robotenis_calibration import bag_io, cdr_arrays
from robotenis_calibration.session import nearest_gap, Session
from robotenis_kinematics import description
from robotenis_ros.convert import joint_vector
from robotenis_ros.names import JOINTS
from scipy.special import chdtr, chdtri, fdtri

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
Z_REFERENCE = 0.35    # m: the range the frames' noise model is written at
EXPONENTS = np.linspace(0.0, 4.0, 41)   # g of the noise model's c (z / z_ref)^g, searched
SETTLE_LEVEL = 1e-3   # the pooled test that the frames have settled, per time bin


@functools.lru_cache(maxsize=None)
def chi2_quantile(q, dof):
    """Return the chi-square quantile q of dof degrees of freedom (cached: the gates repeat)."""
    return float(chdtri(dof, 1 - q))


@dataclass(frozen=True)
class RestParameters:
    """How rests are found (without markers) and averaged; see the module docstring."""

    window: float = 0.2         # s: two half windows whose mean readings are compared
    k: float = 5.0              # noise standard deviations of that difference allowed at rest
    min_duration: float = None  # s: a shorter still period is not a rest (None: one window)
    settle: float = None        # s skipped at the start of a found rest (None: from the data)
    min_samples: int = 2        # good camera frames (and readings) a rest needs
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

    def frames(self, t0, t1):
        """Return the slice of the sphere samples stamped from t0 to t1 (s), both included."""
        return slice(np.searchsorted(self.t_sphere, t0),
                     np.searchsorted(self.t_sphere, t1, side='right'))


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


def read(reader, notes, progress=None, joints=JOINTS):
    """
    Read the Recording of an open BagReader (time order), counting odd messages in ``notes``.

    ``joints``: the names of the three joints, leg by leg, as the bag's JointState calls them.
    """
    check_topics(reader)
    raw = {topic: [] for topic in ('/joint_states', '/sphere/position')}
    report = ((lambda done, total: progress(f'read {done} of {total} messages')) if progress
              else None)
    for record in reader.records(list(raw), report, steps=10):
        raw[record.topic].append(record)
    t_joint, Theta = _joint_states(raw['/joint_states'], joints, reader, notes)
    t_sphere, sphere = _points(raw['/sphere/position'], reader)
    declared = _declared(reader, notes)
    markers = []
    if reader.topics.get(MARKERS[0]) == MARKERS[1]:
        markers = sorted((stamp * 1e-9, int(msg.pose_index), bool(msg.start))
                         for _, _, stamp, msg in reader.messages([MARKERS[0]]))
    J = _sorted(np.column_stack([t_joint, Theta]))
    finite = np.all(np.isfinite(J), axis=1)
    if not finite.any():
        raise ValueError(f'/joint_states: no message has finite positions of {", ".join(joints)}')
    if not finite.all():
        notes.append(f'{int((~finite).sum())} /joint_states readings with NaN or infinite values'
                     ' dropped')
    J = J[finite]
    S = _sorted(np.column_stack([t_sphere, sphere]))
    return Recording(declared, J[:, 0], J[:, 1:], S[:, 0], S[:, 1:], markers)


def _stamp_seconds(stamps_ns, records):
    """Return header stamps in s, the recording time where a stamp is zero."""
    log = np.fromiter((r.log_ns for r in records), dtype=np.int64, count=len(records))
    return np.where(stamps_ns != 0, stamps_ns, log) * 1e-9


def _joint_states(records, joints, reader, notes):
    """Return the stamps (n,) and readings of ``joints`` (n, 3) of the JointState records."""
    stamps, values, ok, names = cdr_arrays.joint_positions([r.data for r in records], joints)
    broken, unnamed = Counter(), 0
    for i in np.flatnonzero(~ok):               # layouts the arrays could not read: one by one
        msg = bag_io.decode(records[i])
        if msg is None:
            broken[records[i].topic] += 1
            continue
        names.add(tuple(msg.name))
        position = joint_vector(msg, 'position', joints)
        if position is None:
            unnamed += 1
            continue
        stamps[i], values[i], ok[i] = bag_io.stamp_ns(msg, 0), position, True
    reader.note_broken(broken)
    if not ok.any():
        found = '; '.join(', '.join(n) for n in sorted(names)) or 'none'
        raise ValueError(f'/joint_states: no message has positions of {", ".join(joints)} '
                         f'(names found: {found}); name the joints with --joints')
    if unnamed:
        notes.append(f'{unnamed} /joint_states messages without positions of'
                     f' {", ".join(joints)} ignored')
    return _stamp_seconds(stamps, records)[ok], values[ok]


def _points(records, reader):
    """Return the stamps (n,) and points (n, 3) of the PointStamped records."""
    stamps, xyz, ok = cdr_arrays.points([r.data for r in records])
    broken = Counter()
    for i in np.flatnonzero(~ok):
        msg = bag_io.decode(records[i])
        if msg is None:
            broken[records[i].topic] += 1
            continue
        stamps[i], ok[i] = bag_io.stamp_ns(msg, 0), True
        xyz[i] = (msg.point.x, msg.point.y, msg.point.z)
    reader.note_broken(broken)
    return _stamp_seconds(stamps, records)[ok], xyz[ok]


def _declared(reader, notes):
    """Return the declared description: the first /robot_description, noting any others."""
    texts = [(stamp, msg.data) for _, _, stamp, msg in reader.messages(['/robot_description'])]
    if not texts:
        raise ValueError('/robot_description: no message could be decoded')
    texts.sort(key=lambda item: item[0])
    if len(texts) > 1:
        differ = sum(text != texts[0][1] for _, text in texts[1:])
        notes.append(f'{len(texts)} /robot_description messages ({differ} different from the '
                     f'first): the first, at {texts[0][0] * 1e-9:.3f} s, is used')
    try:
        return description.loads(texts[0][1])
    except ValueError as e:
        raise ValueError(f'/robot_description: {e}') from e


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
    # the mean interval: a median would follow the stamps' jitter, not the rate
    dt = (t[-1] - t[0]) / (len(t) - 1) if len(t) > 1 else np.inf
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
    shortest = params.window if params.min_duration is None else params.min_duration
    return [(a, b) for a, b in periods if b - a >= shortest]


def found_windows(rec, params, notes):
    """Return (start, end, label) of the rests found from the joint states, after settling."""
    periods = still_periods(rec.t_joint, rec.Theta, params)
    settle = params.settle
    if settle is None:
        settle = settle_time(rec, periods)
        notes.append(f'settle margin found from the data: {settle:.3f} s after the joints stop')
    t_first, out = rec.t_joint[0], []
    for a, b in periods:
        # the margin never leaves a rest fewer frames than it needs: its last ones are the calmest
        frames = rec.t_sphere[rec.frames(a, b)]
        latest = frames[-params.min_samples] if len(frames) >= params.min_samples else a
        out.append((min(a + settle, latest), b, f'rest at {a - t_first:.1f} s'))
    return out


def settle_time(rec, periods, level=SETTLE_LEVEL):
    """
    Return the time after the joints stop from which the camera's frames have settled (s).

    Pooled over the still periods: each frame's deviation from its period's final position (the
    median of its second half) in units of the frames' noise (from differences of consecutive
    frames) is squared and summed over the axes, about 3 once settled. In bins of a frame period of
    time since the stop, the sum over a bin's frames is tested against its chi-square quantile
    1 - level; the margin is the start of the first bin from which every bin passes (at most half
    the shortest period).
    """
    deviations, since = [], []
    for a, b in periods:
        i0, i1 = np.searchsorted(rec.t_sphere, [a, b])
        frames = rec.sphere[i0:i1]
        finite = np.all(np.isfinite(frames), axis=1)
        if finite.sum() < 4:
            continue
        t, x = rec.t_sphere[i0:i1][finite] - a, frames[finite]
        deviations.append(x - np.median(x[len(x) // 2:], axis=0))
        since.append(t)
    if not deviations:
        return 0.0
    steps = np.concatenate([np.diff(d[len(d) // 2:], axis=0) for d in deviations])
    sigma = np.maximum(1.4826 * np.median(np.abs(steps), axis=0) / np.sqrt(2), SPHERE_FLOOR)
    chi2 = np.sum((np.concatenate(deviations) / sigma) ** 2, axis=1)
    since = np.concatenate(since)
    period = float(np.median(np.diff(rec.t_sphere))) if len(rec.t_sphere) > 1 else 0.01
    longest = 0.5 * min(b - a for a, b in periods)
    edges = np.arange(0.0, longest + period, period)
    bins = np.digitize(since, edges) - 1
    passed = []
    for j in range(len(edges) - 1):
        values = chi2[bins == j]
        # the final position is itself a median of half the frames: 2 % more spread, allowed
        passed.append(len(values) == 0 or values.sum()
                      <= 1.02 * chi2_quantile(1 - level, 3 * len(values)))
    failing = [j for j, ok in enumerate(passed) if not ok]
    return float(edges[failing[-1] + 1]) if failing else 0.0


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
    gate = chi2_quantile(1 - alpha, p)
    consistency = chdtr(p + 2, gate) / (1 - alpha)
    center = np.median(x, axis=0)
    cov = np.diag(np.maximum((1.4826 * np.median(np.abs(x - center), axis=0)) ** 2, floor))
    d = x - center
    keep = np.einsum('ni,ij,nj->n', d, np.linalg.inv(cov), d) <= chi2_quantile(1 - START_ALPHA, p)
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
    gate = p * (m - 1) / (m - p) * (m + 1) / m * fdtri(p, m - p, 1 - alpha)
    return D2 <= gate


@dataclass
class FrameNoise:
    """
    The noise of one sample, learned from every rest: per axis a variance c (z / z_ref)^g.

    ``c`` (p,) and ``g`` (p,) per axis, ``correlation`` (p, p); for the readings g is zero.
    """

    c: np.ndarray
    g: np.ndarray
    correlation: np.ndarray

    def covariance(self, z):
        """Return one sample's covariance matrices, (K, p, p), at the ranges z (K,), m."""
        scale = (np.asarray(z, dtype=float)[:, None] / Z_REFERENCE) ** self.g
        sd = np.sqrt(self.c * scale)
        return sd[:, :, None] * self.correlation * sd[:, None, :]

    def as_dict(self):
        """Return the model as plain data (for a result file)."""
        return {'variance_at_reference': self.c.tolist(), 'range_exponent': self.g.tolist(),
                'correlation': self.correlation.tolist(), 'reference_range': Z_REFERENCE}


def frame_noise(groups, z, floor, grow=True):
    """
    Return the FrameNoise of samples grouped by rest (list of (n_k, p)) at ranges z (K,).

    Maximum likelihood over the rests with two or more samples: given g, the best c is the
    dof-weighted mean of s^2 / (z / z_ref)^g; g is searched over EXPONENTS (``grow`` False: 0).
    ``floor`` (p,) bounds c from below. A rest whose spread the model cannot have given, its
    (n - 1) s^2 / (c (z / z_ref)^g) beyond chi2(n - 1)'s quantile 1 - START_ALPHA on an axis (the
    robot moving during it, two things taken for the ball: too few samples for the gate within
    the rest), is left out and the model fitted again, until the rests kept repeat: one such
    rest made the whole bag's noise a thousand times too large.
    """
    used = [k for k, x in enumerate(groups) if len(x) >= 2]
    p = groups[used[0]].shape[1] if used else len(floor)
    if not used:
        return FrameNoise(np.asarray(floor, dtype=float), np.zeros(p), np.eye(p))
    dof = np.array([len(groups[k]) - 1 for k in used], dtype=float)
    resid = [groups[k] - groups[k].mean(axis=0) for k in used]
    s2 = np.array([np.sum(r ** 2, axis=0) for r in resid]) / dof[:, None]
    zr = np.asarray(z, dtype=float)[used] / Z_REFERENCE
    gate = np.array([chi2_quantile(1 - START_ALPHA, int(n)) for n in dof])
    keep = np.ones(len(used), dtype=bool)
    for _ in range(MAX_PASSES):
        c, g = _noise_fit(dof[keep], s2[keep], zr[keep], floor, grow)
        model = c * zr[:, None] ** g
        agree = np.all(dof[:, None] * s2 <= gate[:, None] * model, axis=1)
        if np.array_equal(agree, keep) or not agree.any():
            break
        keep = agree
    sd = np.sqrt(model)
    u = np.concatenate([r / sd[i] for i, r in enumerate(resid) if keep[i]])
    moment = u.T @ u / np.sum(dof[keep])
    d = np.sqrt(np.diag(moment))
    return FrameNoise(c, g, moment / np.outer(d, d))


def _noise_fit(dof, s2, zr, floor, grow):
    """Return (c, g) per axis: frame_noise's maximum likelihood over rests' variances s2 (K, p)."""
    p = s2.shape[1]
    c, g = np.empty(p), np.empty(p)
    for a in range(p):
        best = None
        for exponent in (EXPONENTS if grow else [0.0]):
            shape = zr ** exponent
            ca = max(np.sum(dof * s2[:, a] / shape) / np.sum(dof), floor[a])
            loss = np.sum(dof * (np.log(ca * shape) + s2[:, a] / (ca * shape)))
            if best is None or loss < best[0]:
                best = (loss, ca, exponent)
        _, c[a], g[a] = best
    return c, g


def known_gate(x, cov, alpha):
    """
    Return the mask of samples (n, p) within the level-alpha gate, with a known covariance (p, p).

    A good sample x minus the mean of m others is N(0, (1 + 1/m) cov): its squared Mahalanobis
    distance over (1 + 1/m) follows chi2(p) exactly. From the median, until the kept set repeats.
    """
    n, p = x.shape
    inverse = np.linalg.inv(cov)
    d = x - np.median(x, axis=0)
    keep = np.einsum('ni,ij,nj->n', d, inverse, d) <= chi2_quantile(1 - START_ALPHA, p)
    gate = chi2_quantile(1 - alpha, p)
    for _ in range(MAX_PASSES):
        m = int(keep.sum())
        if m < 2:
            return keep
        total = x[keep].sum(axis=0)
        others = np.where(keep[:, None], (total - x) / max(m - 1, 1), total / m)
        count = np.where(keep, m - 1, m)
        d = x - others
        new = np.einsum('ni,ij,nj->n', d, inverse, d) / (1 + 1 / count) <= gate
        if np.array_equal(new, keep):
            break
        keep = new
    return keep


MOVED = 2e-4    # rad: the smallest gap tried (5 counts of the resolvers and their noise)
# rad: gaps a side may be taken at, 0.2 to 14 mrad, 5 % apart. Which rests' sides a gap gets
# right changes within a tenth of the width: on five live bags of a 0.6 mrad play (the simulator's
# readings are 38 urad counts) its sides came out right at gaps of 0.68-0.71 mrad, 3-8 wrong at
# 0.61 and 4-5 at 0.76, the neighbours of a 25 % grid, and those few wrong sides were most of the
# held-out error (backlash_gaps chooses among these; live_links scores the sides).
GAPS = MOVED * 1.05 ** np.arange(88)
# the sides before any backlash is known: a reversal shorter than a coarse gear's backlash (about
# 10 arcmin) is taken for a controller's overshoot, which leaves the contact where it was
START_GAP = int(nearest_gap(GAPS, 3e-3)[0])


def approach_directions(t_joint, Theta, t0, previous, since=-np.inf, gaps=GAPS):
    """
    Return each joint's backlash contact side at the rest that starts at t0, per gap (G, 3).

    A backlash of width g is a play (hysteresis) between motor and arm: the contact changes side
    only when the motor, which the resolvers read, travels back across the whole gap. So the side
    is that of the last stretch of readings in [since, t0) that spans g: +1 if it rose from its
    lowest reading, -1 if it fell from its highest, whatever the rest's own value (a reversal
    across the gap may straddle it). A joint whose readings since then span less than g keeps
    ``previous`` (G, 3), the sides of the rest before, which started at ``since``. The joint
    states show the motion through every pose visited, measured or not.
    """
    before = Theta[np.searchsorted(t_joint, since):np.searchsorted(t_joint, t0)]
    out = np.array(previous, dtype=float)
    for j in range(3):
        x = before[:, j]
        # the span of the readings from each one on shrinks with time: the last stretch that
        # spans g starts at the last index where that span is still at least g
        highest = np.maximum.accumulate(x[::-1])[::-1]
        span = highest - np.minimum.accumulate(x[::-1])[::-1]
        last = np.searchsorted(-span, -np.asarray(gaps), side='right') - 1
        crossed = last >= 0
        out[crossed, j] = np.where(x[last[crossed]] >= highest[last[crossed]], -1.0, 1.0)
    return out


# rad/s: speeds of the other family of sides, 0.05 to 1.8 rad/s, 25 % apart; the slowest are
# within the resolvers' 1-2 counts a reading (0.04-0.08 rad/s at 1 kHz and 38 urad counts), where
# a dither at rest reads as motion: the fit refuses those when they give wrong sides
SPEEDS = 0.05 * 1.25 ** np.arange(17)


def fast_motion_sides(t_joint, Theta, t0, previous, since=-np.inf, speeds=SPEEDS):
    """
    Return each joint's contact side at the rest that starts at t0, per speed (V, 3).

    The other family of backlash sides: a drive whose contact takes the side of its last motion
    faster than v between successive readings, and keeps it through slower motion (a creep back
    after an overshoot, a controller's dither at rest, a load the motor follows). A gap crossed
    within one reading period reads as such a step. So the side is the sign of the last step in
    [since, t0) faster than v; a joint without one keeps ``previous`` (V, 3), the sides of the
    rest before. approach_directions' travel across a gap is the first family; the fit chooses
    (pipeline.backlash_gaps).
    """
    i0, i1 = np.searchsorted(t_joint, since), np.searchsorted(t_joint, t0)
    step = np.diff(Theta[i0:i1], axis=0)
    dt = np.diff(t_joint[i0:i1])
    speed = np.abs(step) / np.where(dt > 0, dt, np.inf)[:, None]
    out = np.array(previous, dtype=float)
    for j in range(3):
        # the fastest step from each one on shrinks with time: the last step faster than v is
        # at the last index where that maximum still exceeds v
        fastest = np.maximum.accumulate(speed[::-1, j])[::-1]
        last = np.searchsorted(-fastest, -np.asarray(speeds), side='left') - 1
        crossed = last >= 0
        out[crossed, j] = np.sign(step[last[crossed], j])
    return out


def average(rec, windows, params, notes):
    """Average the rests in ``windows`` into a Session (module docstring); skips go to notes."""
    _, q = resolver_noise(rec.Theta)
    spheres, readings, kept_windows = [], [], []
    for t0, t1, label in windows:
        j0, j1 = np.searchsorted(rec.t_joint, t0), np.searchsorted(rec.t_joint, t1, side='right')
        sphere = rec.sphere[rec.frames(t0, t1)]
        sphere = sphere[np.all(np.isfinite(sphere), axis=1)]
        if min(len(sphere), j1 - j0) < params.min_samples:
            notes.append(f'{label}: only {len(sphere)} camera frames and {j1 - j0} readings '
                         f'(at least {params.min_samples} needed), skipped')
            continue
        spheres.append(sphere)
        readings.append(rec.Theta[j0:j1])
        kept_windows.append((t0, t1, label))
    if not spheres:
        return _empty(rec.description)
    z = np.array([np.median(x[:, 2]) for x in spheres])
    # the noise models from provisionally cleaned samples, then the exact gate with them
    camera = frame_noise([x[_provisional(x)] for x in spheres], z, np.full(3, SPHERE_FLOOR ** 2))
    joints = frame_noise(readings, z, q ** 2 / 12, grow=False)
    camera_cov, joint_cov = camera.covariance(z), joints.covariance(z)
    rows, rejected, total, since = [], 0, 0, -np.inf
    direction, fast = np.ones((len(GAPS), 3)), np.ones((len(SPEEDS), 3))
    for k, (t0, t1, label) in enumerate(kept_windows):
        keep = known_gate(spheres[k], camera_cov[k], params.alpha)
        keep_T = known_gate(readings[k], joint_cov[k], params.alpha)
        n, n_T = int(keep.sum()), int(keep_T.sum())
        if min(n, n_T) < params.min_samples:
            notes.append(f'{label}: only {n} camera frames and {n_T} readings agree with the rest '
                         f'(at least {params.min_samples} needed), skipped')
            continue
        rejected, total = rejected + len(keep) - n, total + len(keep)
        th = readings[k][keep_T].mean(axis=0)
        direction = approach_directions(rec.t_joint, rec.Theta, t0, direction, since)
        fast = fast_motion_sides(rec.t_joint, rec.Theta, t0, fast, since)
        since = t0
        rows.append((th, np.sqrt(np.diag(joint_cov[k]) / n_T), spheres[k][keep].mean(axis=0),
                     camera_cov[k] / n, 0.5 * (t0 + t1), n, np.vstack([direction, fast])))
    notes.append(f'{rejected} of {total} finite camera frames in the rests rejected as outliers')
    if not rows:
        return _empty(rec.description)
    Theta, sigma, sphere, cov, stamps, samples, approach = (np.array(v) for v in zip(*rows))
    return Session(rec.description, Theta, sigma, sphere, cov, stamps, samples,
                   approach[:, START_GAP], {'camera': camera.as_dict(),
                                            'resolvers': joints.as_dict()}, approach, GAPS,
                   speeds=SPEEDS)


def _provisional(x):
    """Return the mask of a rest's frames without its gross outliers, for the noise model."""
    if len(x) < 6:
        return np.ones(len(x), dtype=bool)
    return robust_mean(x, np.full(3, SPHERE_FLOOR ** 2), START_ALPHA)[2]


def _empty(declared):
    return Session(declared, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)),
                   np.zeros((0, 3, 3)), np.zeros(0), np.zeros(0, dtype=int), np.zeros((0, 3)))


def load_session(bag_dir, params=RestParameters(), progress=None, joints=JOINTS):
    """(Session, notes) of a recorded session; ValueError naming a missing topic or bad content."""
    notes = []
    with bag_io.BagReader(bag_dir) as reader:
        rec = read(reader, notes, progress, joints)
        notes[:0] = reader.notes
    bad = int((~np.all(np.isfinite(rec.sphere), axis=1)).sum())
    if bad:
        notes.append(f'{bad} /sphere/position messages with NaN or infinite values dropped')
    if rec.markers:
        windows = marked_windows(rec.markers, notes)
        notes.append(f'{len(windows)} rests between /calibration/rest markers')
    else:
        windows = found_windows(rec, params, notes)
        shortest = params.window if params.min_duration is None else params.min_duration
        notes.append(f'no /calibration/rest markers: {len(windows)} rests found from the joint'
                     f' states (still for at least {shortest} s)')
    session = average(rec, windows, params, notes)
    session.timing = rest_timing(rec, windows)
    return session, notes


def rest_timing(rec, windows):
    """
    Return the recording's pace, {'camera_rate_hz', 'rest_overhead_s'}, or None if it cannot tell.

    The rate is that of the detections within the rests (median over rests of their frames less
    one over their span: frames the detector dropped included); the overhead is the robot time a
    rest costs besides its frames: the median time from one rest's start to the next one's, less
    the median rest's frames at that rate (the move, the settling, the wait for the first frame).
    Needs two rests with two frames each.
    """
    rates, counts = [], []
    for t0, t1, _ in windows:
        t = rec.t_sphere[rec.frames(t0, t1)]
        if len(t) >= 2 and t[-1] > t[0]:
            rates.append((len(t) - 1) / (t[-1] - t[0]))
            counts.append(len(t))
    if len(rates) < 2:
        return None
    rate = float(np.median(rates))
    overhead = float(np.median(np.diff([t0 for t0, _, _ in windows])) - np.median(counts) / rate)
    if not overhead > 0:
        return None
    return {'camera_rate_hz': rate, 'rest_overhead_s': overhead}
