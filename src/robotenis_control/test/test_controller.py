"""The feedforward PD law (eqs. 10-11) and the motion controller's bookkeeping."""
import numpy as np
import pytest

from robotenis_control import controller as ctl
from robotenis_control import dynamics as dyn
from robotenis_kinematics import delta, description


@pytest.fixture
def desc():
    return description.nominal()


def test_on_the_desired_motion_the_drive_applies_the_model_torque():
    """Zero error: tau = K_V (alphad_ref - alphad) = tau_d exactly (what eq. 11 is for)."""
    gains = ctl.Gains(kp=150, kd=0.5, kv=60)
    alpha_d, dalpha_d, tau_d = (np.array([0.1, 0.2, 0.3]), np.array([1.0, -2.0, 0.5]),
                                np.array([10.0, -5.0, 30.0]))
    ref = ctl.velocity_command(alpha_d, dalpha_d, tau_d, alpha_d, dalpha_d, gains)
    np.testing.assert_allclose(ctl.drive_torque(ref, dalpha_d, gains.kv), tau_d)


def test_errors_add_a_pd_torque():
    """Check tau - tau_d = K_V K_p e + K_V (1 + K_d) edot."""
    gains = ctl.Gains(kp=100, kd=0.5, kv=40)
    e, edot = np.array([1e-3, -2e-3, 0.0]), np.array([0.0, 0.1, -0.2])
    alpha, dalpha = np.zeros(3), np.ones(3)
    ref = ctl.velocity_command(alpha + e, dalpha + edot, np.zeros(3), alpha, dalpha, gains)
    np.testing.assert_allclose(ctl.drive_torque(ref, dalpha, gains.kv),
                               gains.kv * gains.kp * e + gains.kv * (1 + gains.kd) * edot)


def test_goal_is_reached_on_the_planned_time(desc):
    c = ctl.MotionController(desc, max_speed=2.0, max_acceleration=4 * 9.81)
    home = delta.forward(desc, desc.theta0)
    c.update(0.0, np.zeros(3))
    goal = np.array([-0.2, 0.2, 0.75])
    c.add_goal(goal, 0.0)
    end = c.segments[-1].t1
    P, dP, ddP = c.desired(end / 2)
    # 283 mm at 2 m/s, 4 g: speed-limited
    assert np.linalg.norm(dP) == pytest.approx(2.0, rel=1e-9)
    # the polynomial is symmetric about u = 1/2
    assert np.allclose(P, (home + goal) / 2, atol=1e-9)
    P, dP, _ = c.desired(end + 1e-3)
    np.testing.assert_allclose(P, goal)
    np.testing.assert_allclose(dP, 0)
    assert not c.moving


def test_at_the_desired_joint_position_at_rest_only_gravity_is_fed_forward(desc):
    mass = dyn.MassParameters()
    c = ctl.MotionController(desc, mass)
    ref, P_est = c.update(0.0, np.zeros(3))
    static = dyn.inverse_dynamics(desc, mass, P_est, np.zeros(3), np.zeros(3))
    np.testing.assert_allclose(ref, static.tau / c.gains.kv, atol=1e-9)


def test_goals_outside_the_workspace_are_refused(desc):
    c = ctl.MotionController(desc)
    with pytest.raises(ctl.GoalError, match='goal before the first joint reading'):
        c.add_goal([0, 0, 0.8], 0.0)
    c.update(0.0, np.zeros(3))
    with pytest.raises(ctl.GoalError, match='outside the usable workspace'):
        c.add_goal([0, 0, 3.0], 0.0)
    with pytest.raises(ctl.GoalError, match='three finite'):
        c.add_goal([0, np.nan, 0.8], 0.0)


def test_velocity_commands_integrate_then_time_out(desc):
    c = ctl.MotionController(desc, max_speed=1.0, velocity_timeout=0.1)
    _, P0 = c.update(0.0, np.zeros(3))
    c.set_velocity([2.0, 0.0, 0.0], 0.0)                 # clipped to 1 m/s
    for k in range(1, 51):
        c.update(k * 1e-3, np.zeros(3))
    np.testing.assert_allclose(c.hold, P0 + [0.05, 0, 0], atol=1e-12)
    P, dP, _ = c.desired(0.2)                             # no command for 0.15 s: hold
    np.testing.assert_allclose(dP, 0)
    assert not c.moving


def test_batch_velocity_mode_commands_as_the_scalar_controller_does():
    """
    Check that the batch velocity mode commands as the scalar controller does.

    BatchVelocityController is MotionController's velocity mode vectorised over runs, each run
    with its own description: the same readings and velocity commands give the same drive
    commands, through a timeout too.
    """
    descs = [description.nominal(), description.load(description.config_path(
        'table1_calibrated.yaml'))]
    runs = [descs[0], descs[1], descs[0]]
    batch = ctl.BatchVelocityController(runs, velocity_timeout=0.05)
    scalar = [ctl.MotionController(d, velocity_timeout=0.05) for d in runs]
    rng = np.random.default_rng(3)
    Theta = rng.normal(scale=0.05, size=(3, 3))
    for k in range(150):
        t = 1e-3 * k
        Theta = Theta + rng.normal(scale=1e-4, size=(3, 3))
        dTheta = rng.normal(scale=0.01, size=(3, 3))
        if k in (1, 40):                             # commands at 1 and 40 ms; timeout from 90 ms
            U = rng.normal(scale=1.0, size=(3, 3))
            batch.set_velocity(U, t)
            for c, u in zip(scalar, U):
                c.set_velocity(u, t)
        expected = [c.update(t, th, dth)[0] for c, th, dth in zip(scalar, Theta, dTheta)]
        np.testing.assert_allclose(batch.update(t, Theta, dTheta), expected, atol=1e-9)
    assert not any(c.moving for c in scalar)         # the timeout was reached
