import numpy as np
import pytest

from robotenis_kinematics import delta, description
from robotenis_kinematics.description import DescriptionError
from robotenis_sim import truth as sim_truth


@pytest.fixture
def truth():
    return sim_truth.load()


def test_default_truth_is_table1_without_effects(truth):
    np.testing.assert_allclose(truth.geometry.b * 1e3, [1002.86, 1001.37, 1001.28])
    assert truth.effects == {}
    np.testing.assert_array_equal(truth.camera_rotation, description.nominal().camera_rotation)


def test_reading_round_trip_with_gear_error(truth):
    t = sim_truth.with_effects(truth, joint_scale=[1e-3, -2e-3, 0.0])
    motor = truth.geometry.theta0 + np.array([0.2, -0.1, 0.3])
    np.testing.assert_allclose(t.reading(motor),
                               (1 + np.array([1e-3, -2e-3, 0])) * [0.2, -0.1, 0.3])
    np.testing.assert_allclose(t.motor_from_reading(t.reading(motor)), motor, atol=1e-15)


def test_backlash_lags_against_the_motion(truth):
    t = sim_truth.with_effects(truth, backlash=[2e-4, 0.0, 0.0])
    motor = np.array([0.3, 0.3, 0.3])
    np.testing.assert_allclose(t.arm_angles(motor, np.array([1, 1, 1])) - motor, [-1e-4, 0, 0])
    np.testing.assert_allclose(t.arm_angles(motor, np.array([-1, 1, 1])) - motor, [1e-4, 0, 0])


def test_gravity_sags_the_arms_down(truth):
    t = sim_truth.with_effects(truth, gravity_compliance=[1e-5, 1e-5, 1e-5])
    motor = delta.inverse(truth.geometry, [0.1, 0.0, 0.9])
    sag = t.arm_angles(motor, np.ones(3)) - motor
    P = delta.forward(truth.geometry, motor)
    # Positive torque pulls the arm down (theta grows); the sag equals c * tau to first order.
    np.testing.assert_allclose(sag, 1e-5 * t.gravity_torque(P, motor), rtol=1e-2)
    assert np.all(sag > 0)


def test_gravity_torque_matches_virtual_work(truth):
    """tau_i = dV/dtheta_i with V = -(m_arm g a sin theta + m_platform g z): finite differences."""
    geometry = truth.geometry
    theta = delta.inverse(geometry, [0.05, -0.1, 0.85])
    load = truth.gravity_load

    def minus_potential(th):
        P = delta.forward(geometry, th)
        return sim_truth.G * (load.arm * np.sum(geometry.a * np.sin(th)) + load.platform * P[2])

    eps = 1e-6
    numeric = [(minus_potential(theta + eps * e) - minus_potential(theta - eps * e)) / (2 * eps)
               for e in np.eye(3)]
    np.testing.assert_allclose(truth.gravity_torque(delta.forward(geometry, theta), theta),
                               numeric, rtol=1e-6)


def test_hand_eye_rotation_turns_the_camera(truth):
    t = sim_truth.with_effects(truth, hand_eye_rotation=[0.0, 0.0, 0.01])
    R = t.camera_rotation
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.isclose(np.arccos((np.trace(R @ truth.camera_rotation.T) - 1) / 2), 0.01)


def test_base_geometry_moves_the_motors(truth):
    t = sim_truth.with_effects(truth, base_geometry={'dH': [0.001, 0, 0], 'dphi': [0, 0.002, 0]})
    np.testing.assert_allclose(t.geometry.H - truth.geometry.H, [0.001, 0, 0])
    np.testing.assert_allclose(t.geometry.phi - truth.geometry.phi, [0, 0.002, 0])


@pytest.mark.parametrize('change, key', [
    ({'geometry': None}, 'geometry: missing key'),
    ({'effects': {'warp': [0, 0, 0]}}, 'effects.warp: unknown effect'),
    ({'effects': {'backlash': [0, 0]}}, 'effects.backlash: expected 3'),
    ({'sphere_position': 'here'}, 'sphere_position: expected 3')])
def test_bad_truth_files_name_the_key(truth, change, key):
    data = {'geometry': truth.geometry.to_dict(), 'camera_translation': [0.1, 0, 0],
            'sphere_position': [0.8, 0, 1]}
    data.update(change)
    data = {k: v for k, v in data.items() if v is not None}
    with pytest.raises(DescriptionError, match=key):
        sim_truth.from_dict(data)


