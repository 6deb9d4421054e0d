"""Joint effects: commanding with a calibrated model inverts what fk applies."""
import numpy as np
import pytest
from robotenis_kinematics import delta, description, effects
from robotenis_kinematics.errors import DescriptionError


def test_increments_for_inverts_the_model_joint_angles():
    desc = description.nominal().copy(effects=[
        {'name': 'joint_scale', 'scale': [4e-3, -3e-3, 2e-3]},
        {'name': 'backlash', 'width': [1e-3, 5e-4, 8e-4]},
        {'name': 'gravity_compliance', 'compliance': [1e-4, 2e-4, 1.5e-4],
         'gravity_load': dict(effects.NOMINAL_GRAVITY_LOAD)}])
    P = np.array([[0.1, -0.05, 0.9], [-0.2, 0.1, 0.8], [0.0, 0.2, 1.1]])
    theta = delta.inverse(desc, P)
    direction = np.array([[1.0, -1.0, 1.0], [-1.0, -1.0, 1.0], [1.0, 1.0, -1.0]])
    Theta = effects.increments_for(desc, theta, direction, P)
    fx = effects.parameters(desc)
    back, _ = effects.model_joint_angles(desc, fx, Theta, direction, P, effects.gravity_load(desc))
    # three fixed-point passes contract the sag error by (c dtau/dtheta)^3 ~ 1e-9 of 1e-3 rad
    np.testing.assert_allclose(back, theta, atol=1e-12)


def test_without_effects_the_increments_are_the_angles_from_home():
    desc = description.nominal()
    theta = delta.inverse(desc, [0.05, 0.02, 0.95])
    np.testing.assert_allclose(effects.increments_for(desc, theta, np.ones(3), None),
                               theta - desc.theta0)


HARMONICS = {'name': 'joint_harmonics', 'terms': {'cos5': [2e-4, -1e-4, 3e-4],
                                                  'sin5': [-3e-4, 2e-4, 1e-4]}}
FIELD = {'name': 'camera_field', 'reference_range': effects.CAMERA_REFERENCE_RANGE,
         'terms': {'w': [0.0, 0.0, 1.4e-3], 'xx': [1e-4, 0.0, -2e-4]}}


def test_increments_for_inverts_the_joint_harmonics_too():
    desc = description.nominal().copy(effects=[dict(HARMONICS), {
        'name': 'gravity_compliance', 'compliance': [1e-4, 2e-4, 1.5e-4],
        'gravity_load': dict(effects.NOMINAL_GRAVITY_LOAD)}])
    P = np.array([[0.1, -0.05, 0.9], [-0.2, 0.1, 0.8], [0.0, 0.2, 1.1]])
    theta = delta.inverse(desc, P)
    direction = np.ones((3, 3))
    Theta = effects.increments_for(desc, theta, direction, P)
    fx = effects.parameters(desc)
    back, _ = effects.model_joint_angles(desc, fx, Theta, direction, P, effects.gravity_load(desc))
    # each pass contracts the error by n |c| ~ 2e-3: three passes leave 1e-8 of the 4e-4 rad
    np.testing.assert_allclose(back, theta, atol=1e-12)


def test_generic_effects_are_read_written_and_checked():
    desc = description.nominal().copy(effects=[dict(HARMONICS), dict(FIELD)])
    again = description.loads(description.dumps(desc))
    assert set(effects.parameters(again)) == {'joint_cos5', 'joint_sin5', 'camera_w', 'camera_xx'}
    for bad, key in ((dict(HARMONICS, terms={'tan5': [0.0, 0.0, 0.0]}), 'terms.tan5'),
                     (dict(FIELD, terms={'w': [0.0, 0.0]}), 'terms.w'),
                     (dict(FIELD, reference_range=0.5), 'reference_range')):
        with pytest.raises(DescriptionError, match=key):
            description.from_dict(dict(description.nominal().to_dict(), effects=[bad]))


def test_the_camera_field_is_removed_before_the_hand_eye_rotation():
    """s_measured = s + f phi(s): the increments of the true s come back, then turned by r."""
    R = description.nominal().camera_rotation
    s = np.array([[0.02, -0.01, 0.3], [-0.05, 0.04, 0.5]])
    f = np.array([0.0, 0.0, 1.4e-3])
    measured = s + np.outer(s[:, 2] / effects.CAMERA_REFERENCE_RANGE - 1, f)
    back = effects.camera_increments({'camera_w': f}, -measured @ R.T, R)
    # first order: phi is evaluated at the measured s, off by f phi, so the error is at most
    # |f| |dphi/dz| |f phi| = |f|^2 |phi| / z_ref (|phi| < 1 here)
    bound = np.sum(f ** 2) / effects.CAMERA_REFERENCE_RANGE
    np.testing.assert_allclose(back, -s @ R.T, atol=bound)
