"""
What a calibration session cannot do, decided before it starts and while it runs; free of ROS.

Before: a request whose poses cannot give the rests the identification needs is refused at once.
Each planned pose gives at most one rest (none when the ball is out of view there), so the
planned poses are an upper bound on the rests, and fewer than ``pipeline.MIN_POSES`` of them can
never be enough; a rest needs ``rests.RestParameters.min_samples`` frames.

While it runs: an input silent for longer than a pose can explain stops the session. The longest
a pose can last is the session runner's own time-outs end to end (``pose_time_limit``): the move
(``move_timeout``), the stillness and settle times, the measurement (``measure_timeout``); a pose
whose ball is out of view is shorter (it is skipped after ``no_ball_time``). Joint states flow at
every moment of a pose, so a pose never explains their silence; detections stop while the ball is
out of view, so a silence that long means the detector stopped, or the ball was out of view at
every pose of that time. The silence is counted on the robot's clock and on the wall clock, the
shorter of the two (``silence``). With the demo's settings (0.3 s settle) the limit is 20.4 s,
against about 2 s for a measured pose.
"""
from robotenis_calibration.pipeline import MIN_POSES
from robotenis_calibration.rests import RestParameters


def refusal(planned, frames_per_pose):
    """Return why a session of ``planned`` poses and frames per pose cannot succeed, or None."""
    if frames_per_pose < RestParameters.min_samples:
        return (f'{frames_per_pose} frames per pose: a rest needs at least '
                f'{RestParameters.min_samples}')
    if planned < MIN_POSES:
        return (f'{planned} poses give at most {planned} rests (one per pose, none where the ball '
                f'is out of view): the identification needs at least {MIN_POSES}')
    return None


def pose_time_limit(config):
    """Return the longest a pose can last (s) under a RunnerConfig: its time-outs end to end."""
    return config.move_timeout + config.still_time + config.settle_time + config.measure_timeout


def silence(robot, wall=None):
    """
    Return how long (s) an input has been silent, given ``robot`` and ``wall`` clocks' seconds.

    A dead input is silent on both. A simulator that runs faster than real time makes frames
    faster, on its clock, than a detector on the wall clock answers them: a live detector then
    looks silent on the robot's clock alone. On a real robot the two clocks agree.
    """
    return robot if wall is None else min(robot, wall)


def silent_inputs(silences, limit):
    """Return the names in ``silences`` ({name: s}) silent for longer than ``limit`` s."""
    return [name for name, s in silences.items() if s > limit]
