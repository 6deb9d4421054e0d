import math

import numpy as np

from robotenis_calibration import session_limits
from robotenis_calibration.session_runner import (DONE, MEASURING, RunnerConfig, SessionRunner,
                                                  SlidingRange)


def drive(runner, visible, dt=0.001, t_end=30.0, seed=0, joints_until=math.inf,
          detector_until=math.inf, frame_ms=8, on_step=None):
    """
    Drive ``runner`` with a fake robot that moves to each goal in 0.3 s.

    Its readings are quantised with the simulator's count and noise; the camera sees the ball at
    120 Hz (a frame every ``frame_ms``) when visible. The joint states stop at ``joints_until``,
    the detections at ``detector_until`` (s). ``on_step(t)`` is told each step's time.
    """
    rng = np.random.default_rng(seed)
    q = 2 * np.pi / 163840
    t, goal_time, actions = 0.0, 0.0, []
    Theta = start = target = np.zeros(3)
    runner.start(t)
    while runner.state != DONE and t < t_end:
        if on_step is not None:
            on_step(t)
        for a in runner.take_actions():
            actions.append((t, a))
            if a[0] == 'goal':
                goal_time, start, target = t, Theta, np.full(3, (runner.index + 1) * 0.1)
        Theta = start + (target - start) * min(1.0, (t - goal_time) / 0.3)
        if t < joints_until:
            runner.joint_state(t, np.round((Theta + rng.normal(scale=2e-5, size=3)) / q) * q)
        if visible(runner.index) and round(t * 1000) % frame_ms == 0 and t < detector_until:
            runner.detection(t, np.array([0.0, 0.0, 0.3]) + 1e-5 * runner.index, np.eye(3) * 1e-10)
        runner.tick(t)
        t += dt
    actions += [(t, a) for a in runner.take_actions()]
    return actions


def test_each_pose_is_commanded_settled_and_measured_in_order():
    poses = np.array([[0.1, 0, 1.0], [0.2, 0, 1.0], [0.3, 0, 1.0]])
    runner = SessionRunner(poses, RunnerConfig(frames_per_pose=20, settle_time=0.5))
    actions = drive(runner, lambda k: True)
    kinds = [a[0] for _, a in actions if a[0] != 'progress']
    assert kinds == ['goal', 'rest_start', 'rest_end'] * 3 + ['done']
    assert [r.index for r in runner.rests] == [0, 1, 2]
    for rest in runner.rests:
        assert len(rest.sphere) == 20 and len(rest.Theta) > 0
    # Every measurement starts after the move (0.3 s) and the settle time (0.5 s).
    starts = [t for t, a in actions if a[0] == 'rest_start']
    goals = [t for t, a in actions if a[0] == 'goal']
    assert all(s - g >= 0.3 + 0.5 for s, g in zip(starts, goals))


def test_a_pose_without_the_ball_is_skipped_with_a_reason():
    poses = np.array([[0.1, 0, 1.0], [0.2, 0, 1.0], [0.3, 0, 1.0]])
    runner = SessionRunner(poses, RunnerConfig(frames_per_pose=10, settle_time=0.1,
                                               measure_timeout=1.0))
    drive(runner, lambda k: k != 1)
    assert [r.index for r in runner.rests] == [0, 2]
    assert runner.skipped[0][0] == 1 and 'ball not in view' in runner.skipped[0][1]
    assert runner.fraction == 1.0


MISFIT = 'model the ball model misfits the image (residual 9.0 times the noise)'


def test_a_pose_whose_frames_the_detector_drops_is_skipped_with_its_reason():
    """The detector runs but refuses pose 1's frames: the skip says so, not 'not in view'."""
    poses = np.array([[0.1, 0, 1.0], [0.2, 0, 1.0], [0.3, 0, 1.0]])
    runner = SessionRunner(poses, RunnerConfig(frames_per_pose=10, settle_time=0.1,
                                               measure_timeout=1.0))

    def refuse(t):
        if runner.index == 1 and round(t * 1000) % 8 == 0:
            runner.dropped(t, MISFIT)

    drive(runner, lambda k: k != 1, on_step=refuse)
    assert [r.index for r in runner.rests] == [0, 2]
    index, why = runner.skipped[0]
    # dropped at 125 Hz over the rest's no_ball_time (0.5 s): 62 or 63 frames
    assert index == 1 and 'not in view' not in why and MISFIT in why
    assert int(why.split('dropped ')[1].split(' ')[0]) in (62, 63)


