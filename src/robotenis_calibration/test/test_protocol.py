"""The frames per rest that buy the most information per second of robot time."""
import numpy as np
import pytest
from robotenis_calibration import protocol
from robotenis_kinematics import variance


def information_rate(sigma, floor, overhead, rate, N):
    return 1.0 / (protocol.rest_variance(sigma, floor, N) * (overhead + N / rate))


@pytest.mark.parametrize('sigma, floor, overhead, rate', [
    (1e-4, 4e-6, 0.8, 120.0), (4.7e-4, 2.5e-5, 0.3, 25.0), (2e-4, 1e-5, 3.0, 60.0)])
def test_the_rule_maximises_the_information_per_second(sigma, floor, overhead, rate):
    N = protocol.frames_per_rest([sigma] * 3, [floor] * 3, overhead, rate)
    grid = np.arange(1, 5000)
    best = grid[np.argmax(information_rate(sigma, floor, overhead, rate, grid))]
    # N* is the real optimum rounded up: within one frame of the integer one
    assert abs(N - best) <= 1


def test_the_axis_that_needs_most_frames_decides_and_no_floor_means_the_most():
    N = protocol.frames_per_rest([1e-4, 1e-4, 5e-4], [1e-5, 1e-6, 1e-5], 1.0, 100.0)
    assert N in (1000, 1001)   # y: (sigma / f) sqrt(T0 rate) = 100 * 10, rounded up
    assert protocol.frames_per_rest([1e-4] * 3, [0.0] * 3, 1.0, 100.0, most=777) == 777


def test_bad_timing_is_refused():
    with pytest.raises(ValueError, match='overhead and rate'):
        protocol.frames_per_rest([1e-4] * 3, [1e-5] * 3, 0.0, 100.0)


def test_the_next_session_takes_the_rests_floor_at_the_noise_models_range():
    """next_session: the floor's constant and range-grown parts add at the reference range."""
    noise = {'camera': {'variance_at_reference': [1e-8, 1e-8, 4e-8]}}
    floor = variance.Floor({'camera_x': 1e-10, 'camera_z': 2e-10, 'camera_z_range': 2e-10})
    timing = {'camera_rate_hz': 100.0, 'rest_overhead_s': 0.5}
    plan = protocol.next_session(noise, floor, timing)
    # z decides: (2e-4 / 2e-5) sqrt(0.5 * 100) = 70.7
    assert plan['frames_per_rest'] == 71
    assert plan['floor_m'] == pytest.approx([1e-5, 0.0, 2e-5])
    assert '71 frames per rest' in protocol.next_session_text(plan)
    assert protocol.next_session(noise, variance.Floor(), timing) is None
    assert protocol.next_session(noise, floor, None) is None
