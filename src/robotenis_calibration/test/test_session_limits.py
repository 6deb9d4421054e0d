"""A request that cannot give enough rests is refused; a silent input is named."""
from robotenis_calibration import session_limits
from robotenis_calibration.pipeline import MIN_POSES
from robotenis_calibration.rests import RestParameters
from robotenis_calibration.session_runner import RunnerConfig


def test_too_few_poses_for_the_identification_are_refused_with_the_numbers():
    reason = session_limits.refusal(12, 10)
    assert reason is not None and '12 poses' in reason and f'at least {MIN_POSES}' in reason
    assert session_limits.refusal(MIN_POSES, 10) is None


def test_too_few_frames_for_a_rest_are_refused():
    reason = session_limits.refusal(300, RestParameters.min_samples - 1)
    assert reason is not None and 'frames per pose' in reason
    assert session_limits.refusal(300, RestParameters.min_samples) is None


def test_a_pose_lasts_at_most_its_time_outs_end_to_end():
    config = RunnerConfig(settle_time=0.3)
    assert session_limits.pose_time_limit(config) == 10.0 + 0.1 + 0.3 + 10.0


def test_only_inputs_silent_for_longer_than_the_limit_are_named():
    silences = {'joint_states': 0.5, 'sphere/detection': 6.0}
    assert session_limits.silent_inputs(silences, 5.0) == ['sphere/detection']
    assert session_limits.silent_inputs(silences, 6.0) == []


def test_the_silence_is_the_shorter_of_the_robot_s_and_the_wall_s():
    assert session_limits.silence(8.5) == 8.5
    assert session_limits.silence(8.5, 0.3) == 0.3      # a simulator running ahead of the wall
    assert session_limits.silence(2.0, 8.0) == 2.0      # a simulator slower than real time