def test_increments_invert_the_joint_effects(truth):
    """Map motor to arm angles, then back to readings: the truth's joint effects round-trip."""
    t = sim_truth.with_effects(truth, joint_scale=[1e-3, -2e-3, 0.0], backlash=[2e-4, 1e-4, 3e-4],
                               gravity_compliance=[1e-4, 2e-4, 1.5e-4])
    motor = delta.inverse(truth.geometry, [0.1, -0.05, 0.9])
    direction = np.array([1.0, -1.0, 1.0])
    arm = t.arm_angles(motor, direction)
    P = delta.forward(t.geometry, arm)
    # the fixed point in arm_angles contracts by c dtau/dtheta ~ 1e-3 per pass: 1e-12 after three
    np.testing.assert_allclose(t.increments(arm, direction, P), t.reading(motor), atol=1e-12)


def test_joint_readings_remember_the_last_motion(truth):
    t = sim_truth.with_effects(truth, backlash=[2e-4, 2e-4, 2e-4])
    hook = sim_truth.JointReadings(t)
    alpha = truth.geometry.theta0 + 0.2
    moving_down = hook(alpha, np.array([0.5, -0.5, 0.0]))
    resting = hook(alpha, np.zeros(3))
    np.testing.assert_allclose(moving_down, resting)
    np.testing.assert_allclose(resting - (alpha - truth.geometry.theta0), [1e-4, -1e-4, 1e-4])


def test_saved_truth_reads_back(truth, tmp_path):
    t = sim_truth.with_effects(truth, backlash=[1e-3, 6e-4, 8e-4],
                               base_geometry={'dH': [0.002, 0, 0], 'dphi': [0, 0.008, -0.006]})
    sim_truth.save(t, tmp_path / 'truth.yaml')
    back = sim_truth.load(tmp_path / 'truth.yaml')
    np.testing.assert_allclose(back.geometry.phi, t.geometry.phi)
    np.testing.assert_allclose(back.effects['backlash'], t.effects['backlash'])
    np.testing.assert_allclose(back.sphere_position, t.sphere_position)


def test_the_sides_read_back_from_the_readings_are_the_simulators():
    """reading_sides inverts JointReadings: moves, fast and slow returns, a count's rounding."""
    t = sim_truth.with_effects(sim_truth.load(), backlash=[1e-3, 6e-4, 8e-4])
    hook = sim_truth.JointReadings(t)
    dt = 1e-3
    time = np.arange(0.0, 8.0, dt)
    # moves of 0.2 s to random rests every 0.5 s, then a decaying ringing: its first returns are
    # fast (the side flips), its last ones slow (it stays)
    targets = np.random.default_rng(2).uniform(-0.3, 0.3, size=(16, 3))
    k, since = (time // 0.5).astype(int), time % 0.5
    s = np.clip(since / 0.2, 0.0, 1.0)
    move = targets[k - 1] + (targets[k] - targets[k - 1]) * (s * s * (3 - 2 * s))[:, None]
    after = np.maximum(since - 0.2, 0.0)
    ring = 4e-4 * np.sin(2 * np.pi * 12 * after) * np.exp(-after / 0.1)
    alpha = np.asarray(t.geometry.theta0) + move + ring[:, None] * [1.0, 0.7, 0.4]
    dalpha = np.gradient(alpha, dt, axis=0)
    readings, sides = [], []
    for a, da in zip(alpha, dalpha):
        readings.append(hook(a, da))
        sides.append(hook.direction.copy())
    count = 3.83e-5
    readings = np.round(np.array(readings) / count) * count
    sides = np.array(sides)
    assert np.all(np.sum(np.diff(sides, axis=0) != 0, axis=0) > 10)
    np.testing.assert_array_equal(sim_truth.reading_sides(readings, [1e-3, 6e-4, 8e-4]), sides)


def test_every_effect_on_the_readings_is_simulated_on_the_readings():
    """An effect that changes Truth.increments is one JointReadings applies (JOINT_EFFECTS)."""
    from robotenis_sim import scenarios
    values = {**{k: v for k, v in scenarios.EFFECTS.items() if v},
              **{k: v for k, (v, _) in scenarios.OUTSIDE_LIBRARY.items()}}
    plain = sim_truth.load()
    arm = np.asarray(plain.geometry.theta0) + np.array([[0.1, -0.2, 0.3], [-0.3, 0.2, 0.05]])
    P = delta.forward(plain.geometry, arm)
    direction = np.array([[1.0, -1.0, 1.0], [-1.0, 1.0, -1.0]])
    for effect in values.values():
        t = sim_truth.with_effects(plain, **effect)
        (name,) = set(t.effects)
        moved = not np.allclose(t.increments(arm, direction, P),
                                plain.increments(arm, direction, P), rtol=0, atol=1e-9)
        assert moved == (name in sim_truth.JOINT_EFFECTS), name
        if moved:
            hook = sim_truth.JointReadings(t)
            hook.direction = direction[0]
            np.testing.assert_allclose(hook(arm[0], np.zeros(3)),
                                       t.increments(arm[0], direction[0], P[0]), atol=1e-12)
