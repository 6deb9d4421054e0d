"""
The calibration session as a state machine, fed with time and measurements, free of ROS.

For each planned pose, in order: command it, wait until the joints are still, wait the settle time
(vibrations of the robot and the ball's holder), then average resolver readings and sphere
detections until enough frames are in; a pose whose ball is not seen within a time-out, or whose
detections stop (a ball at the edge of the view), is skipped with the reason. When
the measured rests reach each count of ``replan_after`` the poses still to come may be replaced
(``replan``: the ball is then known from those rests, not from the user's rough guess). An input
silent for longer than a pose can last (robotenis_calibration.session_limits) stops the session:
``failure`` then says which, and the session is done without its remaining poses. The
calibration node feeds it messages and executes the actions it returns.

Times are the robot's (simulated time in simulation). Given a wall ``clock``, the waits for a
detection (an input's silence, a rest's first detection) must also have lasted that long on the
wall clock: a simulator faster than real time outruns a detector that runs at its own wall-clock
pace, and its frames would otherwise look unanswered.
"""
from collections import deque
from dataclasses import dataclass, field
import math

import numpy as np
from robotenis_calibration import session_limits

MOVING, SETTLING, MEASURING, DONE = 'moving', 'settling', 'measuring', 'done'
INPUTS = {  # the inputs watched for silence: name -> what feeds it
    'joint_states': "the robot's driver (joint states)",
    'sphere/detection': 'the sphere detector (or the ball is out of view at every pose)',
}


class SlidingRange:
    """
    The range (max - min) of each joint's readings over the last ``span`` seconds, as they come.

    Per joint, the readings that can still be the window's maximum (a decreasing queue) and
    minimum (increasing), and the times of its NaN readings (a NaN in the window makes the range
    NaN, as numpy's ptp): O(1) per reading on average, where the range of the whole window costs a
    pass over its ~100 readings at 1 kHz (26 us a reading in numpy). The same max - min.
    """

    def __init__(self, span):
        self.span = span
        self.clear()

    def clear(self):
        self.first = None                 # time of the oldest reading in the window
        self._times = deque()
        self._queues = None               # per joint: (maxima, minima, NaN times)

    def add(self, t, values):
        """Add the readings (sequence of floats) at time t; drop those older than t - span."""
        if self._queues is None:
            self._queues = [(deque(), deque(), deque()) for _ in values]
        self._times.append(t)
        for v, (high, low, nan) in zip(values, self._queues):
            if v != v:
                nan.append((t, v))
                continue
            while high and high[-1][1] <= v:
                high.pop()
            high.append((t, v))
            while low and low[-1][1] >= v:
                low.pop()
            low.append((t, v))
        old = t - self.span
        while self._times[0] < old:
            self._times.popleft()
        for queues in self._queues:
            for queue in queues:
                while queue and queue[0][0] < old:
                    queue.popleft()
        self.first = self._times[0]

    def ranges(self):
        """Return each joint's max - min over the window (NaN if it holds a NaN)."""
        return [math.nan if nan or not high else high[0][1] - low[0][1]
                for high, low, nan in self._queues]


@dataclass
class Rest:
    """What was measured at one pose."""

    index: int
    start: float
    end: float
    Theta: list = field(default_factory=list)
    sphere: list = field(default_factory=list)
    sphere_cov: list = field(default_factory=list)


@dataclass
class RunnerConfig:
    frames_per_pose: int = 500
    settle_time: float = 4.0           # s, the paper's wait at each change of pose
    # Still: over still_time every joint's readings stay within still_range. Judged on positions,
    # as the speed a drive differentiates from a quantised resolver at 1 kHz flickers by a count
    # per ms (3.8e-5 rad / 1 ms = 0.04 rad/s). The range covers a count and +-4 sigma of the 2e-5
    # rad noise.
    still_range: float = 2.5e-4        # rad
    still_time: float = 0.1            # s of stillness before the settle time starts
    move_timeout: float = 10.0         # s to reach a pose
    # s a rest may take beyond its frames' own time at the detections' rate before it is skipped
    measure_timeout: float = 10.0
    # s without a single detection: ball not in view, skip. A rest's detections that stop for
    # this and two of their periods: a ball flickering at the view's edge, skip it at once
    no_ball_time: float = 0.5


