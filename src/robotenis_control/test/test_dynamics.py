"""Dynamics (eqs. 1-9): the equations against the energy they come from and each other."""
import numpy as np
import pytest

from robotenis_control import dynamics as dyn
from robotenis_kinematics import delta, description, effects


@pytest.fixture(scope='module')
def desc():
    return description.nominal()


def random_states(desc, n, seed):
    """Draw effector positions deep in the workspace, random velocities (m/s) and accelerations."""
    rng = np.random.default_rng(seed)
    P = np.array([0.0, 0.0, 0.8]) + rng.uniform(-0.2, 0.2, size=(n, 3))
    return P, rng.normal(scale=2.0, size=(n, 3)), rng.normal(scale=30.0, size=(n, 3))


def test_static_torque_is_the_virtual_work_gravity_torque(desc):
    """At rest, torques hold gravity: the kinematics package's virtual-work formula, same load."""
    mass = dyn.MassParameters()
    P = random_states(desc, 50, 1)[0]
    motion = dyn.inverse_dynamics(desc, mass, P, np.zeros_like(P), np.zeros_like(P))
    load = {'arm': 0.5 * (mass.m_a + mass.m_b), 'platform': mass.m_p + 1.5 * mass.m_b}
    np.testing.assert_allclose(motion.tau, -effects.gravity_torque(desc, P, motion.alpha, load),
                               rtol=1e-10, atol=1e-10)


def test_power_balance_along_a_motion(desc):
    """
    Check eqs. 4-5 against T + V (eqs. 6-9): constraint forces do no work, so dE/dt = tau . alphad.

    dE/dt by central differences of step h has error O(h^2 E'''), far below 1e-6 of the power
    here.
    """
    mass = dyn.MassParameters()
    P0, V0, A0 = random_states(desc, 20, 2)
    h = 1e-5

    def E(s):
        alpha, dalpha, _ = dyn.joint_motion(desc, P0 + V0 * s + 0.5 * A0 * s * s, V0 + A0 * s,
                                            A0)
        return dyn.energy(desc, mass, alpha, dalpha)

    dE = (E(h) - E(-h)) / (2 * h)
    motion = dyn.inverse_dynamics(desc, mass, P0, V0, A0)
    power = np.sum(motion.tau * motion.dalpha, axis=-1)
    np.testing.assert_allclose(dE, power, rtol=1e-6, atol=1e-6 * np.abs(power).max())


@pytest.mark.parametrize('mass', [dyn.MassParameters(), dyn.MassParameters().massless_forearms()])
def test_forward_dynamics_inverts_inverse_dynamics(desc, mass):
    P, V, A = random_states(desc, 30, 3)
    motion = dyn.inverse_dynamics(desc, mass, P, V, A)
    ddalpha = dyn.forward_dynamics(desc, mass, motion.alpha, motion.dalpha, motion.tau)
    np.testing.assert_allclose(ddalpha, motion.ddalpha, rtol=1e-9,
                               atol=1e-9 * np.abs(motion.ddalpha).max())


def test_single_robot_scalars_match_the_vectorised_equations(desc):
    mass = dyn.MassParameters()
    P, V, A = random_states(desc, 10, 4)
    motion = dyn.inverse_dynamics(desc, mass, P, V, A)
    single = dyn.SingleRobotDynamics(desc, mass)
    for k in range(len(P)):
        ddalpha, P_k, dP_k = single.accelerations(list(motion.alpha[k]), list(motion.dalpha[k]),
                                                  list(motion.tau[k]))
        np.testing.assert_allclose(ddalpha, motion.ddalpha[k], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(P_k, P[k], atol=1e-12)
        np.testing.assert_allclose(dP_k, V[k], atol=1e-11)
        alpha, dalpha, tau = single.inverse_dynamics(P[k], V[k], A[k])
        np.testing.assert_allclose(alpha, motion.alpha[k], atol=1e-12)
        np.testing.assert_allclose(dalpha, motion.dalpha[k], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(tau, motion.tau[k], rtol=1e-9, atol=1e-9)


def test_massless_forearms_only_move_the_platform_and_arms(desc):
    """m_b = 0: no forearm terms, tau = I_t alphadd + (arm gravity) + J^T (m_p (Pdd - g z))."""
    mass = dyn.MassParameters().massless_forearms()
    P, V, A = random_states(desc, 10, 5)
    motion = dyn.inverse_dynamics(desc, mass, P, V, A)
    J = delta.jacobian(desc, P, motion.alpha)
    expected = (mass.I_t * motion.ddalpha - dyn.G * 0.5 * mass.m_a * desc.a * np.cos(motion.alpha)
                + np.einsum('...ji,...j->...i', J, mass.m_p * (A - dyn.G * dyn.Z)))
    np.testing.assert_allclose(motion.tau, expected, rtol=1e-9, atol=1e-9)


def test_bad_mass_parameter_is_named():
    with pytest.raises(ValueError, match='m_b'):
        dyn.MassParameters(m_b=-1.0)
