"""Averaging one rest: the outlier gate rejects good samples at its level, and rejects outliers."""
import numpy as np
import pytest
from robotenis_calibration import rests
from robotenis_sim import session_bag
from scipy import stats


def test_the_gate_rejects_good_samples_with_its_probability_whatever_their_number():
    rng = np.random.default_rng(4)
    alpha, rests_per_size = 1e-3, 2000
    for n in (12, 25, 60):
        cov = np.array([[4.0, 1.0, 0.0], [1.0, 2.0, 0.5], [0.0, 0.5, 1.0]])
        rejected = sum(int((~rests.robust_mean(rng.multivariate_normal(np.zeros(3), cov, n),
                                               np.full(3, 1e-12), alpha)[2]).sum())
                       for _ in range(rests_per_size))
        total = n * rests_per_size
        low, high = stats.binom.ppf([0.0005, 0.9995], total, alpha)
        assert low <= rejected <= high, (n, rejected, total * alpha)


def test_false_detections_are_rejected_and_the_mean_is_the_good_samples():
    rng = np.random.default_rng(5)
    x = rng.normal(size=(40, 3))
    x[[3, 17, 30]] += [8.0, -6.0, 5.0]
    mean, cov, keep = rests.robust_mean(x, np.full(3, 1e-12), 1e-3)
    assert not keep[[3, 17, 30]].any() and keep.sum() >= 36
    np.testing.assert_allclose(mean, x[keep].mean(axis=0))


# Drivers' timings: joint states, camera, rests, moves, jitter, drops (some more in the benchmark)
TIMINGS = {
    '100Hz-60Hz-1s': {'joint_rate': 100.0, 'camera_rate': 60.0, 'rest_time': 1.0,
                      'move_time': (0.5, 0.0)},
    '50Hz-15Hz-0.3s': {'joint_rate': 50.0, 'camera_rate': 15.0, 'rest_time': 0.3,
                       'move_time': (0.3, 0.5)},
    '1kHz-120Hz-2s-jitter': {'joint_rate': 1000.0, 'camera_rate': 120.0, 'rest_time': 2.0,
                             'move_time': (0.4, 1.0), 'stamp_jitter': 0.0005},
    '200Hz-30Hz-0.5s-drops': {'joint_rate': 200.0, 'camera_rate': 30.0, 'rest_time': 0.5,
                              'move_time': (1.0, 0.0), 'drop_fraction': 0.05,
                              'stamp_jitter': 0.003},
}


@pytest.mark.parametrize('timing', list(TIMINGS))
def test_rests_of_any_drivers_timing_are_found_and_average_to_the_truth(tmp_path, timing):
    """
    Check a bag another driver recorded (rosbags, no markers): the rests are used, and right.

    At least 98 % of the rests are found and averaged; each average is the camera's mean
    measurement within the noise the learned noise model gives it (chi-square of all rests, 1 %),
    and likewise the readings.
    """
    bag = session_bag.write(tmp_path / 'bag', session_bag.BagSpec(
        poses=50, seed=7, markers=False, **TIMINGS[timing]))
    session, notes = rests.load_session(bag.path)
    assert len(session) >= 0.98 * len(bag.Theta), notes
    found = np.array([np.argmin(np.linalg.norm(bag.Theta - th, axis=1)) for th in session.Theta])
    assert len(set(found)) == len(found)
    d = session.sphere - bag.sphere[found]
    chi2 = np.einsum('ki,kij,kj->', d, np.linalg.inv(session.sphere_cov), d)
    assert chi2 < stats.chi2.ppf(0.99, d.size), notes
    readings = np.sum(((session.Theta - bag.Theta[found]) / session.sigma_Theta) ** 2)
    assert readings < stats.chi2.ppf(0.99, d.size)


def play(x, gap):
    """Return the contact side of a play of width ``gap`` driven by x (n,), from side +1."""
    y, side = x[0] - gap / 2, 1.0
    for v in x:
        if v - y > gap / 2:
            y, side = v - gap / 2, 1.0
        elif v - y < -gap / 2:
            y, side = v + gap / 2, -1.0
    return side


def test_the_sides_are_a_play_of_each_gap_driven_by_the_readings():
    """approach_directions is the last contact of a backlash (a play) of each width in GAPS."""
    rng = np.random.default_rng(8)
    for _ in range(200):
        # moves of any length, overshoots and returns, and the resolvers' count
        steps = rng.normal(scale=rng.choice([2e-4, 1e-3, 5e-3]), size=(rng.integers(5, 60), 3))
        Theta = np.round(np.cumsum(np.repeat(steps, 4, axis=0) / 4, axis=0) / 3.83e-5) * 3.83e-5
        t = np.arange(len(Theta)) * 1e-3
        sides = rests.approach_directions(t, Theta, t[-1] + 1e-3, np.ones((len(rests.GAPS), 3)))
        expected = [[play(Theta[:, j], g) for j in range(3)] for g in rests.GAPS]
        np.testing.assert_array_equal(sides, expected)


