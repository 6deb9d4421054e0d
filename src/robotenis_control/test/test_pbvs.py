import numpy as np
from scipy import stats

from robotenis_control import pbvs

R_CAM = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # looking along base +x


def test_error_is_zero_when_the_ball_is_where_it_should_be():
    np.testing.assert_allclose(pbvs.relative_error(pbvs.S_DESIRED, R_CAM), 0.0)
    # Ball 10 cm too far along the optical axis (base +x): the robot is 10 cm behind, e_r = -0.1 x.
    np.testing.assert_allclose(pbvs.relative_error(pbvs.S_DESIRED + [0, 0, 0.1], R_CAM), [-0.1, 0, 0])


def test_closed_loop_converges_at_the_gain_and_tracks_a_steady_ball():
    """Ideal kinematics: e' = -K_p e + (v_p - v_ball); with v_p = v_ball the error decays as exp(-K_p t)."""
    dt, v_ball = 1e-3, np.array([0.5, -0.2, 0.1])
    ball, robot = np.array([1.2, 0.0, 1.0]), np.array([0.5, 0.1, 0.9])
    e0 = None
    for k in range(300):
        s = R_CAM.T @ (ball - robot)            # the camera at the effector centre, for the test
        e = pbvs.relative_error(s, R_CAM)
        e0 = e if e0 is None else e0
        robot = robot + dt * pbvs.cartesian_command(e, v_ball)
        ball = ball + dt * v_ball
    s = R_CAM.T @ (ball - robot)
    # After 0.3 s the error is e0 (1 - K_p dt)^300 (explicit Euler of the exponential decay).
    np.testing.assert_allclose(pbvs.relative_error(s, R_CAM), e0 * (1 - pbvs.K_P * dt) ** 300, atol=1e-12)


def test_kalman_velocity_is_consistent_with_its_covariance():
    """NEES of the velocity estimate over 200 runs follows chi2(3) on average (two-sided 1 %)."""
    rng = np.random.default_rng(0)
    sigma, dt, q, runs = 0.5e-3, 1 / 120, 20.0, 200
    # The process noise of continuous white acceleration over one step (the filter's own model).
    Q = q * np.block([[dt ** 3 / 3 * np.eye(3), dt ** 2 / 2 * np.eye(3)], [dt ** 2 / 2 * np.eye(3), dt * np.eye(3)]])
    nees = 0.0
    for _ in range(runs):
        f = pbvs.BallKalman(q)
        p, v = np.zeros(3), rng.normal(scale=1.0, size=3)
        for k in range(60):
            if k:
                f.predict(dt)
                w = rng.multivariate_normal(np.zeros(6), Q)
                p, v = p + v * dt + w[:3], v + w[3:]
            f.update(p + rng.normal(scale=sigma, size=3), sigma ** 2 * np.eye(3))
        e = f.velocity - v
        nees += e @ np.linalg.solve(f.P[3:, 3:], e)
    n = 3 * runs
    assert stats.chi2.ppf(0.005, n) < nees < stats.chi2.ppf(0.995, n)


def test_joint_command_uses_the_inverse_jacobian():
    J_inv = np.diag([2.0, 3.0, 4.0])
    np.testing.assert_allclose(pbvs.joint_command(J_inv, [1.0, 1.0, 1.0]), [2.0, 3.0, 4.0])
