"""Joint effects: commanding with a calibrated model inverts what fk applies."""
import numpy as np

from robotenis_kinematics import delta, description, effects


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