def test_a_detector_dropping_every_frame_stops_the_session_with_its_reason():
    config = RunnerConfig(frames_per_pose=10, settle_time=0.1, move_timeout=2.0,
                          measure_timeout=2.0)
    runner = SessionRunner(np.array([[0.1 * k, 0, 1.0] for k in range(1, 40)]), config)
    drive(runner, lambda k: True, detector_until=2.5,
          on_step=lambda t: t >= 2.5 and runner.dropped(t, MISFIT))
    assert 'no message on sphere/detection' in runner.failure and MISFIT in runner.failure


def test_a_slow_camera_gets_the_time_its_frames_need():
    """
    50 frames at 5 Hz take 10 s: longer than measure_timeout, which is time beyond the frames'.

    A rest whose detections then stop is skipped once they have been silent for no_ball_time and
    two of their periods (0.2 s), not after the whole measure_timeout.
    """
    poses = np.array([[0.1, 0, 1.0], [0.2, 0, 1.0], [0.3, 0, 1.0]])
    config = RunnerConfig(frames_per_pose=50, settle_time=0.1, measure_timeout=2.0)
    runner = SessionRunner(poses, config)
    actions = drive(runner, lambda k: True, t_end=60.0, frame_ms=200, detector_until=23.0)
    assert [r.index for r in runner.rests] == [0, 1]
    assert all(len(r.sphere) == 50 for r in runner.rests)
    assert runner.skipped[0][0] == 2 and 'detections stopped' in runner.skipped[0][1]
    end = next(t for t, a in actions if a == ('rest_end', 2))
    last = max(t for t in np.arange(0.0, 23.0, 0.001) if round(t * 1000) % 200 == 0)
    period = np.mean([r.end - r.start for r in runner.rests]) / 50
    assert abs(end - last - (config.no_ball_time + 2 * period)) < 0.01


def test_a_rest_whose_detections_stop_is_skipped_at_once():
    """A ball at the edge of the view seen in its rest's first frames only: skipped, not waited."""
    poses = np.array([[0.1, 0, 1.0], [0.2, 0, 1.0]])
    config = RunnerConfig(frames_per_pose=30, settle_time=0.1, measure_timeout=10.0)
    runner = SessionRunner(poses, config)
    actions = drive(runner, lambda k: k == 1 or (runner.state == MEASURING
                                                 and len(runner._rest.sphere) < 3))
    assert [r.index for r in runner.rests] == [1]
    assert runner.skipped[0][0] == 0 and 'detections stopped after 3 of 30' in runner.skipped[0][1]
    start = next(t for t, a in actions if a == ('rest_start', 0))
    end = next(t for t, a in actions if a == ('rest_end', 0))
    assert end - start < 1.0 < config.measure_timeout


def test_a_rest_counts_the_frames_exposed_in_it_whenever_they_arrive():
    """Detections of frames from before the rest (a detector behind) are not the rest's."""
    runner = SessionRunner(np.zeros((1, 3)), RunnerConfig(frames_per_pose=3, settle_time=0.1))
    runner.start(0.0)
    t = 0.0
    while runner.state != MEASURING:
        t += 0.001
        runner.joint_state(t, np.zeros(3))
        runner.tick(t)
    start = t
    for k, stamp in enumerate([start - 0.02, start - 0.01, start, start + 0.008]):
        runner.detection(start + 0.05 + 0.001 * k, np.ones(3), np.eye(3), stamp)
    assert len(runner._rest.sphere) == 2
    runner.detection(start + 0.06, np.ones(3), np.eye(3))      # no stamp: counted on arrival
    assert len(runner._rest.sphere) == 3


def test_no_measurement_while_moving():
    runner = SessionRunner(np.zeros((1, 3)), RunnerConfig(frames_per_pose=5, settle_time=0.2))
    runner.start(0.0)
    runner.take_actions()
    runner.detection(0.01, np.ones(3), np.eye(3))
    assert runner.state != MEASURING and runner._rest is None


def test_a_ball_out_of_view_costs_only_the_no_ball_time():
    poses = np.array([[0.1, 0, 1.0], [0.2, 0, 1.0]])
    config = RunnerConfig(frames_per_pose=10, settle_time=0.1, no_ball_time=0.5,
                          measure_timeout=10.0)
    runner = SessionRunner(poses, config)
    actions = drive(runner, lambda k: k != 0)
    starts = {a[1]: t for t, a in actions if a[0] == 'rest_start'}
    ends = {a[1]: t for t, a in actions if a[0] == 'rest_end'}
    assert abs(ends[0] - starts[0] - config.no_ball_time) < 0.01
    assert [r.index for r in runner.rests] == [1]


