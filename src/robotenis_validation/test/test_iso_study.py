"""Static tests of section 6.1: distance accuracy and repeatability studies against their noise."""
import numpy as np
import pytest

from robotenis_kinematics import delta, description, synthetic
from robotenis_sim import motors, truth as sim_truth
from robotenis_validation import iso_study as iso


@pytest.fixture(scope='module')
def truth():
    return sim_truth.load()


@pytest.fixture(scope='module')
def plate(truth):
    return iso.Plate.in_front_of(iso.CUBE_CENTRE,
                                 truth.camera_translation
                                 + iso.STANDOFF * truth.camera_rotation[:, 2])


def guess(truth):
    """Return the user's belief of the camera offset: 5 mm off on each axis."""
    return truth.camera_translation + iso.STANDOFF * truth.camera_rotation[:, 2] + 0.005


def test_plate_geometry(plate):
    assert plate.centres.shape == (5, 5, 5, 3)
    assert len(iso.neighbour_pairs()) == 40
    np.testing.assert_allclose(np.diff(plate.centres[:, 0, 0, 0]), iso.PLANE_SPACING)
    np.testing.assert_allclose(np.diff(plate.centres[0, 0, :, 1]), iso.PITCH)


def test_perfect_model_leaves_only_the_camera_noise(truth, plate):
    """
    With the true geometry the readings cancel exactly.

    Each pair's AD is then |mean of n| of the difference of two camera errors along the pair:
    |N(0, 2 sigma^2 / n)|, sigma the optical x noise (horizontal pairs, base y) or y noise
    (vertical pairs, base z). The mean of the per-circle maps weighs pair p by
    (1/pairs(a) + 1/pairs(b)) / circles: its expectation and spread follow exactly.
    """
    n = 3
    AD = iso.distance_accuracy(truth, truth.geometry, plate, guess(truth), n,
                               np.random.default_rng(4))
    sx, sy = synthetic.NoiseModel().sigma_camera[:2]
    pairs = iso.neighbour_pairs()
    count = np.zeros((iso.GRID, iso.GRID))
    for a, b in pairs:
        count[a] += 1
        count[b] += 1
    w = np.array([(1 / count[a] + 1 / count[b]) / iso.GRID ** 2 for a, b in pairs])
    sigma = np.array([np.sqrt(2 / n) * (sx if a[0] == b[0] else sy) for a, b in pairs])
    planes = plate.centres.shape[0]
    expected = np.sum(w * sigma) * np.sqrt(2 / np.pi)
    spread = np.sqrt(np.sum(w ** 2 * sigma ** 2) * (1 - 2 / np.pi) / planes)
    assert abs(AD.mean() - expected) < 5 * spread, (AD.mean(), expected, spread)


def test_nominal_model_is_far_worse_than_the_noise(truth, plate):
    AD_nominal = iso.distance_accuracy(truth, description.nominal(), plate, guess(truth), 1,
                                       np.random.default_rng(5))
    sx, sy = synthetic.NoiseModel().sigma_camera[:2]
    assert AD_nominal.mean() > 20 * np.sqrt(2) * max(sx, sy)


def test_repeatability_is_camera_noise_plus_the_resolver_resolution(truth):
    rng = np.random.default_rng(6)
    samples = iso.repeatability(truth, motors.true_masses(truth), description.nominal(), 2.0, 4,
                                rng)
    assert samples.shape == (4, 3)
    q = motors.ResolverParameters().resolution
    J = np.linalg.norm(delta.jacobian(truth.geometry, iso.CUBE_CENTRE), 2)
    bound = J * 4 * q + 4 * np.linalg.norm(synthetic.NoiseModel().sigma_camera)
    assert np.all(np.linalg.norm(samples - samples.mean(axis=0), axis=1) < bound)
    ranges, RP = iso.repeatability_figures(samples)
    assert RP > 0 and np.all(ranges >= 0)


def test_servo_refuses_a_circle_it_cannot_centre(truth, plate):
    robot = iso.StaticRobot(truth, truth.geometry, np.random.default_rng(0))
    far = plate.centres[0, 0, 0] + np.array([0.0, 0.0, 5.0])
    with pytest.raises((RuntimeError, ValueError)):
        iso.servo(robot, far, far - guess(truth))