class SessionRunner:
    """Drives one session; ``actions`` lists what the node must do, ``rests`` what was measured."""

    def __init__(self, poses, config=RunnerConfig(), replan=None, replan_after=(1, 6),
                 clock=None):
        """
        Prepare a session over ``poses``, visited in order.

        replan(rests, n): n poses (n, 3) to visit instead of the n still planned, or None to keep
        them; called when the measured rests reach each count in ``replan_after`` (the first
        rest tells where the ball is to the declared model's error, a few more guard against
        one wrong detection). clock(): wall seconds (monotonic), or None to wait on the robot's
        times alone (see the module).
        """
        self.poses = np.asarray(poses, dtype=float)
        self.config = config
        self.replan, self.replan_after = replan, replan_after
        self.index = -1
        self.state = MOVING
        self.rests, self.skipped = [], []
        self.failure = None               # why the session stopped early, if it did
        self.last_input = {}              # input name -> time of its last message
        self.clock = clock
        self._wall_input = {}             # input name -> wall time of its last message
        self._wall_state = None
        self.actions = []
        self._t_state = None
        self._clock_wait = None           # wall time start() began waiting for the clock
        self._window = SlidingRange(config.still_time)   # the last still_time while moving
        self._rest = None
        self._last_detection = None       # (robot, wall) time of the rest's last detection
        self._measured = [0, 0.0]         # frames and seconds of the rests measured so far
        self._drops = (0, None)           # frames the detector dropped in this rest, the last why
        self._last_drop = None            # the detector's last reason for a dropped frame

    @property
    def fraction(self):
        """Share of the session done (0..1); a session stopped early stays at its pose."""
        if self.state == DONE and self.failure is None:
            return 1.0
        return min(max(self.index, 0), len(self.poses)) / len(self.poses)

    def _wall(self):
        return None if self.clock is None else self.clock()

    def _elapsed(self, t, since, wall_since):
        """Return the seconds since (``since``, ``wall_since``) on both clocks (session_limits)."""
        wall = self._wall()
        return session_limits.silence(t - since, None if wall is None else wall - wall_since)

    def _enter(self, state, t):
        self.state, self._t_state, self._wall_state = state, t, self._wall()

    def _next_pose(self, t):
        self.index += 1
        if self.index >= len(self.poses):
            self._enter(DONE, t)
            self.actions.append(('done', None))
            return
        self._window.clear()
        self._enter(MOVING, t)
        self.actions.append(('goal', self.poses[self.index]))
        self.actions.append(('progress', (MOVING, self.index, len(self.poses))))

    def start(self, t):
        """
        Start the session at time t (s): command the first pose.

        A time of 0 is a simulated clock that has not started (ROS time 0: no /clock message
        yet). The first pose is then commanded at the first tick with a time: commanded at 0, the
        readings of the robot still at home before it moved passed for the pose reached, and the
        first rest measured the move (one live session's pose 0: 0.57 rad of motion and 4 frames
        in its rest, which spoilt the readings' noise model of the whole bag).
        """
        if t <= 0:
            self._clock_wait = self._wall()
            return
        self._clock_wait = None
        self.last_input = dict.fromkeys(INPUTS, t)
        self._wall_input = dict.fromkeys(INPUTS, self._wall())
        self._next_pose(t)

    @property
    def started(self):
        """Whether the first pose was commanded (start waits for a clock that runs)."""
        return self._t_state is not None

    def _wait_for_clock(self, t):
        """Start once the clock runs; stop, saying why, if it stays at 0 longer than a pose."""
        if t > 0:
            self.start(t)
            return
        limit = session_limits.pose_time_limit(self.config)
        waited = None if self._clock_wait is None else self._wall() - self._clock_wait
        if waited is not None and waited > limit:
            self._stop(t, f'the clock stayed at 0 for {waited:.1f} s of wall time, longer than a '
                          f'pose can last ({limit:.1f} s): no /clock message (is the simulator '
                          'running, with sim_time on every node?)')

    def joint_state(self, t, Theta):
        """Take one /joint_states sample: the increments (rad) of the three joints."""
        if not self.started:
            return
        self._heard('joint_states', t)
        if self.state == MOVING:
            self._window.add(t, [float(v) for v in Theta])
            # Ignore stillness right after the goal: the robot has not started moving yet.
            if t - self._t_state > 0.1 and self._window.first <= t - 0.9 * self.config.still_time:
                if all(r <= self.config.still_range for r in self._window.ranges()):
                    self._enter(SETTLING, t)
                    self.actions.append(('progress', (SETTLING, self.index, len(self.poses))))
        elif self.state == MEASURING:
            self._rest.Theta.append(np.asarray(Theta, dtype=float))

    def detection(self, t, position, covariance, stamp=None):
        """
        Take one sphere detection, in the optical frame (m), with its covariance (3x3, m^2).

        ``stamp``: its image's time (s), if known. A frame exposed before the rest began is not
        the rest's, whenever its detection arrives: the calibration reads the rests from the bag by
        the images' stamps (robotenis_calibration.rests), and a detector a few frames behind would
        otherwise end a rest with fewer frames in it than asked.
        """
        if not self.started:
            return
        self._heard('sphere/detection', t)
        if (self.state == MEASURING and np.all(np.isfinite(position))
                and (stamp is None or stamp >= self._rest.start)):
            self._last_detection = (t, self._wall())
            self._rest.sphere.append(np.asarray(position, dtype=float))
            self._rest.sphere_cov.append(np.asarray(covariance, dtype=float).reshape(3, 3))

    def dropped(self, t, reason):
        """Take the reason the sphere detector gave for a frame it dropped, from sphere/dropped."""
        if not self.started:
            return
        self._last_drop = reason
        if self.state == MEASURING:
            self._drops = (self._drops[0] + 1, reason)

    def _unseen(self, guess):
        """Say why a rest lacks detections: the detector's own reason if it gave one, or guess."""
        count, reason = self._drops
        return guess if count == 0 else f'the detector dropped {count} frame(s): {reason}'

    def _heard(self, name, t):
        self.last_input[name], self._wall_input[name] = t, self._wall()

    def tick(self, t):
        """Advance on time alone: settle time over, time-outs, enough frames, silent inputs."""
        c = self.config
        if not self.started:
            if self.state != DONE:
                self._wait_for_clock(t)
            return
        if self.state != DONE and self._stop_if_silent(t):
            return
        if self.state == MOVING and t - self._t_state > c.move_timeout:
            self.skipped.append((self.index,
                                 f'did not come to rest within {c.move_timeout:.0f} s'))
            self._next_pose(t)
        elif self.state == SETTLING and t - self._t_state >= c.settle_time:
            self._rest, self._drops = Rest(self.index, t, t), (0, None)
            self._enter(MEASURING, t)
            self.actions.append(('rest_start', self.index))
            self.actions.append(('progress', (MEASURING, self.index, len(self.poses))))
        elif self.state == MEASURING:
            if len(self._rest.sphere) >= c.frames_per_pose:
                self._finish_rest(t)
            elif (not self._rest.sphere
                  and self._elapsed(t, self._t_state, self._wall_state) > c.no_ball_time):
                self.skipped.append((self.index, f'no detection in {c.no_ball_time:.1f} s '
                                                 f'({self._unseen("ball not in view?")})'))
                self.actions.append(('rest_end', self.index))
                self._next_pose(t)
            elif (self._rest.sphere and self._elapsed(t, *self._last_detection)
                  > c.no_ball_time + 2 * self._frame_period()):
                self.skipped.append((self.index,
                                     f'detections stopped after {len(self._rest.sphere)} of '
                                     f'{c.frames_per_pose} '
                                     f'({self._unseen("ball at the edge of the view?")})'))
                self.actions.append(('rest_end', self.index))
                self._next_pose(t)
            elif t - self._t_state > self._measure_limit(t):
                self.skipped.append((self.index,
                                     f'only {len(self._rest.sphere)} of {c.frames_per_pose} '
                                     f'detections in {t - self._t_state:.0f} s '
                                     f'({self._unseen("ball not in view?")})'))
                self.actions.append(('rest_end', self.index))
                self._next_pose(t)

    def _stop_if_silent(self, t):
        """Stop the session, saying why, if an input is silent for longer than a pose can last."""
        limit = session_limits.pose_time_limit(self.config)
        silences = {name: self._elapsed(t, self.last_input[name], self._wall_input[name])
                    for name in INPUTS}
        silent = session_limits.silent_inputs(silences, limit)
        if not silent:
            return False
        self._stop(t, '; '.join(
            f'no message on {name} for {silences[name]:.1f} s ({t - self.last_input[name]:.1f} s '
            f'of robot time), longer than a pose can last ({limit:.1f} s): {self._source(name)}'
            for name in silent))
        return True

    def _source(self, name):
        """Say what feeds an input, and for the detections its last reason to drop a frame."""
        if name == 'sphere/detection' and self._last_drop is not None:
            return f'the sphere detector, which drops the frames (last: {self._last_drop})'
        return INPUTS[name]

    def _stop(self, t, failure):
        """Stop the session early, saying why: a rest being measured is closed first."""
        self.failure = failure
        if self.state == MEASURING:
            self.actions.append(('rest_end', self.index))
        self._enter(DONE, t)
        self.actions.append(('done', None))

    def _frame_period(self):
        """Return the seconds between detections: over the rests measured, or this one's."""
        frames, seconds = self._measured
        if not frames:
            frames, seconds = len(self._rest.sphere), self._last_detection[0] - self._t_state
        return seconds / frames

    def _measure_limit(self, t):
        """
        Return how long (s) a rest may measure: its frames' own time, plus measure_timeout.

        The frames' time is at the detections' rate over the rests measured so far (the camera's
        and the detector's, whatever they are), or before any, over this rest's own.
        """
        frames, seconds = self._measured
        if not frames:
            frames, seconds = len(self._rest.sphere), t - self._t_state
        if not frames or seconds <= 0:
            return self.config.measure_timeout
        return self.config.measure_timeout + self.config.frames_per_pose * seconds / frames

    def _finish_rest(self, t):
        self._rest.end = t
        self._measured[0] += len(self._rest.sphere)
        self._measured[1] += t - self._rest.start
        self.rests.append(self._rest)
        self.actions.append(('rest_end', self.index))
        remaining = len(self.poses) - self.index - 1
        if self.replan is not None and len(self.rests) in self.replan_after and remaining > 0:
            poses = self.replan(self.rests, remaining)
            if poses is not None:
                self.poses = np.concatenate([self.poses[:self.index + 1],
                                             np.asarray(poses, dtype=float)])
        self._next_pose(t)

    def take_actions(self):
        """Return the actions since the last call, in order."""
        out, self.actions = self.actions, []
        return out