def test_the_poses_after_the_first_rests_are_planned_again():
    """
    ``replan`` is asked when the measured rests reach each of replan_after, for the poses to come.

    The goals commanded from then on are its poses, and the session keeps its length.
    """
    poses = np.array([[0.1 * k, 0, 1.0] for k in range(1, 6)])
    asked = []

    def replan(rests, n):
        asked.append(([r.index for r in rests], n))
        return np.full((n, 3), 7.0 + len(rests))

    runner = SessionRunner(poses, RunnerConfig(frames_per_pose=5, settle_time=0.1), replan,
                           replan_after=(1, 3))
    actions = drive(runner, lambda k: k != 1)
    assert asked == [([0], 4), ([0, 2, 3], 1)]
    goals = [a[1] for _, a in actions if a[0] == 'goal']
    np.testing.assert_array_equal(goals[:1], poses[:1])
    np.testing.assert_array_equal(goals[1:4], np.full((3, 3), 8.0))
    np.testing.assert_array_equal(goals[4:], np.full((1, 3), 10.0))
    assert [r.index for r in runner.rests] == [0, 2, 3, 4]


def test_a_replan_that_keeps_the_plan():
    poses = np.array([[0.1 * k, 0, 1.0] for k in range(1, 4)])
    runner = SessionRunner(poses, RunnerConfig(frames_per_pose=5, settle_time=0.1),
                           lambda rests, n: None, (1,))
    actions = drive(runner, lambda k: True)
    np.testing.assert_array_equal([a[1] for _, a in actions if a[0] == 'goal'], poses)


def test_balls_out_of_view_at_a_few_poses_in_a_row_do_not_stop_the_session():
    poses = np.array([[0.1 * k, 0, 1.0] for k in range(1, 7)])
    runner = SessionRunner(poses, RunnerConfig(frames_per_pose=10, settle_time=0.1))
    drive(runner, lambda k: k not in (1, 2, 3, 4))
    assert runner.failure is None and [r.index for r in runner.rests] == [0, 5]


def stopped(silent_input, **silence):
    """
    Run a session whose ``silent_input`` stops at 2.5 s (``silence``: drive's keyword).

    Return the runner, the stop time and the time limit; the limit is a pose's time-outs end to end
    (4.2 s here).
    """
    config = RunnerConfig(frames_per_pose=10, settle_time=0.1, move_timeout=2.0,
                          measure_timeout=2.0)
    runner = SessionRunner(np.array([[0.1 * k, 0, 1.0] for k in range(1, 40)]), config)
    actions = drive(runner, lambda k: True, **silence)
    assert runner.state == DONE and runner.failure is not None
    assert silent_input in runner.failure and 'longer than a pose can last' in runner.failure
    return runner, actions[-1][0], session_limits.pose_time_limit(config)


def test_a_detector_that_stops_stops_the_session_naming_it():
    """
    The session stops one pose time-limit after the last detection.

    Within 2 ms: the 1 ms tick that notices it, and drive records actions one tick later.
    """
    runner, t_stop, limit = stopped('sphere/detection', detector_until=2.5)
    last = runner.last_input['sphere/detection']
    assert limit < t_stop - last <= limit + 0.002 and last < 2.5
    assert 'sphere detector' in runner.failure and 'joint_states' not in runner.failure
    assert len(runner.rests) >= 1 and runner.fraction < 1.0


class FastSimulation:
    """A wall clock for a simulation that runs ``speed`` times faster than real time."""

    def __init__(self, speed):
        self.speed, self.t = speed, 0.0

    def step(self, t):
        self.t = t

    def __call__(self):
        return self.t / self.speed


def test_a_simulator_ahead_of_the_wall_waits_for_a_live_detector_on_the_wall_clock():
    """
    At 30x real time a detector answering a frame per 40 ms of wall time answers every 1.2 s.

    On the robot's clock alone each rest's first detection comes later than no_ball_time (0.5 s)
    and its pose is skipped; on both clocks each rest is measured.
    """
    poses = np.array([[0.1, 0, 1.0], [0.2, 0, 1.0], [0.3, 0, 1.0]])
    config = RunnerConfig(frames_per_pose=3, settle_time=0.1, move_timeout=2.0,
                          measure_timeout=2.0)
    robot_clock_only = SessionRunner(poses, config)
    drive(robot_clock_only, lambda k: True, frame_ms=1200)
    assert robot_clock_only.skipped and 'no detection in 0.5 s' in robot_clock_only.skipped[0][1]
    wall = FastSimulation(30.0)
    runner = SessionRunner(poses, config, clock=wall)
    drive(runner, lambda k: True, frame_ms=1200, on_step=wall.step)
    assert runner.failure is None and not runner.skipped
    assert [len(r.sphere) for r in runner.rests] == [3, 3, 3]