def test_a_reversal_across_the_gap_counts_even_where_it_straddles_the_rest():
    """Up to 0.4 mrad past the rest, down to 0.4 mrad short of it, back: the 0.6 gap is crossed."""
    rise = np.linspace(-5e-3, 4e-4, 50)
    Theta = np.column_stack([np.concatenate([rise, np.linspace(4e-4, -4e-4, 9), [-2e-4, 0.0]]),
                             np.concatenate([rise, np.linspace(4e-4, 0.0, 11)]),
                             np.full(61, 1e-3)])
    t = np.arange(61) * 1e-3
    previous = np.full((len(rests.GAPS), 3), -1.0)
    sides = rests.approach_directions(t, Theta, 1.0, previous)
    at = rests.nearest_gap(rests.GAPS, 6e-4)[0]
    # joint 1 crossed it back (the reading farthest from the rest was the approach's, +1);
    # joint 2 came back 0.4 mrad only: the approach's side; joint 3 did not move: as before
    assert list(sides[at]) == [-1.0, 1.0, -1.0]


def test_sides_of_fast_motion_keep_through_a_slow_creep_back():
    """
    fast_motion_sides: the sign of the last step faster than each speed; a slow creep keeps it.

    Joint 1 rises at 0.9 rad/s, crosses a 0.6 mrad gap back within one 1 ms reading (0.6 rad/s),
    then creeps up 0.8 mrad at 0.01 rad/s; joint 2 falls at 0.9 rad/s; joint 3 stands.
    """
    rise, creep = np.linspace(0.0, 45e-3, 51), 44.4e-3 + np.linspace(1e-5, 8e-4, 80)
    one = np.concatenate([rise, creep])
    Theta = np.column_stack([one, -np.minimum(np.arange(131) * 9e-4, 45e-3), np.zeros(131)])
    t = np.arange(131) * 1e-3
    previous = np.full((len(rests.SPEEDS), 3), -1.0)
    previous[:, 1] = 1.0                # joint 2 must be seen falling
    sides = rests.fast_motion_sides(t, Theta, 1.0, previous)
    v = rests.SPEEDS
    expected = np.where(v < 0.6, -1.0, np.where(v < 0.9, 1.0, -1.0))   # the jump, the rise
    np.testing.assert_array_equal(sides[:, 0], expected)
    np.testing.assert_array_equal(sides[:, 1], np.where(v < 0.9, -1.0, 1.0))
    np.testing.assert_array_equal(sides[:, 2], previous[:, 2])
    # a play (the travel family) at a 0.7 mrad gap takes the creep, 0.8 mrad, for a reversal
    gap = rests.nearest_gap(rests.GAPS, 7e-4)[0]
    travel = rests.approach_directions(t, Theta, 1.0, np.ones((len(rests.GAPS), 3)))
    assert travel[gap, 0] == 1.0


def test_the_pace_of_a_recording_is_its_camera_rate_and_the_time_between_rests(tmp_path):
    """rest_timing: 120 Hz, and 1 s besides the frames: a 0.4 s move, 0.5 s settle, 0.1 s tail."""
    spec = session_bag.BagSpec(poses=12, seed=2, move_time=(0.4, 0.0), settle=0.5)
    session, _ = rests.load_session(session_bag.write(tmp_path / 'bag', spec).path)
    period = 1.0 / spec.camera_rate
    assert session.timing['camera_rate_hz'] == pytest.approx(spec.camera_rate, rel=1e-6)
    # the end marker half a period after the last frame, the first frame on the next period
    # boundary after the settle: the overhead is 1 s less half a period, plus up to one period
    overhead = session_bag.TAIL + 0.4 + spec.settle - 0.5 * period
    assert overhead - 1e-6 <= session.timing['rest_overhead_s'] <= overhead + period + 1e-6


def test_a_rest_that_moved_does_not_spoil_the_noise_model():
    """
    A rest whose spread no noise gives is left out of frame_noise.

    60 rests of 12 samples of known noise, and one of 2 samples 0.5 rad apart (the robot moving
    during it): the model is the clean rests' own, within its chi-square band.
    """
    rng = np.random.default_rng(11)
    sigma = 2e-5
    clean = [rng.normal(scale=sigma, size=(12, 3)) for _ in range(60)]
    moved = np.array([[0.0, 0.0, 0.0], [0.5, 0.4, 0.6]])
    z = np.full(61, rests.Z_REFERENCE)
    noise = rests.frame_noise(clean + [moved], z, np.zeros(3), grow=False)
    dof = 60 * 11
    band = stats.chi2.ppf([0.0005, 0.9995], dof) / dof * sigma ** 2
    assert np.all((band[0] < noise.c) & (noise.c < band[1]))
    assert np.array_equal(noise.c, rests.frame_noise(clean, z[:60], np.zeros(3), grow=False).c)