def test_a_dead_detector_in_a_fast_simulation_stops_the_session_on_the_wall_clock():
    """At 5x real time, detections stop at 2.5 s: the stop comes a pose limit of wall time on."""
    config = RunnerConfig(frames_per_pose=10, settle_time=0.1, move_timeout=2.0,
                          measure_timeout=2.0)
    wall = FastSimulation(5.0)
    runner = SessionRunner(np.array([[0.1 * k, 0, 1.0] for k in range(1, 40)]), config,
                           clock=wall)
    actions = drive(runner, lambda k: True, detector_until=2.5, on_step=wall.step)
    limit = session_limits.pose_time_limit(config)
    assert runner.state == DONE and 'sphere detector' in runner.failure
    last = runner.last_input['sphere/detection']
    assert limit < (actions[-1][0] - last) / wall.speed <= limit + 0.002


def test_joint_states_that_stop_stop_the_session_naming_them():
    runner, t_stop, limit = stopped('joint_states', joints_until=2.5)
    assert limit < t_stop - runner.last_input['joint_states'] <= limit + 0.002
    assert 'sphere/detection' not in runner.failure


def test_a_stop_while_measuring_closes_the_rest():
    runner = SessionRunner(np.zeros((1, 3)), RunnerConfig(frames_per_pose=5, settle_time=0.0))
    runner.start(1.0)
    runner.state = MEASURING
    runner.tick(1.0 + session_limits.pose_time_limit(runner.config) + 0.1)
    kinds = [a[0] for a in runner.take_actions()]
    assert kinds[-2:] == ['rest_end', 'done'] and runner.state == DONE


def test_the_sliding_range_is_the_window_s_max_minus_min():
    """Quantised readings (many ties), irregular times, a NaN: the range of the window's own."""
    rng = np.random.default_rng(3)
    window, span = SlidingRange(0.1), 0.1
    t, seen = 0.0, []
    for k in range(3000):
        t += rng.choice([0.001, 0.004, 0.02])
        values = np.round(rng.normal(scale=3.0, size=3)) * 0.5
        if k == 1500:
            values[1] = np.nan
        window.add(t, list(values))
        seen = [(s, v) for s, v in seen if s >= t - span] + [(t, values)]
        assert window.first == seen[0][0]
        want = np.ptp([v for _, v in seen], axis=0)
        got = np.array(window.ranges())
        assert np.array_equal(np.isnan(got), np.isnan(want))
        assert np.array_equal(got[~np.isnan(want)], want[~np.isnan(want)])


def test_a_session_waits_for_the_clock_to_run_before_its_first_pose():
    """Time 0 is a simulated clock without /clock yet: no goal, no reading taken until it runs."""
    runner = SessionRunner(np.array([[0.1, 0, 1.0]]), RunnerConfig(frames_per_pose=5))
    runner.start(0.0)
    runner.joint_state(0.0, np.zeros(3))          # the robot at home, stamped before the clock
    runner.tick(0.0)
    assert not runner.started and runner.take_actions() == []
    runner.tick(7.5)
    kind, goal = runner.take_actions()[0]
    assert runner.started and kind == 'goal' and np.array_equal(goal, runner.poses[0])
    # the reading taken at 0 is not in the window that judges the move over
    runner.joint_state(7.6, np.zeros(3))
    assert runner.state != MEASURING and runner._window.first == 7.6


def test_a_clock_that_never_runs_stops_the_session_saying_so():
    wall = [100.0]
    config = RunnerConfig(frames_per_pose=5)
    runner = SessionRunner(np.array([[0.1, 0, 1.0]]), config, clock=lambda: wall[0])
    runner.start(0.0)
    wall[0] += session_limits.pose_time_limit(config) + 0.5
    runner.tick(0.0)
    assert runner.state == DONE and 'no /clock message' in runner.failure
    assert runner.take_actions() == [('done', None)]
